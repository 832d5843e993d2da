"""Design of the next chamber run: the Fisher information and Cramér–Rao bound
(:mod:`.fisher`), the set-point program search (:mod:`.search`), the run that tells two
look-alikes apart (:mod:`.separation`) and several switch-ons (:mod:`.switch_ons`).
"""

from __future__ import annotations

from ..lazy import exports

#: each public name and the submodule defining it
EXPORTS: dict[str, str] = {
    "design": "search",
    "ChamberLimits": "search",
    "Program": "search",
    "DesignResult": "search",
    "crlb": "fisher",
    "fisher_information": "fisher",
    "rivals": "separation",
    "separate": "separation",
    "Rivals": "separation",
    "power_cycle": "switch_ons",
    "separate_power_cycle": "switch_ons",
}
__all__ = sorted(EXPORTS)
__getattr__, __dir__ = exports(__name__, EXPORTS, globals())
