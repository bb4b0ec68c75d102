"""Tests of the paper's baseline identifiers: nonlinear regression and the parameter EKF."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from heli_core.params import ModelParams
from heli_core.physics import simulate
from identification.baselines import (
    P0_EQ74,
    RATE_CAP,
    TABLE4_M0,
    NonlinearRegression,
    NotFittedError,
    ParameterEKF,
    ekf_sample_length_study,
    parameter_names,
    simulate_rate,
)
from identification.flight import make_flight

# Decoupled model with the paper's identified values, eqs. (68)-(70).
TRUTH = ModelParams(
    k2=1.3475, k3=2.4208, kd1=0.0399,
    k6=-0.8903, k7=2.5188, kd2=0.0115,
    k10=13.4702, k11=3.4342, k12=-0.5623, kd3=0.0964,
)
RATE_NOISE = 0.005  # rad/s, white noise on the measured rates


def truth_flight(seed: int = 0, duration: float = 40.0, rate_hz: float = 50.0):
    """A flight simulated from TRUTH: every stick a sum of 8 sinusoids (0.3-3 Hz,
    0.1 each) plus 0.01 white noise; the rates get RATE_NOISE white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    freqs = np.linspace(0.3, 3.0, 8)

    def excitation():
        phase = rng.uniform(0.0, 2.0 * np.pi, freqs.size)
        return 0.1 * np.sin(2.0 * np.pi * freqs[:, None] * t + phase[:, None]).sum(axis=0)

    sticks = np.array([excitation() + 0.01 * rng.standard_normal(t.size) for _ in range(4)])
    sticks[2] = 0.1 + 0.5 * sticks[2]  # collective around a trim value
    rates = simulate(TRUTH, t, sticks)[:3] + RATE_NOISE * rng.standard_normal((3, t.size))
    return make_flight(t, rates, sticks, metadata={"seed": seed})


def truth(names):
    return np.array([TRUTH.get(n) for n in names])


@pytest.fixture(scope="module")
def flight():
    return truth_flight(seed=0)


@pytest.fixture(scope="module")
def nlr_eq73(flight):
    return NonlinearRegression(axis="roll", start=(5, 5, 5)).fit(flight)


# ------------------------------------------------------------------ nonlinear regression
def test_nlr_recovers_roll_from_eq73_start(nlr_eq73):
    # Noise-limited: 0.005 rad/s on a ~0.1 rad/s roll rate leaves ~0.3 % scatter on the
    # damping and gain and ~5e-4 rad/s^2 on the small offset kd1 (hence atol).
    assert nlr_eq73.param_names_ == ("k3", "k2", "kd1")
    assert_allclose(nlr_eq73.coef_, truth(("k3", "k2", "kd1")), rtol=1e-2, atol=1e-3)
    assert nlr_eq73.converged_ and not nlr_eq73.diverged_
    assert nlr_eq73.params_.k1 == nlr_eq73.params_.k4 == 0.0
    assert nlr_eq73.cpu_time_ > 0.0
    assert nlr_eq73.n_simulations_ >= nlr_eq73.nfev_ > 0
    assert nlr_eq73.history_.params.shape == (nlr_eq73.n_simulations_, 3)
    assert nlr_eq73.history_.cost.min() == pytest.approx(nlr_eq73.cost_, rel=1e-9)


def test_nlr_fit_reaches_noise_floor(nlr_eq73, flight):
    # Residual RMS equals the injected rate noise; MAE of white noise is sqrt(2/pi)*sigma.
    assert np.sqrt(np.mean(nlr_eq73.residual_ ** 2)) == pytest.approx(RATE_NOISE, rel=0.1)
    assert nlr_eq73.errors(flight).mae == pytest.approx(np.degrees(RATE_NOISE) * np.sqrt(2 / np.pi), rel=0.1)
    assert nlr_eq73.score(flight) > 0.98  # R^2, limited by the noise (signal std ~0.04 rad/s)


