"""Tests of the physics core (:mod:`heli_core`) and of :mod:`identification.attitude`.

Eqs. (18) and (21) (rate dynamics), (25)-(29) (quaternion kinematics and Euler
angles), (31) (Padé servo delay); the detrend of Section 3.2.
"""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.spatial.transform import Rotation

from heli_core.params import ModelParams
from heli_core.physics import N_STATE, QUAT, RATES, SERVO, derivatives, initial_state, simulate, step
from heli_core.quaternion import euler_from_quaternion, quaternion_from_euler
from heli_core.servo import servo_coefficients
from identification.attitude import attitude_from_rates, detrend_piecewise, quaternions_from_rates

COUPLED = ModelParams(
    k1=-0.05, k2=8.0, k3=3.0, k4=0.5, kd1=0.1, k5=0.05, k6=6.0, k7=3.0, k8=0.4, kd2=-0.05,
    k9=0.01, k10=10.0, k11=4.0, k12=1.0, kd3=0.2, tau_roll=0.05, tau_pitch=0.04, tau_yaw=0.02,
)
"""A fully coupled model with servo delays on every axis."""


def _wrap(a):
    return np.angle(np.exp(1j * a))


def _random_batch(n, seed=0):
    """Random states (unit quaternions, non-zero servo states), sticks and disturbances, batch size n."""
    rng = np.random.default_rng(seed)
    x = rng.normal(scale=0.8, size=(N_STATE, n))
    x[QUAT] /= np.linalg.norm(x[QUAT], axis=0)
    return x, rng.uniform(-1, 1, size=(4, n)), rng.normal(scale=0.5, size=(3, n))


@pytest.fixture(scope="module")
def coupled_flight():
    """10 s of the coupled model at 500 Hz with multi-sine sticks: time, sticks, states (10, n)."""
    t = np.arange(0.0, 10.0, 0.002)
    sticks = np.array([
        0.3 * np.sin(2 * np.pi * 0.4 * t) + 0.1 * np.sin(2 * np.pi * 1.3 * t),
        0.3 * np.sin(2 * np.pi * 0.3 * t + 1.0),
        0.2 * np.sin(2 * np.pi * 0.2 * t),
        0.3 * np.sin(2 * np.pi * 0.5 * t + 2.0),
    ])
    return t, sticks, simulate(COUPLED, t, sticks)


# ------------------------------------------------------------------------------------ ModelParams


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, "1.0", None])
def test_params_must_be_finite_numbers(value):
    with pytest.raises(ValueError, match=r"parameter k3 must be a finite number, got"):
        ModelParams(k3=value)


@pytest.mark.parametrize("name, value", [("tau_roll", -0.01), ("tau_yaw", 2.5)])
def test_delay_must_be_between_0_and_2_s(name, value):
    with pytest.raises(ValueError, match=rf"{name} must be a delay in \[0, 2\] s, got {value}"):
        ModelParams(**{name: value})


def test_unknown_extra_term():
    with pytest.raises(ValueError, match=r"unknown extra term 'drag'; known: ct1, ct2, nld1"):
        ModelParams(extra=(("drag", 0.1),))


def test_bad_extra_values():
    with pytest.raises(ValueError, match=r"extra terms must have unique names, got \['nld1', 'nld1'\]"):
        ModelParams(extra=(("nld1", 0.1), ("nld1", 0.2)))
    with pytest.raises(ValueError, match=r"extra term nld1 must be finite, got nan"):
        ModelParams(extra=(("nld1", math.nan),))


def test_params_are_floats_hashable_and_compare_by_value():
    a = ModelParams(k2=2, extra=(("nld1", 1), ("gs1", 0.5)))
    b = ModelParams(k2=2.0, extra=(("gs1", 0.5), ("nld1", 1.0)))
    assert isinstance(a.k2, float)
    assert a.extra == (("gs1", 0.5), ("nld1", 1.0))  # sorted, floats
    assert a == b and hash(a) == hash(b)
    assert a.taus == (0.0, 0.0, 0.0)
    assert_array_equal(COUPLED.control_gains, [8.0, 6.0, 10.0])


