"""The paper's linearised Kalman filter with a moving linearisation point: over a record
(:mod:`.filter`), one bin at a time (:mod:`.online`), made to converge (:mod:`.relin`, its
held noise levels in :mod:`.noise`), compiled (:mod:`.kernel`); its band's status
(:mod:`.band`) and β's profile likelihood (:mod:`.profile`).
"""

from __future__ import annotations

from ..lazy import exports

#: each public name and the submodule defining it
EXPORTS: dict[str, str] = {
    "lkf": "filter",
    "OnlineLKF": "filter",
    "lkf_terms": "filter",
    "lkf_layout": "filter",
    "relin_fit": "filter",
    "RelinLKF": "relin",
    "RelinSchedule": "schedule",
    "band_warnings": "band",
    "calibrated_estimates": "band",
    "profile_interval": "profile",
    "profile_check": "profile",
}
__all__ = sorted(EXPORTS)
__getattr__, __dir__ = exports(__name__, EXPORTS, globals())
