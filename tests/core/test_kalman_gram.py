"""The Gram matrix of the filtered columns: the block product for a wide ``Y`` (the
saturated reference's) is the same sum as the sample-by-sample one of a narrow ``Y``, and
the sum of the innovations' products the filter keeps when asked to (``store``)."""

import numpy as np
import pytest

from gyrostand.core.kalman import BLOCK, WIDE, kf_run


@pytest.mark.parametrize("weighted", [True, False])
@pytest.mark.parametrize("m", [WIDE - 1, WIDE, 25])
def test_gram_is_the_sum_of_whitened_innovation_products(m: int, weighted: bool) -> None:
    rng = np.random.default_rng(7)
    N = 3 * BLOCK + 17  # full blocks and a partial one
    Y = rng.standard_normal((N, m)).cumsum(axis=0)
    Y[[5, 300, 301], 0] = np.nan  # missing samples: predict only, not in G
    phi, q, p0 = np.array([0.99, 0.5]), np.array([1e-3, 0.2]), np.array([0.1, 1.0])
    # a changing R (the covariance never steady) or none (steady after a few hundred)
    rw = 1.0 + rng.random(N) if weighted else np.zeros(0)
    E, f, G0, _, _ = kf_run(phi, q, p0, 0.01, rw, Y, True)
    assert not G0.any()  # who keeps E gets no Gram matrix (m² a sample saved)
    _, _, G, slogf, n = kf_run(phi, q, p0, 0.01, rw, Y, False)
    ok = ~np.isnan(Y[:, 0])
    want = (E[ok] / f[ok, None]).T @ E[ok]
    assert n == N - 3
    assert np.allclose(G, want, rtol=1e-11, atol=0)
    assert np.array_equal(G, G.T)
    assert slogf == pytest.approx(np.log(f[ok]).sum(), rel=1e-13)
