"""Tests of the PD design and policy (:mod:`controllers.pd`).

Hand computations use the decoupled roll model of eq. (18), ``p' = -a p + k u``:
its stick-to-angle plant is ``k / (s (s + a))`` and, sampled with a zero-order
hold at ``T``, ``k G(z)`` with the textbook

    G(z) = ((aT - 1 + e) z + (1 - e - aT e)) / (a^2 (z - 1)(z - e)),   e = exp(-aT)

for the angle and ``k (1 - e) / (a (z - e))`` for the rate. Closed-loop checks
run :class:`heli_env.env.HeliAttitudeEnv` (the shipped model) and the physics
core :func:`heli_core.discrete.discrete_step`.
"""

from __future__ import annotations

import json
import math

import control
import gymnasium
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.optimize import brentq

import heli_env  # noqa: F401  (registers HeliAttitude-v0)
from controllers.pd import (
    PDController,
    PDGains,
    closed_loop_bandwidth,
    control_sign,
    design_gains,
    loop_analysis,
    plant,
    plot_bode,
    plot_step_responses,
    propose_gains,
)
from heli_core.discrete import discrete_step
from heli_core.params import ModelParams
from heli_core.physics import initial_state
from heli_core.quaternion import euler_from_quaternion
from heli_env.env import HeliAttitudeEnv
from heli_env.env_model import load_env_model

DT = 0.01
K2, K3 = 1.5, 2.0  # a simple roll axis [rad/s^2 per stick], [1/s]
SIMPLE = ModelParams(k2=K2, k3=K3, k6=-0.9, k7=2.5, k10=13.0, k11=3.4, tau_roll=0.04)


@pytest.fixture(scope="module")
def default_params():
    return load_env_model().params


@pytest.fixture(scope="module")
def default_gains(default_params):
    return design_gains(default_params)


def _zoh_angle_rate(k, a, T, z):
    """Hand-derived ZOH responses of k/(s(s+a)) (angle) and k/(s+a) (rate) at z."""
    e = math.exp(-a * T)
    g_angle = k * ((a * T - 1 + e) * z + (1 - e - a * T * e)) / (a * a * (z - 1) * (z - e))
    g_rate = k * (1 - e) / (a * (z - e))
    return g_angle, g_rate


# --------------------------------------------------------------------- plant
def test_plant_poles_zeros_gain_without_delay():
    P = plant(SIMPLE, "pitch")
    assert_allclose(np.sort(control.poles(P).real), [-2.5, 0.0], atol=1e-12)
    assert control.zeros(P).size == 0
    assert_allclose(P(1j * 3.0), -0.9 / (3j * (3j + 2.5)), rtol=1e-12)
    # rate DC gain k6/k7, sign kept (k6 < 0 as in the paper's eq. 69)
    assert_allclose(plant(SIMPLE, "pitch", output="rate").dcgain(), -0.9 / 2.5, rtol=1e-12)


def test_plant_with_pade_servo():
    """tau_roll = 0.04 s: first-order Padé (eq. 31) adds a pole at -2/tau and a zero at +2/tau."""
    P = plant(SIMPLE, "roll")
    assert_allclose(np.sort(control.poles(P).real), [-50.0, -K3, 0.0], atol=1e-9)
    assert_allclose(control.zeros(P).real, [50.0], rtol=1e-9)
    assert_allclose(plant(SIMPLE, "roll", output="rate").dcgain(), K2 / K3, rtol=1e-12)
    s = 7j
    assert_allclose(P(s), K2 * (50.0 - s) / (50.0 + s) / (s * (s + K3)), rtol=1e-10)


def test_plant_ignores_coupling_terms():
    coupled = SIMPLE.with_values(k1=0.3, k4=0.5, k5=-0.2, k8=0.4, kd1=0.1)
    for axis in ("roll", "pitch", "yaw"):
        a, b = plant(SIMPLE, axis), plant(coupled, axis)
        assert_allclose(b(2j), a(2j), rtol=1e-12)


