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


@pytest.mark.parametrize("wind_model", ["gm2", "gm_so"])
def test_a_point_whose_hold_or_alignment_alone_changed_reuses_its_riccati_solution_with_the_same_bits(wind_model,
                                                                                                    monkeypatch):
    """The search's Jacobian perturbs one entry at a time; the hold and the alignment leave the Kalman gain as it
    was (AxisLikelihood.system keeps it), and every evaluation equals a fresh likelihood's bit for bit."""
    from identification.likelihood import axis_likelihood
    from identification.likelihood.axis_likelihood import AxisData, AxisLikelihood
    from identification.likelihood.state_space import HOLD_INDEX, N_NONLINEAR

    solved = []
    monkeypatch.setattr(axis_likelihood, "kalman", lambda Ad, Qd: solved.append(1) or kalman(Ad, Qd))
    rng = np.random.default_rng(3)
    y, X = rng.standard_normal(3000), rng.standard_normal((2, 3000))
    data = AxisData(y=[y], regressors=[X], names=("k", "kd@0"), dt=0.01, hold=0.5, burn=200, wind_model=wind_model)
    base = np.array([2.4, 0.0, np.log(0.3), np.log(80.0), np.log(120.0), 0.5, np.log(0.7)][:N_NONLINEAR[wind_model]])
    points = [base]
    for j in range(base.size):  # a forward-difference Jacobian's points, then a new point
        points.append(base.copy())
        points[-1][j] += 1e-5
    points.append(base + 0.01)
    warm, solves = AxisLikelihood(data), []
    for x in points:
        before = len(solved)
        got = warm.filtered(x)
        solves.append(len(solved) > before)
        fresh = AxisLikelihood(data).filtered(x)
        assert all(np.array_equal(a, b) for a, b in zip(got, fresh))
    assert solves[1 + HOLD_INDEX] is False  # the hold's column: the point's own Riccati solution
    assert sum(solves) == len(points) - 1
    with pytest.raises(ValueError, match="read-only"):
        warm.system(base)[0][0, 0] = 0.0  # shared between evaluations: nobody may change it in place