def test_nlr_far_start_does_not_alias_rk4_pole(flight):
    # From Table 3's (100, 100, 100) a fixed-step RK4 at k3*dt ~ 2.75 reproduces the slow
    # pole; simulate_rate sub-steps stiff models, so the regression finds the true one.
    nlr = NonlinearRegression(axis="roll", start=(100, 100, 100)).fit(flight)
    assert_allclose(nlr.coef_, truth(("k3", "k2", "kd1")), rtol=1e-2, atol=1e-3)


def test_nlr_pitch_axis(flight):
    nlr = NonlinearRegression(axis="pitch", start=(2.0, -1.0, 0.0)).fit(flight)
    assert nlr.param_names_ == ("k7", "k6", "kd2")
    # Pitch rate is smaller (~0.07 rad/s), so the same noise leaves ~1 % scatter.
    assert_allclose(nlr.coef_, truth(("k7", "k6", "kd2")), rtol=3e-2, atol=1e-3)
    assert nlr.params_.k3 == 0.0


def test_nlr_divergent_start_gives_finite_results(flight):
    nlr = NonlinearRegression(axis="roll", start=(-50.0, 5.0, 5.0), max_nfev=3).fit(flight)
    assert np.all(np.isfinite(nlr.residual_))
    assert np.all(np.isfinite(nlr.history_.cost))
    assert np.all(np.isfinite(nlr.coef_))
    assert nlr.diverged_ and not nlr.converged_
    assert np.all(np.isfinite(nlr.predict(flight)))


def test_simulate_rate_clips_divergence(flight):
    sim = simulate_rate(ModelParams(k3=-200.0, k2=5.0), flight, "roll")
    assert np.all(np.isfinite(sim))
    assert np.abs(sim).max() == RATE_CAP


# ------------------------------------------------------------------ EKF
@pytest.fixture(scope="module")
def ekf_case2a(flight):
    return ParameterEKF(axis="roll", q=1e-8, m0=TABLE4_M0["a"]).fit(flight)


def test_ekf_recovers_roll_approximately(ekf_case2a):
    # Table 4 case 2(a). The Euler model of eq. (48) biases damping and gain low by
    # ~k3*Ts/2 = 2.4 % at 50 Hz, hence 5 %.
    assert ekf_case2a.param_names_ == ("k3", "k2", "kd1")
    assert_allclose(ekf_case2a.coef_, truth(("k3", "k2", "kd1")), rtol=5e-2)
    assert not ekf_case2a.diverged_
    assert ekf_case2a.cpu_time_ > 0.0
    # Automatic R is the variance of the injected rate noise.
    assert ekf_case2a.r_ == pytest.approx(RATE_NOISE ** 2, rel=0.2)


def test_ekf_history_and_covariance(ekf_case2a, flight):
    h = ekf_case2a.history_
    assert h.names == ("rate", "k3", "k2", "kd1")
    assert h.state.shape == h.cov_diag.shape == (flight.n, 4)
    assert_allclose(h.state[0], TABLE4_M0["a"])
    assert_allclose(h.cov_diag[0], P0_EQ74)
    assert_allclose(h.state[-1], ekf_case2a.state_)
    assert_allclose(h.params[-1], ekf_case2a.coef_)
    # Fig. 22: parameter uncertainties settle well below their prior and stay bounded.
    assert np.all(h.cov_diag[-1, 1:] < 1e-2 * np.array(P0_EQ74[1:]))
    assert np.all(h.cov_diag[:, 1:] <= np.array(P0_EQ74[1:]) * (1 + 1e-9))
    P = ekf_case2a.covariance_
    assert_allclose(P, P.T)
    assert np.linalg.eigvalsh(P).min() > -1e-12


def test_ekf_predict_simulates_final_parameters(ekf_case2a, flight):
    sim = ekf_case2a.predict(flight)
    assert sim.shape == (flight.n,)
    assert_allclose(sim, simulate_rate(ekf_case2a.params_, flight, "roll"))
    assert ekf_case2a.errors(flight).mae < 1.0  # deg/s


