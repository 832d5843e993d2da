"""The paper's least squares (Algorithm 1), batch and recursive (:mod:`.fit`).
"""

from __future__ import annotations

from ..lazy import exports

#: each public name and the submodule defining it
EXPORTS: dict[str, str] = {
    "lsq": "fit",
    "OnlineLSQ": "fit",
    "check_lsq_model": "fit",
}
__all__ = sorted(EXPORTS)
__getattr__, __dir__ = exports(__name__, EXPORTS, globals())