def test_with_values_replaces_base_and_adds_extras():
    p = ModelParams(k2=1.0, extra=(("nld1", 0.1),))
    q = p.with_values(k2=3.0, tau_roll=0.1, nld1=0.2, gs2=-0.4)
    assert (q.k2, q.tau_roll) == (3.0, 0.1)
    assert dict(q.extra) == {"nld1": 0.2, "gs2": -0.4}
    assert q.get("gs2") == -0.4 and q.get("nld3") == 0.0 and q.get("tau_roll") == 0.1
    assert q.values()["gs2"] == -0.4 and q.values()["k2"] == 3.0
    assert (p.k2, dict(p.extra)) == (1.0, {"nld1": 0.1})  # the original is unchanged
    with pytest.raises(KeyError, match="unknown parameter 'k99'"):
        p.with_values(k99=1.0)
    with pytest.raises(KeyError, match="unknown parameter 'k99'"):
        p.get("k99")


# ------------------------------------------------------------------------------ Padé servo, eq. (31)


@pytest.mark.parametrize("tau", [0.01, 0.05, 0.1, 0.37])
def test_servo_coefficients_are_the_first_order_pade(tau):
    """theta + d1 theta' = n1 delta - n2 delta' with d1 = tau/2, n1 = 1, n2 = tau/2 (eq. 31, control.pade)."""
    d1, n1, n2 = servo_coefficients(tau)
    assert_allclose((d1, n1, n2), (tau / 2, 1.0, tau / 2), rtol=1e-12)
    num, den = control.pade(tau, 1)
    num, den = np.asarray(num, float), np.asarray(den, float)
    assert_allclose((den[0] / den[1], num[1] / den[1], -num[0] / den[1]), (d1, n1, n2), rtol=1e-12)
    # The same transfer function as exp(-s tau) to second order at low frequency
    w = 0.1 / tau
    s = 1j * w
    assert_allclose((n1 - n2 * s) / (1 + d1 * s), np.polyval(num, s) / np.polyval(den, s), rtol=1e-12)
    assert abs((n1 - n2 * s) / (1 + d1 * s) - np.exp(-s * tau)) < 1e-3


def test_no_delay_is_a_feedthrough():
    assert servo_coefficients(0.0) == (0.0, 1.0, 0.0)


def test_a_servo_lag_is_a_first_order_response_and_adds_to_the_delays_denominator():
    """eq. (31) with the lag added to d1: a pure lag is 1/(1 + s T); with a delay, (1 - s tau/2)/(1 + s (tau/2 + T))."""
    assert servo_coefficients(0.0, 0.05) == (0.05, 1.0, 0.0)
    d1, n1, n2 = servo_coefficients(0.08, 0.05)
    assert_allclose((d1, n1, n2), (0.04 + 0.05, 1.0, 0.04), rtol=1e-12)
    lag, dt = 0.05, 0.001
    t = dt * np.arange(501)
    sticks = np.zeros((4, t.size))
    sticks[0] = 1.0
    x = simulate(ModelParams(k2=1.0, lag_roll=lag), t, sticks, x0=initial_state())
    servo_out = derivatives(x, sticks, None, ModelParams(k2=1.0, lag_roll=lag))[0]
    assert_allclose(servo_out, 1 - np.exp(-t / lag), rtol=0, atol=1e-9)  # the lag's step response, no inverse part
    assert_allclose(x[0], t - lag + lag * np.exp(-t / lag), rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="lag_pitch must be a servo time constant in \\[0, 1\\] s"):
        ModelParams(lag_pitch=1.5)