def test_ekf_case2_insensitive_to_m0(ekf_case2a, flight):
    # Table 4: with the good Q, starts (a) and (b) end at the same parameters.
    b = ParameterEKF(axis="roll", q=1e-8, m0=TABLE4_M0["b"]).fit(flight)
    assert_allclose(b.coef_, ekf_case2a.coef_, rtol=1e-2)


@pytest.mark.parametrize(
    "axis, collective, m0, p0",
    [
        ("pitch", False, TABLE4_M0["b"], P0_EQ74),
        ("yaw", True, (0.0, 2.0, 3.0, 0.0, 0.0), P0_EQ74 + (1.0,)),
    ],
)
def test_ekf_other_axes(flight, axis, collective, m0, p0):
    ekf = ParameterEKF(axis=axis, q=1e-8, m0=m0, p0=p0, collective=collective).fit(flight)
    names = parameter_names(axis, collective)
    assert ekf.param_names_ == names
    assert_allclose(ekf.coef_, truth(names), rtol=8e-2, atol=5e-3)


def test_ekf_sample_length_study(flight):
    rows = ekf_sample_length_study(flight, lengths=(4.84, 11, 22), q=1e-2)
    assert [r.length for r in rows] == [4.84, 11.0, 22.0]
    # Table 5's trend: a longer window converges further.
    assert rows[0].errors.mae > rows[1].errors.mae > rows[2].errors.mae
    assert all(r.errors.p90 >= r.errors.mae and not r.diverged for r in rows)


def test_ekf_sample_length_longer_than_flight(flight):
    with pytest.raises(ValueError, match="window length"):
        ekf_sample_length_study(flight, lengths=(100.0,))


# ------------------------------------------------------------------ common behaviour
@pytest.mark.parametrize("estimator", [NonlinearRegression(), ParameterEKF()])
def test_predict_before_fit_raises(estimator, flight):
    with pytest.raises(NotFittedError, match="not fitted"):
        estimator.predict(flight)
    with pytest.raises(NotFittedError, match="not fitted"):
        estimator.coef_
    assert not hasattr(estimator, "params_")


def test_constructor_only_stores_arguments():
    est = ParameterEKF(axis="bank", q=-1.0, m0=(1, 2))  # invalid, but not checked yet
    assert (est.axis, est.q, est.m0) == ("bank", -1.0, (1, 2))


def test_seeded_determinism():
    a, b, c = truth_flight(seed=3, duration=10.0), truth_flight(seed=3, duration=10.0), truth_flight(seed=4, duration=10.0)
    assert_array_equal(a.rates, b.rates)
    assert not np.array_equal(a.rates, c.rates)
    ekf_a, ekf_b = ParameterEKF(q=1e-8).fit(a), ParameterEKF(q=1e-8).fit(b)
    assert_array_equal(ekf_a.history_.state, ekf_b.history_.state)
    nlr_a, nlr_b = NonlinearRegression(start=(2, 1, 0)).fit(a), NonlinearRegression(start=(2, 1, 0)).fit(b)
    assert nlr_a.params_ == nlr_b.params_


# ------------------------------------------------------------------ bad inputs
@pytest.mark.parametrize(
    "estimator, match",
    [
        (NonlinearRegression(axis="bank"), "axis must be one of"),
        (NonlinearRegression(start=(5, 5)), r"start must hold 3 values in the order \(k3, k2, kd1\)"),
        (NonlinearRegression(start=(5, np.nan, 5)), "start must be finite"),
        (NonlinearRegression(collective=True), "needs axis='yaw'"),
        (ParameterEKF(m0=(0, 1, 1)), r"m0 must hold 4 values in the order \(rate, k3, k2, kd1\)"),
        (ParameterEKF(p0=(1, 1, 1)), "p0 must be a diagonal of 4 values"),
        (ParameterEKF(p0=-np.eye(4)), "positive semi-definite"),
        (ParameterEKF(q=-1.0), "q must be a finite variance"),
        (ParameterEKF(r=0.0), "r must be a finite variance"),
        (ParameterEKF(r="grid"), "or 'auto'"),
    ],
)
def test_bad_arguments(estimator, match, flight):
    with pytest.raises(ValueError, match=match):
        estimator.fit(flight)
