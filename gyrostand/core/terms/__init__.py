"""The model terms: the protocol every term follows (:mod:`.base`) and the built-in
vocabulary with the registry of every term, built-in or plugin (:mod:`.builtin`).
"""

from __future__ import annotations

from ..lazy import exports

#: each public name and the submodule defining it
EXPORTS: dict[str, str] = {
    "Term": "base",
    "Param": "base",
    "Context": "base",
    "Bin": "base",
    "Scales": "base",
    "POSITIVE_KINDS": "base",
    "TERMS": "builtin",
    "register": "builtin",
    "term_class": "builtin",
    "separation": "builtin",
}
__all__ = sorted(EXPORTS)
__getattr__, __dir__ = exports(__name__, EXPORTS, globals())
