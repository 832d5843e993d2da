"""The re-linearisation's fixed point x = g(x), accelerated by SQUAREM (Varadhan & Roland
2008): shared by the paper's iterated pass (:mod:`~gyrostand.core.lkf.filter`) and the
converging filter (:mod:`~gyrostand.core.lkf.relin`)."""

from __future__ import annotations

import numpy as np

__all__ = ["fixed_point"]


def fixed_point(g, count, x0, x1, sd, run, max_iter, tol, clipped, beta_max,
                 settle_sigma=1e-3):
    """Re-linearise until the estimate equals the linearisation point: x = g(x).

    Plain re-linearisation converges linearly (slowly along the γ/β ridge); every step is
    accelerated with SQUAREM (Varadhan & Roland 2008), falling back to the plain step when
    the extrapolation would make β non-positive. Settled when every parameter moves by less
    than ``tol`` (relative) or ``settle_sigma`` of its std. Returns the last point and its
    pass (the last call of ``g`` is at the returned point).
    """

    def fix_beta(x_new, x_old):
        x_new = x_new.copy()
        if x_new[0] <= 0:  # typical of the first passes from the paper's 1e-4 point
            clipped[0] += 1
            x_new[0] = x_old[0] / 3
        x_new[0] = min(max(x_new[0], x_old[0] / 10), x_old[0] * 10, beta_max)
        return x_new

    def small(a, b, s):
        d = np.abs(a - b)
        return bool(np.all((d <= tol * np.abs(b)) | (d <= settle_sigma * s)))

    x1 = fix_beta(x1, x0)
    while True:
        if small(x1, x0, sd):
            return x0, x1, sd, run, True
        x2, sd2, run2 = g(x1)
        x2 = fix_beta(x2, x1)
        r, v = x1 - x0, x2 - 2 * x1 + x0
        scale = np.where(sd2 > 0, sd2, 1.0)
        nr, nv = np.linalg.norm(r / scale), np.linalg.norm(v / scale)
        alpha = -nr / nv if nv > 0 else -1.0
        alpha = min(alpha, -1.0)
        xa = x0 - 2 * alpha * r + alpha * alpha * v
        while xa[0] <= 0 and alpha < -1.0:
            alpha = (alpha - 1.0) / 2
            xa = x0 - 2 * alpha * r + alpha * alpha * v
        if xa[0] <= 0:
            xa = x2
        x0 = xa
        x1, sd, run = g(x0)
        x1 = fix_beta(x1, x0)
        if count() >= max_iter:
            return x0, x1, sd, run, small(x1, x0, sd)