def test_step_response_through_the_pade_servo_is_delayed():
    """p' = k2 theta_cyc with k2 = 1, tau = 0.1 s: a unit lateral step, analytic solution of eq. (31).

    The servo output theta = 1 - 2 exp(-t/d1) (d1 = tau/2) starts at -1 (Padé inverse response),
    crosses 50 % at d1 ln 4 = 0.69 tau, and p(t) = t - tau + tau exp(-t/d1) is the undelayed
    ramp p = t shifted by tau.
    """
    tau, dt = 0.1, 0.001
    params = ModelParams(k2=1.0, tau_roll=tau)
    t = dt * np.arange(1001)
    sticks = np.zeros((4, t.size))
    sticks[0] = 1.0  # the step at t = 0 (zero-order hold from sample 0)
    x = simulate(params, t, sticks, x0=initial_state())  # servo settled on centred sticks
    p = x[0]
    d1 = tau / 2
    assert_allclose(p, t - tau + tau * np.exp(-t / d1), rtol=0, atol=1e-9)

    servo_out = derivatives(x, sticks, None, params)[0]  # p' = k2 * theta_cyc
    assert_allclose(servo_out, 1 - 2 * np.exp(-t / d1), rtol=0, atol=1e-9)
    assert servo_out[0] == pytest.approx(-1.0)  # initial inverse response of the Padé
    assert p[1: int(0.05 / dt)].max() < 0.0 and p.min() == pytest.approx(d1 * (math.log(2) - 1), abs=5e-6)  # sampled at 1 ms
    t50 = t[np.argmax(servo_out >= 0.5)]
    assert t50 == pytest.approx(d1 * math.log(4), abs=dt)
    assert 0.5 * tau < t50 < tau
    late = t > 0.8  # tau*exp(-t/d1) < 2e-8
    assert_allclose(p[late], t[late] - tau, rtol=0, atol=1e-6)  # the ramp is exactly tau late

    undelayed = simulate(ModelParams(k2=1.0), t, sticks, x0=initial_state())
    assert_allclose(undelayed[0], t, rtol=0, atol=1e-12)


# ------------------------------------------------------------------------------ integration, eq. (18), (21)


def test_free_decay_matches_the_exponential():
    """p' = -k3 p, q' = -k7 q, r' = -k11 r from non-zero rates: exp(-k t) to 1e-6 with RK4 at 100 Hz."""
    params = ModelParams(k3=2.0, k7=1.5, k11=4.0)
    t = 0.01 * np.arange(501)
    x0 = initial_state(rates=(1.0, -0.5, 0.8))
    x = simulate(params, t, np.zeros((4, t.size)), x0=x0)
    k = np.array([[2.0], [1.5], [4.0]])
    assert_allclose(x[RATES], x0[RATES, None] * np.exp(-k * t), rtol=0, atol=1e-6)


def test_rk4_is_fourth_order():
    params = ModelParams(k3=2.0)
    errs = []
    for substeps in (2, 4):
        x = initial_state(rates=(1.0, 0.0, 0.0))
        for _ in range(10):
            x = step(x, np.zeros(4), None, params, 0.1, substeps=substeps)
        errs.append(abs(x[0] - math.exp(-2.0)))
    assert errs[0] / errs[1] == pytest.approx(16.0, rel=0.15)  # halving the step: 2^4 smaller error


def test_constant_disturbance_is_a_torque_per_inertia():
    """With damping only, a constant roll disturbance d settles at p = d / k3."""
    params = ModelParams(k3=2.0, k7=2.0, k11=4.0)
    t = 0.01 * np.arange(1001)
    dist = np.tile([[0.6], [-0.6], [0.8]], t.size)
    x = simulate(params, t, np.zeros((4, t.size)), torque=dist)
    assert_allclose(x[RATES, -1], [0.3, -0.3, 0.2], rtol=0, atol=1e-6)


def test_derivatives_are_eqs_18_21_25():
    """Hand-written eqs. (18), (21) and (25) at random states, without servo delay."""
    params = COUPLED.with_values(tau_roll=0.0, tau_pitch=0.0, tau_yaw=0.0)
    x, u, d = _random_batch(5)
    f = derivatives(x, u, d, params)
    p, q, r = x[RATES]
    lat, lon, col, ped = u
    P = params
    assert_allclose(f[0], P.k1 * q * r + P.k2 * lat - P.k3 * p + P.k4 * q + P.kd1 + d[0], rtol=1e-13)
    assert_allclose(f[1], P.k5 * p * r + P.k6 * lon - P.k7 * q - P.k8 * p + P.kd2 + d[1], rtol=1e-13)
    assert_allclose(f[2], P.k9 * p * q + P.k10 * ped - P.k11 * r - P.k12 * col + P.kd3 + d[2], rtol=1e-13)
    assert_array_equal(f[SERVO], 0.0)  # no delay: the servo states do not move
    q0, q1, q2, q3 = x[QUAT]
    expected = 0.5 * np.array([
        -(q3 * r + q2 * q + q1 * p),
        q2 * r - q3 * q + q0 * p,
        -q1 * r + q0 * q + q3 * p,
        q0 * r + q1 * q - q2 * p,  # eq. (25) with its typo q3*p -> q2*p corrected
    ])
    assert_allclose(f[QUAT], expected, rtol=1e-13)


