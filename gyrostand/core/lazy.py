"""Lazy exports of a package (PEP 562): each public name imported from its module on first
use, so importing a package costs nothing until a name is used.

A package lists ``EXPORTS`` (public name -> the submodule defining it, relative) and binds
``__getattr__, __dir__ = exports(__name__, EXPORTS, globals())``. A structure test reads
``EXPORTS`` to follow ``from package import name`` to the module that defines the name.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def exports(package: str, sources: Mapping[str, str], namespace: dict[str, Any]
            ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package`` whose names come from ``sources``."""

    def __getattr__(name: str) -> Any:
        try:
            source = sources[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        value = getattr(importlib.import_module(f".{source}", package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(sources))

    return __getattr__, __dir__