# ------------------------------------------------------------------- margins
def test_margins_match_hand_computation_continuous():
    """P control of k/(s(s+a)): |L| = 1 at wc^2 = (sqrt(a^4 + 4K^2) - a^2)/2, PM = 90 - atan(wc/a)."""
    kp = 4.0
    K = K2 * kp
    an = loop_analysis(SIMPLE.with_values(tau_roll=0.0), "roll", kp, 0.0, dt=0)
    wc = math.sqrt((math.sqrt(K3 ** 4 + 4 * K * K) - K3 ** 2) / 2)
    assert_allclose(an.gain_crossover, wc, rtol=1e-9)
    assert_allclose(an.phase_margin, 90 - math.degrees(math.atan(wc / K3)), rtol=1e-9)
    assert math.isinf(an.gain_margin)
    # T = K/(s^2 + a s + K) drops 3 dB (|T| = g = 10^(-3/20), as control.bandwidth) at the root w^2 of
    # w^4 + (a^2 - 2K) w^2 + K^2 (1 - 1/g^2) = 0
    g2 = 10 ** (-3 / 10)
    wb = math.sqrt((2 * K - K3 ** 2 + math.sqrt((K3 ** 2 - 2 * K) ** 2 - 4 * K * K * (1 - 1 / g2))) / 2)
    assert_allclose(an.bandwidth, wb, rtol=1e-8)
    # closed-loop poles of s^2 + (a + k kd) s + k kp with kd = 0
    assert_allclose(np.sort_complex(an.poles), np.sort_complex(np.roots([1, K3, K])), rtol=1e-10)


def test_margins_match_hand_computation_sampled():
    """PD on the ZOH'd loop: crossover, phase margin and the gain margin at Nyquist from the z-transforms."""
    kp, kd = 6.0, 0.8
    an = loop_analysis(SIMPLE.with_values(tau_roll=0.0), "roll", kp, kd, dt=DT)

    def L(w):
        ga, gr = _zoh_angle_rate(K2, K3, DT, np.exp(1j * w * DT))
        return kp * ga + kd * gr

    wc = brentq(lambda w: abs(L(w)) - 1.0, 0.1, 100.0, xtol=1e-13)
    assert_allclose(an.gain_crossover, wc, rtol=1e-7)
    assert_allclose(an.phase_margin, 180.0 + math.degrees(np.angle(L(wc))), rtol=1e-7)
    # the sampled PD loop reaches -180 deg at the Nyquist frequency (z = -1), where L is real and negative
    assert L(math.pi / DT).real < 0
    assert_allclose(an.phase_crossover, math.pi / DT, rtol=1e-12)
    assert_allclose(an.gain_margin, 1.0 / abs(L(math.pi / DT)), rtol=1e-9)
    # ... and that gain margin is where the loop goes unstable
    g = an.gain_margin
    assert loop_analysis(SIMPLE.with_values(tau_roll=0.0), "roll", 0.99 * g * kp, 0.99 * g * kd).stable
    assert not loop_analysis(SIMPLE.with_values(tau_roll=0.0), "roll", 1.01 * g * kp, 1.01 * g * kd).stable