def test_derivatives_with_servo_delay_and_extra_terms():
    """Eq. (31) in state-space form: theta = -n2/d1 delta + (n1 + n2/d1) z, z' = (delta - z)/d1."""
    params = ModelParams(k2=2.0, k6=3.0, k10=4.0, tau_roll=0.1, tau_pitch=0.2, extra=(("nld1", 0.5), ("gs3", 0.7)))
    x, u, d = _random_batch(4, seed=3)
    f = derivatives(x, u, None, params)
    cmd = []
    for i, (stick, tau) in enumerate(zip(u[[0, 1, 3]], params.taus)):
        if tau == 0:
            cmd.append(stick)
            assert_array_equal(f[3 + i], 0.0)
            continue
        d1, n1, n2 = tau / 2, 1.0, tau / 2
        cmd.append(-n2 / d1 * stick + (n1 + n2 / d1) * x[3 + i])
        assert_allclose(f[3 + i], (stick - x[3 + i]) / d1, rtol=1e-13)
    p = x[0]
    assert_allclose(f[0], 2.0 * cmd[0] - 0.5 * p * np.abs(p), rtol=1e-13)
    assert_allclose(f[1], 3.0 * cmd[1], rtol=1e-13)
    assert_allclose(f[2], 4.0 * cmd[2] + 0.7 * cmd[2] * u[2], rtol=1e-13)


def test_derivatives_on_a_batch_equal_the_single_state_path():
    x, u, d = _random_batch(9)
    params = COUPLED.with_values(nld2=0.3, ct1=0.2)
    batch = derivatives(x, u, d, params)
    assert batch.shape == (N_STATE, 9)
    for j in range(9):
        single = derivatives(x[:, j], u[:, j], d[:, j], params)
        assert single.shape == (N_STATE,)
        assert_allclose(batch[:, j], single, rtol=0, atol=1e-12)
        assert_allclose(derivatives(list(x[:, j]), list(u[:, j]), None, params), derivatives(x[:, j], u[:, j], None, params), rtol=0, atol=0)


@pytest.mark.parametrize("with_disturbance", [True, False])
def test_batched_step_equals_scalar_steps(with_disturbance):
    """A (10, N) batch advanced by step() equals N scalar trajectories (to 1e-12)."""
    x, u, d = _random_batch(7, seed=1)
    params = COUPLED.with_values(nld1=0.2, gs1=0.3)
    dd = d if with_disturbance else None
    xb = x
    xs = [list(x[:, j]) for j in range(7)]
    for _ in range(20):
        xb = step(xb, u, dd, params, 0.01, substeps=2)
        xs = [step(xs[j], list(u[:, j]), None if dd is None else list(d[:, j]), params, 0.01, substeps=2)
              for j in range(7)]
    assert isinstance(xb, np.ndarray) and xb.shape == (N_STATE, 7)
    assert isinstance(xs[0], tuple) and len(xs[0]) == N_STATE
    assert_allclose(xb, np.array(xs).T, rtol=0, atol=1e-12)


def test_simulate_equals_repeated_steps(coupled_flight):
    t, sticks, x = coupled_flight
    xs = initial_state(sticks=sticks[[0, 1, 3], 0])
    for k in range(200):
        xs = step(xs, sticks[:, k], None, COUPLED, t[1] - t[0])
    assert_allclose(x[:, 200], xs, rtol=0, atol=1e-12)


def test_initial_state_batch_shape():
    x = initial_state(rates=(0.1, 0.2, 0.3), euler=(0.1, -0.2, 0.3), sticks=(0.5, 0.0, -0.5), batch=(2, 3))
    assert x.shape == (N_STATE, 2, 3)
    assert_allclose(x[RATES, 1, 2], [0.1, 0.2, 0.3])
    assert_allclose(x[SERVO, 0, 0], [0.5, 0.0, -0.5])
    assert_allclose(euler_from_quaternion(x[QUAT, 1, 1]), [0.1, -0.2, 0.3], atol=1e-14)


# ----------------------------------------------------------------------------- quaternions, eq. (25)-(29)


