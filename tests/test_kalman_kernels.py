"""The likelihood's compiled filter loop is scipy's lfilter, bit for bit: its speed changed no fitted value
(identification.likelihood.kalman_kernels)."""

import numpy as np
import pytest
from scipy import signal

from identification.likelihood.kalman_kernels import PAIR_TAPS, filter_rows
from identification.likelihood.state_space import discrete_model, innovation_filters, kalman


def _stable_filter(rng, order):
    """A random denominator of ``order`` with its poles inside the unit circle (up to 0.9995, as a slow gust's), in
    complex pairs where the order allows."""
    pairs = rng.uniform(0.3, 0.9995, order // 2) * np.exp(0.3j)
    real = rng.uniform(0.3, 0.9995, order % 2)
    return np.real(np.poly(np.concatenate([pairs, np.conj(pairs), real])))


@pytest.mark.parametrize("order", range(1, PAIR_TAPS + 3))
@pytest.mark.parametrize("rows", [1, 2, 5])
def test_each_row_comes_out_as_lfilter_gives_it(order, rows):
    rng = np.random.default_rng(10 * order + rows)
    a = _stable_filter(rng, order) * rng.uniform(0.5, 2.0)  # a[0] != 1: the coefficients are divided by it
    B = rng.standard_normal((rows, order + 1))
    U = rng.standard_normal((rows, 3000)) * np.array([1.0, 1e-3, 1e4, 1.0, 1.0])[:rows, None]
    out = filter_rows(B, a, U)
    for r in range(rows):
        assert np.array_equal(out[r], signal.lfilter(B[r], a, U[r])), (order, rows, r)


def test_the_likelihoods_own_filters_come_out_as_lfilter_gives_them():
    Ad, g0, g1, Qd = discrete_model(2.5, 4.0, 0.3, 100.0, 100.0, 0.8, 0.01, 0.5, "gm_so")
    b_y, b_u, a = innovation_filters(Ad, g0, g1, kalman(Ad, Qd)[1])
    rng = np.random.default_rng(0)
    y, X = rng.standard_normal(30001), rng.standard_normal((3, 30001))
    out = filter_rows(np.vstack([b_y, b_u, b_u, b_u]), a, np.vstack([y, X]))
    assert np.array_equal(out[0], signal.lfilter(b_y, a, y))
    assert np.array_equal(out[1:], signal.lfilter(b_u, a, X, axis=-1))
