"""The online LSQ's recursive factor (:class:`gyrostand.core.lsq.fit.GivensQR`)."""

from __future__ import annotations

import numpy as np
import pytest

from gyrostand.core.lsq.fit import GivensQR


def test_givens_factor_solves_like_lstsq_and_costs_no_normal_equations():
    """Rows fed one at a time give lstsq's solution, residual sum and (HᵀH)⁻¹."""
    rng = np.random.default_rng(3)
    n, p = 500, 3
    H = np.column_stack([rng.normal(size=n), 20 + 40 * rng.random(n), np.ones(n)])
    x_true = np.array([0.03, -0.01, 0.2])
    d = H @ x_true + 0.01 * rng.normal(size=n)
    qr = GivensQR(p)
    for h, dk in zip(H.tolist(), d.tolist(), strict=True):
        qr.add(h, dk)
    X, rss, inv, cond = qr.solution()
    want, res, *_ = np.linalg.lstsq(H, d, rcond=None)
    assert X == pytest.approx(want, rel=1e-10)
    assert rss == pytest.approx(float(res[0]), rel=1e-9)
    assert inv == pytest.approx(np.linalg.inv(H.T @ H), rel=1e-9)
    assert cond == pytest.approx(np.linalg.cond(H.T @ H), rel=3.0)  # an estimate of κ


def test_givens_factor_is_accurate_where_normal_equations_are_not():
    """κ(H) ≈ 1e7: the normal equations (κ² ≈ 1e14) lose ~half the digits; the factor
    keeps lstsq's (SVD) solution to ~1e-8."""
    rng = np.random.default_rng(5)
    n = 2000
    t = rng.random(n)
    H = np.column_stack([t, t + 1e-7 * rng.normal(size=n), np.ones(n)])
    d = H @ np.array([1.0, 2.0, 3.0]) + 1e-9 * rng.normal(size=n)
    qr = GivensQR(3)
    for h, dk in zip(H.tolist(), d.tolist(), strict=True):
        qr.add(h, dk)
    X = qr.solution()[0]
    ref = np.linalg.lstsq(H, d, rcond=None)[0]
    normal = np.linalg.solve(H.T @ H, H.T @ d)
    err_qr = np.max(np.abs(X - ref))
    err_ne = np.max(np.abs(normal - ref))
    assert err_qr < 1e-6
    assert err_qr < err_ne / 1000


def test_singular_factor_is_reported_as_none():
    qr = GivensQR(2)
    for _ in range(5):
        qr.add([1.0, 0.0], 1.0)  # the second column never varies: R[1][1] == 0
    assert qr.solution() is None