@pytest.mark.parametrize("delayed, tol", [(False, 2e-4), (True, 2e-3)], ids=["no-servo-delay", "servo-delay"])
def test_disturbance_transfer_matches_physics_core(default_params, delayed, tol):
    """torque_to_angle replayed with control.forced_response equals the closed loop stepped by discrete_step
    (with a servo delay the Padé state's initial value and the attitude's mean-rate rotation differ by more)."""
    params = default_params.with_values(kd1=0.0, kd2=0.0, kd3=0.0)  # no trim needed
    if not delayed:
        params = params.with_values(tau_roll=0.0, tau_pitch=0.0, tau_yaw=0.0)
    kp, kd = 30.0, 2.0
    an = loop_analysis(params, "roll", kp, kd, dt=DT)
    rng = np.random.default_rng(0)
    n = 400
    d = np.repeat(rng.normal(0.0, 0.3, n // 20), 20)  # gust torque [rad/s^2], held
    x = tuple(initial_state())
    angle = np.zeros(n)
    for k in range(n):
        phi = euler_from_quaternion(np.array(x[6:10]))[0]
        angle[k] = phi
        u = an.sign * (kp * (-phi) + kd * (-x[0]))
        assert abs(u) < 1  # linear range
        x = discrete_step(x, (u, 0.0, 0.0, 0.0), (d[k], 0.0, 0.0), params, DT)
    predicted = control.forced_response(an.torque_to_angle, T=np.arange(n) * DT, U=d).outputs
    assert_allclose(angle, predicted, atol=tol * np.max(np.abs(predicted)))
    # the equivalent-stick channel is the same loop scaled by the control gain (eq. 42); DC: s/kp
    assert_allclose(an.ud_to_angle.dcgain(), an.sign / kp, rtol=1e-9)
    assert_allclose(an.ud_to_angle(np.exp(0.5j)), params.k2 * an.torque_to_angle(np.exp(0.5j)), rtol=1e-12)


# ------------------------------------------------------------------ design
@pytest.mark.parametrize("axis", ["roll", "pitch", "yaw"])
def test_proposed_gains_meet_request(default_params, axis):
    kp, kd, an = propose_gains(default_params, axis, bandwidth=10.0, phase_margin=50.0)
    assert kp > 0 and kd >= 0 and an.stable
    assert_allclose(an.bandwidth, 10.0, rtol=1e-6)
    assert an.phase_margin >= 50.0 - 1e-6
    assert_allclose(closed_loop_bandwidth(an.complementary), 10.0, rtol=1e-6)


def test_proposed_gains_with_servo_delay():
    """With the Padé servo (tau_roll = 0.04 s) the achievable bandwidth is lower, and still met."""
    kp, kd, an = propose_gains(SIMPLE, "roll", bandwidth=6.0, phase_margin=45.0)
    assert an.stable and an.phase_margin >= 45.0 - 1e-6
    assert_allclose(an.bandwidth, 6.0, rtol=1e-6)
    with pytest.raises(ValueError, match=r"cannot reach a bandwidth of 60 rad/s .* at most [\d.]+ deg"):
        propose_gains(SIMPLE, "roll", bandwidth=60.0, phase_margin=45.0)


def test_default_bandwidth(default_params, default_gains):
    """None: five times the bare rate pole (k3 for roll)."""
    kp, kd, an = propose_gains(default_params, "roll")
    assert_allclose(an.bandwidth, 5 * default_params.k3, rtol=1e-6)
    assert (kp, kd) == default_gains.axis("roll")


def test_infeasible_request_says_best_margin(default_params):
    with pytest.raises(ValueError, match=r"roll: .*cannot reach a bandwidth of 500 rad/s.*largest bandwidth is"):
        propose_gains(default_params, "roll", bandwidth=500.0)
    with pytest.raises(ValueError, match=r"phase_margin must be in \(0, 180\)"):
        propose_gains(default_params, "roll", bandwidth=5.0, phase_margin=-5.0)
    with pytest.raises(ValueError, match="bandwidth must be a positive"):
        propose_gains(default_params, "roll", bandwidth=-1.0)


# ------------------------------------------------- prediction vs environment
def _roll_run(params, base, kp, kd, seconds=10.0):
    """Gust-free hold in the environment with (kp, kd) on roll; |roll error| and |lat action| per step."""
    env = HeliAttitudeEnv(task="hold", gust_scale=0.0, episode_seconds=seconds, init_angle_deg=1.0,
                          init_rate_deg=1.0, obs_noise=0.0)  # a decay by 1000 is seen below the sensor noise
    gains = PDGains(kp=(kp, base.kp[1], base.kp[2]), kd=(kd, base.kd[1], base.kd[2]))
    pol = PDController.from_model(params, gains)
    obs, _ = env.reset(seed=3)
    err, act = [abs(obs[0])], []
    terminated = truncated = False
    while not (terminated or truncated):
        a, _ = pol.predict(obs)
        obs, _, terminated, truncated, _ = env.step(a)
        err.append(abs(obs[0]))
        act.append(abs(a[0]))
    return np.array(err), np.array(act), terminated


@pytest.mark.parametrize("scale_or_gains, continuous_says", [
    (1.0, True),            # the proposed design (6 dB, 45 deg with the shipped model's 45 ms servo delay)
    (5.0, True),            # just inside the gain margin (15.7 dB = 6.1x)
    (7.0, True),            # just outside it: the sampled loop is unstable, the continuous one is not
    ((2000.0, 0.0), False),  # high P
    ((0.0, 170.0), False),  # high D: the rate loop oscillates at the Nyquist frequency
    ((20.0, 3.0), True),
])
def test_predicted_stability_matches_environment(default_params, default_gains, scale_or_gains, continuous_says):
    """Stability predicted on the sampled loop agrees with the environment; the continuous analysis would not."""
    kp0, kd0, _ = propose_gains(default_params, "roll")
    kp, kd = (scale_or_gains * kp0, scale_or_gains * kd0) if np.ndim(scale_or_gains) == 0 else scale_or_gains
    an = loop_analysis(default_params, "roll", kp, kd, dt=DT)
    assert loop_analysis(default_params, "roll", kp, kd, dt=0).stable == continuous_says
    err, act, terminated = _roll_run(default_params, default_gains, kp, kd)
    first, last = err[:100].max(), err[-100:].max()
    if an.stable:  # decays: error down by 1000, stick back at trim
        assert not terminated and last < 1e-3 * first and act[-100:].max() < 1e-2
    else:  # grows until the stick saturates: a limit cycle at the stick limit in the last second (or a crash)
        assert terminated or act[-100:].max() >= 0.99


@pytest.mark.parametrize("factor, stable", [(0.9, True), (1.1, False)])
def test_action_delay_boundary_matches_environment(default_params, default_gains, factor, stable):
    """Three periods of action delay (``action_delay=3``): 10 % inside / outside the predicted gain margin."""
    kp0, kd0, an0 = propose_gains(default_params, "roll", delay_steps=3)
    g = factor * an0.gain_margin
    assert loop_analysis(default_params, "roll", g * kp0, g * kd0, delay_steps=3).stable is stable
    env = HeliAttitudeEnv(task="hold", gust_scale=0.0, episode_seconds=10.0, init_angle_deg=1.0, init_rate_deg=1.0,
                          action_delay=3, obs_noise=0.0)
    pol = PDController.from_model(default_params, PDGains(kp=(g * kp0, 0.0, 0.0), kd=(g * kd0, 0.0, 0.0)))
    obs, _ = env.reset(seed=3)
    first, act = abs(obs[0]), []
    for _ in range(1000):
        a, _ = pol.predict(obs)
        obs, _, terminated, truncated, _ = env.step(a)
        act.append(abs(a[0]))
        if terminated or truncated:
            break
    assert (max(act[-100:]) < 1e-2 and abs(obs[0]) < 1e-3 * first) if stable else (terminated or max(act[-100:]) >= 0.99)


def test_pd_holds_level_in_gusts(default_params, default_gains):
    env = HeliAttitudeEnv(episode_seconds=10.0)
    pol = PDController.from_model(default_params, default_gains)
    p90 = {}
    for name, policy in (("pd", pol), ("zero", None)):
        errs = []
        for seed in range(3):
            obs, _ = env.reset(seed=seed)
            done = False
            while not done:
                a = policy.predict(obs)[0] if policy else np.zeros(3, dtype=np.float32)
                obs, _, term, trunc, info = env.step(a)
                done = term or trunc
                errs.append(np.abs(info["attitude_error_deg"]))
        p90[name] = np.percentile(np.array(errs), 90)
    assert p90["pd"] < 0.05 * p90["zero"], p90
    assert p90["pd"] < 1.0  # degrees


# ------------------------------------------------------------------ policy
def test_predict_single_and_batch(default_params):
    gains = PDGains(kp=(2.0, 3.0, 4.0), kd=(0.5, 0.25, 0.1))
    pol = PDController.from_model(default_params, gains)
    assert pol.signs == (1.0, -1.0, 1.0)  # k6 < 0
    rng = np.random.default_rng(1)
    obs = rng.normal(0.0, 0.2, (5, 12)).astype(np.float32)
    act, state = pol.predict(obs, state=None, episode_start=np.ones(5, bool), deterministic=True)
    assert act.shape == (5, 3) and act.dtype == np.float32 and state is None
    want = np.clip(np.array([1, -1, 1]) * (np.array(gains.kp) * obs[:, 0:3] + np.array(gains.kd) * obs[:, 6:9]),
                   -1, 1)
    assert_allclose(act, want, rtol=1e-6, atol=1e-7)
    single, _ = pol.predict(obs[2])
    assert single.shape == (3,) and single.dtype == np.float32
    assert_allclose(single, act[2])
    big, _ = pol.predict(np.full(12, 10.0))
    assert_allclose(big, [1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match=r"observation must have shape \(12,\) or \(n, 12\)"):
        pol.predict(np.zeros(11))


def test_save_load_round_trip(tmp_path, default_params, default_gains):
    pol = PDController.from_model(default_params, default_gains)
    path = pol.save(tmp_path / "pd.json", metadata={"model": "default"})
    loaded = PDController.load(path)
    assert loaded.gains == pol.gains and loaded.signs == pol.signs
    obs = np.random.default_rng(2).normal(0, 0.3, (7, 12))
    assert_allclose(loaded.predict(obs)[0], pol.predict(obs)[0])
    doc = json.loads(path.read_text())
    assert doc["schema"] == "heli-env/pd-controller" and doc["metadata"] == {"model": "default"}
    assert not list(tmp_path.glob(".*tmp"))  # atomic write left nothing behind
    (tmp_path / "other.json").write_text(json.dumps({"schema": "heli-env/model"}))
    with pytest.raises(ValueError, match="expected schema 'heli-env/pd-controller'"):
        PDController.load(tmp_path / "other.json")
    doc["kp"] = [1.0, -2.0, 3.0]
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="kp must be >= 0"):
        PDController.load(tmp_path / "bad.json")


def test_evaluate_policy_single_and_vec_env(default_params, default_gains):
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import DummyVecEnv

    def mean_reward(policy):  # both flown on the same two seeded episodes (unseeded, a calm draw for the zero
        # gains beside a gusty one for the PD made the PD lose: -8.08 against -7.63 on one clean clone)
        single = DummyVecEnv([lambda: gymnasium.make("HeliAttitude-v0", episode_seconds=2.0)])
        single.seed(0)
        return evaluate_policy(policy, single, n_eval_episodes=2, warn=False)[0]

    pol = PDController.from_model(default_params, default_gains)
    assert mean_reward(pol) > mean_reward(PDController(PDGains(0.0, 0.0)))
    venv = DummyVecEnv([lambda: gymnasium.make("HeliAttitude-v0", episode_seconds=2.0)] * 2)
    rewards, lengths = evaluate_policy(pol, venv, n_eval_episodes=4, warn=False, return_episode_rewards=True)
    assert len(rewards) == 4 and all(n == 200 for n in lengths)


# -------------------------------------------------------------- bad inputs
def test_bad_gains_raise():
    with pytest.raises(ValueError, match="kp must be >= 0"):
        PDGains(kp=-1.0, kd=0.0)
    with pytest.raises(ValueError, match="kd must be finite"):
        PDGains(kp=1.0, kd=(0.0, float("nan"), 0.0))
    with pytest.raises(ValueError, match=r"kp must be a number or 3 numbers"):
        PDGains(kp=(1.0, 2.0), kd=0.0)
    with pytest.raises(ValueError, match=r"axis must be one of"):
        loop_analysis(SIMPLE, "heave", 1.0, 0.1)
    with pytest.raises(ValueError, match="dt must be a control period"):
        loop_analysis(SIMPLE, "roll", 1.0, 0.1, dt=-0.01)
    with pytest.raises(ValueError, match="signs must be three values of"):
        PDController(PDGains(1.0, 0.1), signs=(1, 0, 1))
    with pytest.raises(ValueError, match="yaw control gain k10 is 0"):
        control_sign(ModelParams(k2=1.0, k6=1.0), "yaw")


# ----------------------------------------------------------------- figures
def test_figures(tmp_path, default_params, default_gains):
    steps = plot_step_responses(default_params, default_gains, tmp_path / "steps.png")
    bode = plot_bode(default_params, "pitch", *default_gains.axis("pitch"), tmp_path / "bode.png")
    for p in (steps, bode):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ------------------------------------------------------------ derivative filter
def _flown(pol, params, seconds=5.0, seed=0, **env_kwargs):
    """Fly ``pol`` in one fixed episode (``predict`` carrying its state); actions (n, 3) and |roll error| (n,)."""
    env = HeliAttitudeEnv(episode_seconds=seconds, **env_kwargs)
    obs, _ = env.reset(seed=seed)
    state, start, acts, errs = None, True, [], []
    done = False
    while not done:
        a, state = pol.predict(obs, state=state, episode_start=np.array([start]))
        start = False
        obs, _, term, trunc, info = env.step(a)
        acts.append(a)
        errs.append(abs(info["attitude_error_deg"][0]))
        done = term or trunc
    return np.array(acts), np.array(errs)


def test_d_filter_off_reproduces_the_unfiltered_pd_exactly(default_params, default_gains):
    """No filter (the default, or None on every axis) is the old memoryless law, bit for bit, and so is the
    sweep's replay with zero poles."""
    from controllers.closed_loop import hover_plant, nominal_gains
    from controllers.replay import Autopilot, fly, zoh_step
    from controllers.sweep_inputs import prepare

    old = PDController.from_model(default_params, default_gains)
    off = PDController.from_model(default_params, PDGains(default_gains.kp, default_gains.kd, (None, None, None)))
    assert not off.filtered and off.gains == old.gains
    obs = np.random.default_rng(4).normal(0.0, 0.3, (6, 12))
    want = np.clip(np.array(old.signs) * (np.array(old.gains.kp) * obs[:, 0:3] + np.array(old.gains.kd)
                                          * obs[:, 6:9]), -1, 1).astype(np.float32)
    act, state = off.predict(obs, state="untouched", episode_start=np.ones(6, bool))
    assert_array_equal(act, want)
    assert state == "untouched"
    assert_array_equal(off.step(obs)[0], old.command(obs))
    rp = prepare(None, "roll", 2.0, 0.01, 0, None, 2)
    nominal = nominal_gains(hover_plant(rp.params, 0.01))
    runs = [[rec for _, rec in fly(zoh_step(rp.params, 0.01), rp.inputs,
                                   Autopilot(0, np.array([20.0]), np.array([3.0]), nominal,
                                             np.sign(rp.params.control_gains), poles), progress=False)][0]
            for poles in (None, [0.0, 0.0, 0.0])]
    assert_array_equal(runs[0].act, runs[1].act)
    assert_array_equal(runs[0].att, runs[1].att)


def test_d_filter_reduces_the_stick_increment_on_a_fixed_episode(default_params, default_gains):
    """The same gains with a 5 Hz filter on one fixed episode (gusts and the model's gyro noise): the stick's RMS
    increment per step falls by more than half, the attitude error hardly moves."""
    plain, p_err = _flown(PDController.from_model(default_params, default_gains), default_params)
    filtered_gains = PDGains(default_gains.kp, default_gains.kd, 5.0)
    smooth, s_err = _flown(PDController.from_model(default_params, filtered_gains), default_params)
    step = [np.sqrt(np.mean(np.diff(a, axis=0) ** 2, axis=0)) for a in (plain, smooth)]
    assert np.all(step[1][:2] < 0.5 * step[0][:2]), step  # roll and pitch (measured 0.46x)
    assert np.percentile(s_err, 90) < 1.1 * np.percentile(p_err, 90)


def test_d_filter_state_resets_on_episode_start_and_is_vectorised(default_params):
    """A batch flies as each of its rows alone; a row whose episode starts restarts its filter at the current
    rate error, the others keep their memory; a single observation takes a (1,) episode_start (SB3's)."""
    pol = PDController.from_model(default_params, PDGains((2.0, 3.0, 4.0), (0.5, 0.25, 0.1), (4.0, None, 9.0)))
    obs = np.random.default_rng(5).normal(0.0, 0.2, (20, 3, 12))
    state, batch = None, []
    for k in range(20):
        a, state = pol.predict(obs[k], state, np.full(3, k == 0))
        batch.append(a)
    for r in range(3):
        s1 = None
        for k in range(20):
            a1, s1 = pol.predict(obs[k, r], s1, np.array([k == 0]))
            assert_array_equal(a1, batch[k][r])
    a, s = pol.predict(obs[0], state, np.array([False, True, False]))
    fresh, _ = pol.predict(obs[0, 1], None)
    assert_array_equal(a[1], fresh)
    assert not np.array_equal(a[0], pol.predict(obs[0, 0], None)[0])  # row 0 remembered its filter
    assert_allclose(s[:, 1], obs[0][:, 7])  # the unfiltered pitch passes the rate error through
    with pytest.raises(ValueError, match=r"state must be the filter state .* shape \(3, 3\), got \(2, 3\)"):
        pol.predict(obs[0], np.zeros((2, 3)))
    with pytest.raises(ValueError, match="episode_start must hold one flag per observation"):
        pol.predict(obs[0], state, np.ones(2, bool))


def test_d_filter_linearisation_matches_the_sampled_loop(default_params, default_gains):
    """The filtered loop of loop_analysis is s (kp G_angle + kd F G_rate) with F(z) = (1 - a) z / (z - a) on the
    hand-derived ZOH plant, and its gain margin is the environment's: 5 % inside it the filtered PD holds,
    5 % outside it does not."""
    f_c, a = 8.0, math.exp(-2 * math.pi * 8.0 * DT)
    kp, kd = 10.0, 2.0
    an = loop_analysis(SIMPLE.with_values(tau_roll=0.0), "roll", kp, kd, dt=DT, d_filter_hz=f_c)
    for w in (0.5, 3.0, 20.0, 150.0):
        z = np.exp(1j * w * DT)
        g_angle, g_rate = _zoh_angle_rate(K2, K3, DT, z)
        want = kp * g_angle + kd * (1 - a) * z / (z - a) * g_rate
        assert_allclose(complex(an.loop(z)), want, rtol=1e-9)
    kp0, kd0, an0 = propose_gains(default_params, "roll", d_filter_hz="auto")
    assert an0.d_filter_hz and an0.phase_margin >= 45.0 - 1e-6
    for factor, holds in ((0.95, True), (1.05, False)):
        g = factor * an0.gain_margin
        pol = PDController.from_model(default_params, PDGains((g * kp0, 0, 0), (g * kd0, 0, 0), an0.d_filter_hz))
        acts, errs = _flown(pol, default_params, seconds=10.0, seed=3, task="hold", gust_scale=0.0,
                            init_angle_deg=1.0, init_rate_deg=1.0, obs_noise=0.0)
        assert loop_analysis(default_params, "roll", g * kp0, g * kd0, d_filter_hz=an0.d_filter_hz).stable is holds
        if holds:
            assert errs[-100:].max() < 1e-3 * errs[:100].max()
        else:
            assert len(errs) < 1000 or np.abs(acts[-100:, 0]).max() >= 0.99


def test_d_filter_design_rule_and_round_trip(tmp_path, default_params):
    """"auto" puts the cutoff at D_FILTER_RATIO x crossover and keeps the margin; the filter travels in the
    controller file (schema version 2) and an unfiltered file stays version 1."""
    from controllers.pd import D_FILTER_RATIO

    gains = design_gains(default_params, d_filter_hz="auto")
    for i, axis in enumerate(("roll", "pitch", "yaw")):
        an = loop_analysis(default_params, axis, gains.kp[i], gains.kd[i], d_filter_hz=gains.d_filter_hz[i])
        assert an.phase_margin >= 45.0 - 1e-6
        assert_allclose(gains.d_filter_hz[i], D_FILTER_RATIO * an.gain_crossover / (2 * math.pi), rtol=1e-6)
    pol = PDController.from_model(default_params, gains, dt=0.02)
    loaded = PDController.load(pol.save(tmp_path / "pd.json"))
    assert loaded.gains == pol.gains and loaded.dt == 0.02
    assert json.loads((tmp_path / "pd.json").read_text())["schema_version"] == 2
    obs = np.random.default_rng(6).normal(0, 0.3, (4, 12))
    assert_array_equal(loaded.predict(obs)[0], pol.predict(obs)[0])
    with pytest.raises(ValueError, match=r"d_filter_hz must be a cutoff frequency > 0 Hz or None \(no filter\), got -1"):
        PDGains(1.0, 1.0, -1)
    with pytest.raises(ValueError, match="d_filter_hz must be None, a cutoff in Hz or 3 of them"):
        PDGains(1.0, 1.0, (1.0, 2.0))