def test_quaternion_stays_unit_norm(coupled_flight):
    _, _, x = coupled_flight
    assert_allclose(np.linalg.norm(x[QUAT], axis=0), 1.0, rtol=0, atol=1e-12)
    bad = initial_state(rates=(3.0, -2.0, 4.0))
    bad[QUAT] *= 1.3  # step renormalises (eq. 26)
    assert np.linalg.norm(step(bad, np.zeros(4), None, COUPLED, 0.05)[QUAT]) == pytest.approx(1.0, abs=1e-15)


def test_euler_quaternion_round_trip():
    rng = np.random.default_rng(2)
    e = np.array([rng.uniform(-np.pi, np.pi, 500), rng.uniform(-1.5, 1.5, 500), rng.uniform(-np.pi, np.pi, 500)])
    quat = quaternion_from_euler(*e)
    assert quat.shape == (4, 500)
    assert_allclose(np.linalg.norm(quat, axis=0), 1.0, atol=1e-15)
    assert_allclose(euler_from_quaternion(quat), e, rtol=0, atol=1e-9)
    # ZYX (yaw, pitch, roll) convention, checked against scipy; q and -q are the same rotation
    ref = Rotation.from_euler("ZYX", e[::-1].T).as_quat(scalar_first=True).T
    assert_allclose(np.abs(np.sum(ref * quat, axis=0)), 1.0, atol=1e-12)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_constant_body_rate_turns_the_matching_euler_angle(axis):
    """From level, a constant p (q, r) alone turns phi (theta, psi) at that rate: eq. (25) signs."""
    rates = [0.0, 0.0, 0.0]
    rates[axis] = 0.3
    t = 0.01 * np.arange(401)
    x = simulate(ModelParams(), t, np.zeros((4, t.size)), x0=initial_state(rates=rates))
    expected = np.zeros((3, t.size))
    expected[axis] = 0.3 * t
    assert_allclose(euler_from_quaternion(x[QUAT]), expected, rtol=0, atol=1e-12)


def test_attitude_from_rates_agrees_with_the_physics_core(coupled_flight):
    """Eqs. (25)-(29) integrated from sampled rates vs the simulated quaternion: 1e-5 rad at 500 Hz."""
    t, _, x = coupled_flight
    truth = euler_from_quaternion(x[QUAT])
    assert np.abs(truth).max() > 0.5
    assert_allclose(_wrap(attitude_from_rates(t, x[RATES]) - truth), 0.0, rtol=0, atol=1e-5)
    quat = quaternions_from_rates(t, x[RATES])
    assert_allclose(np.linalg.norm(quat, axis=0), 1.0, atol=1e-12)
    assert_allclose(quat, x[QUAT], rtol=0, atol=1e-5)


def test_attitude_from_rates_starts_from_euler0():
    t = 0.01 * np.arange(10)
    att = attitude_from_rates(t, np.zeros((3, 10)), euler0=(0.1, -0.2, 3.0))
    assert_allclose(att, np.tile([[0.1], [-0.2], [3.0]], 10), atol=1e-14)


# ---------------------------------------------------------------------------------- detrend, Section 3.2


def test_detrend_removes_a_continuous_piecewise_linear_trend():
    t = np.arange(0.0, 35.0, 0.01)
    knots = [0.0, 10.0, 20.0, 30.0, 35.0]
    trend = np.array([np.interp(t, knots, [1, -2, 3, 0, 0.5]), np.interp(t, knots, [0, 5, 5, -1, 2])])
    signal = 0.2 * np.sin(2 * np.pi * 0.7 * t)
    assert_allclose(detrend_piecewise(t, trend), 0.0, atol=1e-9)
    out = detrend_piecewise(t, trend + signal)
    assert out.shape == (2, t.size)
    assert_allclose(out, detrend_piecewise(t, np.stack([signal, signal])), atol=1e-9)  # linear in its input
    assert np.abs(out - signal).max() < 0.05  # a 0.7 Hz oscillation mostly survives 10 s pieces
    assert abs(out[0].mean()) < 1e-12


