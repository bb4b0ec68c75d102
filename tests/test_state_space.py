"""The wind-state model's Riccati solution: the doubling solver against scipy's general one."""

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are

from identification import state_space
from identification.state_space import WIND_MODELS, discrete_model, filter_riccati, kalman


def _scipy_riccati(Ad, Qd, R=1.0):
    c = np.zeros((Ad.shape[0], 1))
    c[0, 0] = 1.0
    return solve_discrete_are(Ad.T, c, Qd, np.array([[R]]))


def _random_axes(n, seed=0):
    """Axis models over the search's range: stable and unstable dampings, slow and fast gusts, any hold."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        yield discrete_model(rng.uniform(-2.0, 30.0), np.exp(rng.uniform(np.log(0.5), np.log(60.0))),
                             np.exp(rng.uniform(np.log(0.01), np.log(2.0))), *np.exp(rng.uniform(-5.0, 10.0, 2)),
                             rng.uniform(0.2, 3.0), 0.01, rng.uniform(), WIND_MODELS[i % 2])


def test_doubling_equals_scipy_over_the_search_range():
    for Ad, _, _, Qd in _random_axes(200):
        ref = _scipy_riccati(Ad, Qd)
        np.testing.assert_allclose(filter_riccati(Ad, Qd), ref, rtol=0, atol=1e-10 * np.max(np.abs(ref)))


def test_noise_variance_other_than_one():
    Ad, _, _, Qd = discrete_model(3.0, 4.0, 0.3, 50.0, 20.0, 1.0, 0.01, 1.0, "gm2")
    ref = _scipy_riccati(Ad, Qd, R=0.04)
    np.testing.assert_allclose(filter_riccati(Ad, Qd, R=0.04), ref, rtol=1e-10)
    _, L, S = kalman(Ad, Qd, R=0.04)
    np.testing.assert_allclose(S, ref[0, 0] + 0.04, rtol=1e-10)
    np.testing.assert_allclose(L, ref[:, 0] / S, rtol=1e-10)


def test_unconverged_doubling_falls_back_to_scipy(monkeypatch):
    monkeypatch.setattr(state_space, "DOUBLING_STEPS", 1)
    Ad, _, _, Qd = discrete_model(3.0, 4.0, 0.3, 50.0, 20.0, 1.0, 0.01, 1.0, "gm2")
    np.testing.assert_array_equal(filter_riccati(Ad, Qd), _scipy_riccati(Ad, Qd))


def test_filter_is_stable_and_covariance_symmetric():
    for Ad, _, _, Qd in _random_axes(50, seed=1):
        P, L, _ = kalman(Ad, Qd)
        assert np.array_equal(P, P.T)
        Phi = Ad - np.outer(Ad @ L, np.eye(Ad.shape[0])[0])
        assert np.max(np.abs(np.linalg.eigvals(Phi))) < 1.0
        assert np.all(np.linalg.eigvalsh(P) > -1e-9 * np.max(np.abs(P)))


@pytest.mark.parametrize("kind", WIND_MODELS)
def test_innovations_unchanged_by_the_solver(kind):
    """The likelihood's innovation filters from either solution agree to rounding."""
    Ad, g0, g1, Qd = discrete_model(5.0, 3.0, 0.2, 80.0, 40.0, 0.8, 0.01, 0.5, kind)
    P = _scipy_riccati(Ad, Qd)
    L_ref = P[:, 0] / (P[0, 0] + 1.0)
    _, L, _ = kalman(Ad, Qd)
    for got, ref in zip(state_space.innovation_filters(Ad, g0, g1, L),
                        state_space.innovation_filters(Ad, g0, g1, L_ref)):
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)
