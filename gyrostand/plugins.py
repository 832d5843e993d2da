"""User terms as plugins: a :class:`~gyrostand.core.terms.Term` subclass in the user's own
package, found the way python-can finds interface plugins.

Two routes, both ending in :func:`gyrostand.core.terms.register`:

* an **entry point** in the group ``gyrostand.terms`` of an installed distribution, its
  name the term's name and its value the class (``temp_step =
  gyrostand_temp_step:TempStep`` in the package's ``pyproject.toml`` under
  ``[project.entry-points."gyrostand.terms"]``); every command loads them before it runs
  (:func:`load_entry_points`);
* a session file's ``plugins: [module, ...]``: each module is imported and every Term
  subclass it defines (or lists in a module-level ``TERMS``) is registered
  (:func:`load_modules`).

A registered term works wherever a built-in does (config ``model:`` and ``simulate:``,
``identify --model``, ML, the LKF when it is linear, ``diagnose`` candidates, ``fit --add``,
reports, the CAN summary's bit after the built-ins'). A name another term has is an error
naming both. The numerical core is imported only when a plugin is found, so a command
without plugins starts as fast as before.
"""

from __future__ import annotations

import importlib
import logging
from collections.abc import Iterable
from typing import Any

from .errors import ModelError

log = logging.getLogger(__name__)

#: the entry-point group of term plugins
GROUP = "gyrostand.terms"

_loaded_entry_points = False


def available_terms() -> tuple[str, ...]:
    """Every term a model may name here: the built-in vocabulary, then each installed
    ``gyrostand.terms`` entry point by its name (the term's), without importing it, so a
    command's ``--help`` lists the plugins without the cost of loading them. (A session
    file's ``plugins:`` module is known only once its file is read.)"""
    from importlib.metadata import entry_points

    from .core.names import VOCABULARY

    extra = sorted({ep.name for ep in entry_points(group=GROUP)} - set(VOCABULARY))
    return (*VOCABULARY, *extra)


def load_entry_points() -> list[str]:
    """Register the terms of every installed ``gyrostand.terms`` entry point (once per
    process; sorted by name, so their summary bits do not depend on install order).
    Returns the names registered by this call."""
    global _loaded_entry_points
    if _loaded_entry_points:
        return []
    _loaded_entry_points = True
    from importlib.metadata import entry_points

    eps = sorted(entry_points(group=GROUP), key=lambda e: (e.name, e.value))
    out = []
    for ep in eps:
        dist = getattr(getattr(ep, "dist", None), "name", None)
        where = f"entry point {ep.name} = {ep.value} (group {GROUP}" + \
            (f", distribution {dist})" if dist else ")")
        try:
            obj = ep.load()
        except Exception as exc:  # noqa: BLE001 - any failure of the user's import
            raise ModelError(f"plugin {where}: cannot be loaded: "
                             f"{type(exc).__name__}: {exc}") from exc
        classes = _term_classes(obj, where)
        if isinstance(obj, type) and classes[0].name != ep.name:
            raise ModelError(f"plugin {where}: the entry point's name {ep.name!r} is not "
                             f"its term's name {classes[0].name!r}")
        out += [_register(cls, where) for cls in classes]
    if out:
        log.info("plugin terms from entry points: %s", ", ".join(out))
    return out


def load_modules(modules: Iterable[str]) -> list[str]:
    """Import each module and register the terms it defines; returns their names.

    Raises :class:`~gyrostand.errors.ModelError` naming the module when it cannot be
    imported or defines no term.
    """
    out = []
    for name in modules:
        where = f"module {name!r}"
        try:
            mod = importlib.import_module(name)
        except Exception as exc:  # noqa: BLE001 - any failure of the user's import
            raise ModelError(f"plugin {where}: cannot be imported: "
                             f"{type(exc).__name__}: {exc}") from exc
        out += [_register(cls, f"{where} ({cls.__module__}.{cls.__qualname__})")
                for cls in _term_classes(mod, where)]
    return out


def known_terms() -> tuple[str, ...]:
    """Every term a model may use now: the built-ins, then the registered plugins."""
    from .core.terms.builtin import TERMS

    return tuple(TERMS)


def _register(cls: Any, where: str) -> str:
    from .core.terms.builtin import register

    register(cls, where)
    return str(cls.name)


def _term_classes(obj: Any, where: str) -> list[Any]:
    """The Term subclasses an entry point or module provides: the class itself, a
    module's ``TERMS`` list, or the subclasses a module defines."""
    from .core.terms.builtin import Term

    if isinstance(obj, type):
        if not issubclass(obj, Term):
            raise ModelError(f"plugin {where}: {obj.__qualname__} is not a subclass of "
                             "gyrostand.core.terms.Term")
        return [obj]
    listed = getattr(obj, "TERMS", None)
    if listed is not None:
        classes = list(listed.values() if isinstance(listed, dict) else listed)
    else:
        classes = [v for v in vars(obj).values() if isinstance(v, type) and
                   issubclass(v, Term) and v.__module__ == getattr(obj, "__name__", None)
                   and "name" in vars(v)]
    bad = [c for c in classes if not (isinstance(c, type) and issubclass(c, Term))]
    if bad:
        raise ModelError(f"plugin {where}: {bad[0]!r} is not a subclass of "
                         "gyrostand.core.terms.Term")
    if not classes:
        raise ModelError(f"plugin {where}: defines no model term (a subclass of "
                         "gyrostand.core.terms.Term with a name)")
    return classes