def test_detrend_trend_is_continuous_at_the_breaks():
    """Like Matlab's detrend(x, 'linear', bp): one continuous trend, so a jump at a break is not removed."""
    t = np.arange(0.0, 30.0, 0.01)
    jump = (t >= 10.0).astype(float)
    out = detrend_piecewise(t, jump)
    trend = jump - out
    assert np.abs(out).max() > 0.3  # the jump stays in the detrended signal
    assert np.abs(np.diff(trend)).max() < 0.01  # no jump in the trend
    away = (np.abs(t[1:-1] - 10.0) > 0.015) & (np.abs(t[1:-1] - 20.0) > 0.015)
    assert_allclose(np.diff(trend, 2)[away], 0.0, atol=1e-10)  # linear between the breaks at 10 and 20 s


def test_detrend_period_sets_the_breaks():
    t = np.arange(0.0, 20.0, 0.01)
    trend = np.interp(t, [0, 5, 10, 15, 20], [0, 1, 0, 1, 0])
    assert_allclose(detrend_piecewise(t, trend, period=5.0), 0.0, atol=1e-9)
    assert np.abs(detrend_piecewise(t, trend, period=10.0)).max() > 0.1


def test_the_old_disturbance_keyword_is_a_deprecated_name_of_the_wind_torque():
    from heli_core.physics import simulate as core_simulate

    t = np.arange(200) * 0.01
    sticks = np.zeros((4, t.size))
    torque = np.full((3, t.size), 0.5)
    from identification.bench.flight_config import PAPER_PARAMS as PAPER

    new = core_simulate(PAPER, t, sticks, torque=torque)
    with pytest.warns(DeprecationWarning, match="torque"):
        old = core_simulate(PAPER, t, sticks, disturbance=torque)
    np.testing.assert_array_equal(new, old)


def test_servo_settings_per_axis_are_parsed_once_for_both_identifiers():
    from heli_core.servo import per_axis
    from identification.integral.method import IntegralIdentifier
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier

    assert per_axis("delay", None, 2.0) == [0.0, 0.0, 0.0] and per_axis("delay", "auto", 2.0) == ["auto"] * 3
    assert per_axis("servo_lag", 0.03, 1.0) == [0.03] * 3 and per_axis("delay", (0.1, 0, 0.2), 2.0) == [0.1, 0, 0.2]
    # words on some axes, seconds on others (the diagnosis' final fit: found delays kept, the rest detected)
    assert per_axis("delay", [0.02, 0.0, "detect"], 2.0, ("auto", "detect")) == [0.02, 0.0, "detect"]
    with pytest.raises(ValueError, match="delay must be"):
        per_axis("delay", [0.02, "sometimes", 0.0], 2.0, ("auto", "detect"))
    for bad, says in (("slow", "delay must be None, 'auto'"), ([0.1, 0.2], "delay needs one value per axis"),
                      (-0.1, r"delay must be .* in \[0, 2\], got -0.1")):
        with pytest.raises(ValueError, match=says):
            IntegralIdentifier(delay=bad)._delays()
        with pytest.raises(ValueError, match="delay"):
            MaximumLikelihoodIdentifier(delay=bad)._delays()


def test_a_servo_faster_than_the_sample_is_simulated_in_sub_steps_it_can_follow():
    """A 5 ms servo delay on a 50 Hz log (what a thinned log's fit can keep): one RK4 step a sample leaves the
    Padé pole's stability region and the simulation runs away; the default takes the sub-steps the servo needs and
    agrees with a fine-step simulation."""
    from heli_core.physics import simulate, stable_substeps

    params = ModelParams(k2=1.3, k3=2.8, k6=-0.9, k7=3.0, k10=13.0, k11=3.8, tau_roll=0.005, tau_pitch=0.005,
                         tau_yaw=0.005)
    time = np.arange(500) * 0.02
    sticks = np.zeros((4, time.size))
    sticks[0] = 0.3 * np.sign(np.sin(time * 2.0))
    assert stable_substeps(params, 0.02) == 4 and stable_substeps(ModelParams(), 0.02) == 1
    with np.errstate(all="ignore"):
        coarse = simulate(params, time, sticks, substeps=1)
    assert not np.all(np.abs(coarse[0]) < 100.0)  # NaN or beyond any rotor's rate
    fine = simulate(params, time, sticks, substeps=40)
    np.testing.assert_allclose(simulate(params, time, sticks)[0], fine[0], atol=1e-3)
