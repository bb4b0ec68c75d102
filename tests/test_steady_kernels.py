"""The likelihood's compiled steady-state filter: the Riccati solution scipy gives, the polynomials numpy gives
(identification.likelihood.steady_kernels)."""

import numpy as np
import pytest
from scipy import signal
from scipy.linalg import solve_discrete_are

from identification.likelihood.state_space import discrete_system, innovation_filters, kalman
from identification.likelihood.steady_kernels import char_poly, filter_riccati


def _scipy_covariance(Ad, Qd):
    C = np.zeros((Ad.shape[0], 1))
    C[0, 0] = 1.0
    return solve_discrete_are(Ad.T, C, Qd, np.array([[1.0]]))


def _riccati_residual(Ad, Qd, P):
    """How far ``P`` is from solving the filter's Riccati equation, relative to its largest entry."""
    gain_column = Ad @ P[:, 0]
    rhs = Ad @ P @ Ad.T - np.outer(gain_column, gain_column) / (P[0, 0] + 1.0) + Qd
    return np.abs(rhs - P).max() / np.abs(P).max()


def _random_axes(seed, count):
    """Axis models over the search's whole box (damping, gust time constants and levels, both gust models) and
    the sample times a log may have."""
    rng = np.random.default_rng(seed)
    for i in range(count):
        kind = ("gm2", "gm_so")[i % 2]
        yield (rng.uniform(-2.0, 200.0), np.exp(rng.uniform(np.log(0.8), np.log(120.0))),
               np.exp(rng.uniform(np.log(0.02), np.log(0.8))), *np.exp(rng.uniform(-9.0, 20.0, 2)),
               rng.uniform(0.2, 3.0), float(rng.choice([0.0025, 0.005, 0.01, 0.02])), kind)


def test_the_doubling_gives_scipys_riccati_solution_over_the_searchs_whole_box():
    worst, solved = 0.0, 0
    for axis in _random_axes(0, 400):
        Ad, _, _, Qd = discrete_system(*axis)
        try:
            reference = _scipy_covariance(Ad, Qd)
        except np.linalg.LinAlgError:
            continue
        P, doublings = filter_riccati(np.ascontiguousarray(Ad), Qd, 1.0)
        assert doublings > 0, axis
        solved += 1
        worst = max(worst, np.abs(P - reference).max() / np.abs(reference).max())
        # at least as close to a solution as scipy's (its QZ leaves up to 1e-14 where doubling leaves 1e-16)
        assert _riccati_residual(Ad, Qd, P) <= max(2.0 * _riccati_residual(Ad, Qd, reference), 1e-14), axis
    assert solved > 350
    assert worst < 1e-8


def test_kalman_gives_the_gain_and_innovation_variance_of_scipys_solution():
    Ad, _, _, Qd = discrete_system(6.0, 4.0, 0.3, 100.0, 100.0, 0.8, 0.01, "gm_so")
    P, L, S = kalman(Ad, Qd)
    reference = _scipy_covariance(Ad, Qd)
    np.testing.assert_allclose(P, reference, rtol=1e-10, atol=1e-12 * np.abs(reference).max())
    assert S == pytest.approx(reference[0, 0] + 1.0, rel=1e-12)
    np.testing.assert_allclose(L, reference[:, 0] / (reference[0, 0] + 1.0), rtol=1e-10)


def test_where_the_doubling_misses_the_stabilising_solution_kalman_takes_scipys():
    """An unstable rate (damping -1) with no gust noise: the doubling starts at P = 0 and stays there, a fixed
    point whose filter leaves the rate unstable; it says so, and kalman takes scipy's stabilising solution."""
    Ad, _, _, Qd = discrete_system(-1.0, 7.45, 0.2, 0.0, 0.0, 1.0, 0.01, "gm2")
    assert filter_riccati(np.ascontiguousarray(Ad), Qd, 1.0)[1] == -1
    P, L, _ = kalman(Ad, Qd)
    np.testing.assert_allclose(P, _scipy_covariance(Ad, Qd), rtol=1e-12, atol=1e-15)
    assert P[0, 0] > 0.02 and abs((Ad - np.outer(Ad @ L, np.eye(3)[0]))[0, 0]) < 1.0  # a stable filter


def test_char_poly_is_numpys_poly():
    rng = np.random.default_rng(1)
    for size in (1, 2, 3, 4, 6):
        for _ in range(20):
            M = rng.standard_normal((size, size)) * rng.uniform(0.1, 3.0)
            np.testing.assert_allclose(char_poly(M), np.real(np.poly(M)), rtol=1e-11, atol=1e-11)


@pytest.mark.parametrize("kind", ["gm2", "gm_so"])
def test_the_innovation_filters_and_further_paths_are_the_predictors_transfer_functions(kind):
    """Each numerator over the common denominator is the predictor's response, read at the rate, to its input:
    checked against the impulse response of the state-space predictor itself."""
    Ad, ga, gb, Qd = discrete_system(3.0, 6.0, 0.2, 50.0, 200.0, 0.7, 0.01, kind)
    g0, g1 = ga - 0.4 * gb, 0.4 * gb
    _, L, _ = kalman(Ad, Qd)
    Phi = Ad - np.outer(Ad @ L, np.eye(Ad.shape[0])[0])
    extra = np.eye(Ad.shape[0])[0]
    b_y, b_u, a, b_e = innovation_filters(Ad, g0, g1, L, extra)
    impulse = np.zeros(40)
    impulse[0] = 1.0
    for numerator, b in ((b_y, Ad @ L), (b_e, extra)):
        x, response = np.zeros(Ad.shape[0]), []
        for u in impulse:  # x+ = Phi x + b u, read x[0] before the step
            response.append(x[0])
            x = Phi @ x + b * u
        np.testing.assert_allclose(signal.lfilter(numerator, a, impulse), response, atol=1e-12)
    x, previous, response = np.zeros(Ad.shape[0]), 0.0, []
    for u in impulse:  # x_k = Phi x_(k-1) + g0 u_(k-1) + g1 u_k: the interpolated input reaches x_k through g1
        x = Phi @ x + g0 * previous + g1 * u
        previous = u
        response.append(x[0])
    np.testing.assert_allclose(signal.lfilter(b_u, a, impulse), response, atol=1e-12)
