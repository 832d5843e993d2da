"""Exact Gaussian maximum likelihood: one run (:mod:`.fit`; its search :mod:`.search`
with the analytic score :mod:`.score`), its standard errors
(:mod:`.cov`) and several runs of one gyro at once (:mod:`.joint`).

The problem (:class:`~.fit.Problem`), the optimiser and its start grids are public: the
joint fit and the candidate refits build on them.
"""

from __future__ import annotations

from ..lazy import exports

#: each public name and the submodule defining it
EXPORTS: dict[str, str] = {
    "ml": "fit",
    "ml_fit": "fit",
    "Problem": "fit",
    "optimise": "search",
    "start_grid": "fit",
    "starts_from": "fit",
    "concentrated_loglik": "gls",
    "fill_natural": "gls",
    "observed_covariance": "cov",
    "hessian": "cov",
    "joint_ml": "joint",
    "JointFit": "joint",
    "JointProblem": "joint",
    "repeatability": "joint",
    "Repeatability": "joint",
}
__all__ = sorted(EXPORTS)
__getattr__, __dir__ = exports(__name__, EXPORTS, globals())
