"""The firmware loops (controllers.firmware): hand-computed ticks, the linearisation, the plain cross-check.

Hand-computed steps of the firmware equations (a step, a ramp, saturation, the leak) for ArduPilot's heli
loop and Rotorflight's pid_mode 3; with the filters off, I and FF zero, the linearisation equals the PD it
maps to (and the sweep's PD machinery gives the same errors and margins); and a second, plain
implementation of each firmware written apart (tests/firmware_plain_loop.py, used only here and by
scripts/firmware_tune_check.py) reproduces the package's ticks and closed-loop flights.
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from controllers.firmware import ArduPilotHeli, ArduPilotHeliParams, Rotorflight, RotorflightParams
from controllers.firmware.ardupilot import sqrt_controller
from controllers.firmware.errors import FirmwareMappingError
from controllers.firmware.linear import attitude_std, closed_loop, linearise, stick_margins

import firmware_plain_loop as plain

DT = 1.0 / 400.0
NO_FILTERS_AP = dict(rat_fltt=0.0, rat_flte=0.0, rat_fltd=0.0, gyro_filter_hz=0.0)
NO_FILTERS_RF = dict(gyro_cutoff=0.0, gyro_lpf1_hz=0.0, relax=False, decay_time_cyclic=0.0)


def ap_tick(loop, memory, e, g):
    out, memory, sat = loop.tick(memory, np.asarray(e, float), np.asarray(g, float))
    return out, memory, sat


# --------------------------------------------------------------------------------------------- ArduPilot
def test_ardupilot_step_by_hand():
    """One tick of the default loop after a 0.1 rad roll step, computed from the firmware's equations."""
    loop = ArduPilotHeli(ArduPilotHeliParams())
    out, mem, _ = ap_tick(loop, loop.initial_memory(), [0.1, 0.0, 0.0], [0.0, 0.0, 0.0])
    a20 = DT / (DT + 1.0 / (2 * math.pi * 20.0))  # FLTT = FLTE = 20 Hz
    target = a20 * (4.5 * 0.1)  # linear band of the square-root controller
    error = a20 * target
    derivative = error / DT  # FLTD = 0: no filter
    integrator = 0.15 * error * DT
    expected = 0.024 * error + integrator + 0.001 * derivative + 0.15 * target
    assert_allclose(out[0], expected, rtol=1e-12)
    assert_allclose(mem[2:6, 0], [target, error, derivative, integrator], rtol=1e-12)
    assert out[1] == 0.0 and out[2] == 0.0


def test_ardupilot_gyro_ramp_without_filters():
    """Filters off, I and FF 0: the output is ``P·(−g) + D·(−Δg/dt)`` on a gyro ramp, tick after tick."""
    p = ArduPilotHeliParams(**NO_FILTERS_AP, rat_i=0.0, rat_ff=0.0, rat_p=(0.05, 0.05, 0.2), rat_d=(0.002,) * 3)
    loop = ArduPilotHeli(p)
    mem = loop.initial_memory()
    slope = 0.4  # rad/s per tick
    for k in range(1, 6):
        out, mem, _ = ap_tick(loop, mem, [0.0, 0.0, 0.0], [slope * k, 0.0, 0.0])
        expected = -0.05 * slope * k + 0.002 * (-slope / DT if k > 1 else -slope * k / DT)
        assert_allclose(out[0], expected, rtol=1e-12)


def test_ardupilot_sqrt_controller_branches():
    """Linear band, square-root branch, the per-tick limit (AP_Math sqrt_controller)."""
    p, lim = 4.5, math.radians(550.0)  # ACCEL_R_MAX 110000 cdeg/s/s, halved
    linear_dist = lim / p**2
    e = np.array([0.5 * linear_dist, 2 * linear_dist, -3 * linear_dist])
    got = sqrt_controller(e, p, lim, DT)
    assert_allclose(got[0], p * e[0])
    assert_allclose(got[1], math.sqrt(2 * lim * (e[1] - linear_dist / 2)))
    assert_allclose(got[2], -math.sqrt(2 * lim * (-e[2] - linear_dist / 2)))
    assert_allclose(sqrt_controller(np.array([1e-4]), 1000.0, 0.0, DT), [1e-4 / DT])  # at most |e|/dt


def test_ardupilot_saturation_and_cyclic_limit():
    """A large error clamps the output to ±1, the cyclic circle scales roll and pitch, and the integrator
    stops growing while limited (AC_PID::update_i)."""
    loop = ArduPilotHeli(ArduPilotHeliParams(cyc_max=2500.0, rat_p=(0.3, 0.3, 0.18)))
    mem = loop.initial_memory()
    for _ in range(200):
        out, mem, sat = ap_tick(loop, mem, [0.4, 0.4, 0.0], [0.0, 0.0, 0.0])
    assert_allclose(math.hypot(out[0], out[1]), 2500.0 / 4500.0, rtol=1e-12)
    assert sat[0] and sat[1] and mem[6, 0] == 1.0
    frozen = mem[5, 0]
    out, mem, _ = ap_tick(loop, mem, [0.4, 0.4, 0.0], [0.0, 0.0, 0.0])
    assert mem[5, 0] <= frozen + 1e-15  # I does not grow while the motors are limited
    loop = ArduPilotHeli(ArduPilotHeliParams(**NO_FILTERS_AP, rat_p=(0.35,) * 3))
    out, _, sat = ap_tick(loop, loop.initial_memory(), [0.0, 0.0, 0.0], [0.0, 0.0, -10.0])
    assert out[2] == 1.0 and sat[2]  # P·10 rad/s = 3.5, clamped


def test_ardupilot_leak():
    """Above ILMI the roll integrator loses 2 % of its excess per tick; below it nothing; yaw never leaks."""
    p = ArduPilotHeliParams(**NO_FILTERS_AP, rat_ilmi=(0.05, 0.05, 0.05))
    loop = ArduPilotHeli(p)
    mem = loop.initial_memory()
    mem[5] = [0.3, 0.04, 0.3]
    for k in range(1, 4):
        _, mem, _ = ap_tick(loop, mem, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
        assert_allclose(mem[5], [0.05 + 0.25 * 0.98**k, 0.04, 0.3], rtol=1e-12)


def test_ardupilot_batch_of_sets_equals_each_set():
    sets = [ArduPilotHeliParams(), ArduPilotHeliParams(rat_p=(0.1, 0.08, 0.3), ang_p=(6.0, 5.0, 4.0))]
    batch = ArduPilotHeli(sets)
    rng = np.random.default_rng(1)
    e, g = rng.normal(0, 0.1, (3, 2, 4)), rng.normal(0, 0.5, (3, 2, 4))
    mem = batch.initial_memory((2, 4))
    one = [ArduPilotHeli(s) for s in sets]
    mems = [o.initial_memory((4,)) for o in one]
    for _ in range(5):
        out, mem, _ = batch.tick(mem, e, g)
        for j, o in enumerate(one):
            o_out, mems[j], _ = o.tick(mems[j], e[:, j], g[:, j])
            assert_allclose(out[:, j], o_out, rtol=1e-13, atol=1e-15)


# ------------------------------------------------------------------------------------------- Rotorflight
def test_rotorflight_step_by_hand():
    """One tick after a 2 deg roll step: P, F and D of pid_mode 3 in deg/s and mixer units, by hand."""
    p = RotorflightParams(**{**NO_FILTERS_RF, "b": (0.0,) * 3})
    loop = Rotorflight(p)
    out, mem, _ = loop.tick(loop.initial_memory(), np.radians([2.0, 0.0, 0.0]), np.zeros(3))
    sp = 4.0 * 2.0  # angle_level_strength 40 -> 4 (deg/s)/deg
    expected = 6.66666e-6 * 50 * sp + 2e-4 * 100 * (sp / 1000.0) + 2.5e-5 * 100 * sp  # P + I + F, D on gyro = 0
    assert_allclose(out[0], expected, rtol=1e-9)
    assert_allclose(mem[7, 0], sp / 1000.0, rtol=1e-12)  # accumulated error [deg]


def test_rotorflight_gyro_ramp_d_term():
    """D on the gyro through the band-limited differentiator ``y = b·x − b·x₁ − a·y₁``, by hand."""
    p = RotorflightParams(**NO_FILTERS_RF, p=(0.0,) * 3, i=(0.0,) * 3, f=(0.0,) * 3, d=(500.0, 0.0, 0.0))
    loop = Rotorflight(p)
    k = math.tan(math.pi * 15.0 / 1000.0)
    a, b = (k - 1) / (k + 1), 2 * math.pi * 15.0 / (k + 1)
    mem, y, x1 = loop.initial_memory(), 0.0, 0.0
    for n in range(1, 5):
        g = math.radians(10.0 * n)  # a ramp of 10 deg/s per tick
        out, mem, _ = loop.tick(mem, np.zeros(3), np.array([g, 0.0, 0.0]))
        x = -10.0 * n
        y = b * x - b * x1 - a * y
        x1 = x
        assert_allclose(out[0], 1e-7 * 500 * y, rtol=1e-9)


def test_rotorflight_error_limit_saturation_and_decay():
    """The accumulated error stops at ±error_limit; the output at ±output_limit holds the I-term; with zero
    error the decay removes ``clamp(E·r, ±l)·dt`` per tick."""
    p = RotorflightParams(**{**NO_FILTERS_RF, "error_limit": (1.0, 30.0, 45.0)})
    loop = Rotorflight(p)
    mem = loop.initial_memory()
    for _ in range(300):
        out, mem, _ = loop.tick(mem, np.radians([30.0, 0.0, 0.0]), np.zeros(3))
    assert_allclose(mem[7, 0], 1.0)
    big = Rotorflight(RotorflightParams(**NO_FILTERS_RF, p=(1000.0,) * 3))
    mem = big.initial_memory()
    out, mem, sat = big.tick(mem, np.radians([40.0, 0.0, 0.0]), np.zeros(3))
    assert out[0] == 1.25 and sat[0]
    held = mem[7, 0]
    out, mem, _ = big.tick(mem, np.radians([40.0, 0.0, 0.0]), np.zeros(3))
    assert mem[7, 0] == held  # saturated and growing: not accumulated
    decaying = Rotorflight(RotorflightParams(**{**NO_FILTERS_RF, "decay_time_cyclic": 25.0,
                                                 "decay_limit_cyclic": 0.0}))
    mem = decaying.initial_memory()
    mem[7] = [10.0, 0.0, 0.0]
    _, mem, _ = decaying.tick(mem, np.zeros(3), np.zeros(3))
    rate = (10.0 / 25.0) * 12 * 0.08
    assert_allclose(mem[7, 0], 10.0 - 10.0 * rate / 1000.0, rtol=1e-12)


def test_rotorflight_yaw_stop_gains():
    p = RotorflightParams(**NO_FILTERS_RF, i=(0.0,) * 3, f=(0.0,) * 3, d=(0.0,) * 3)
    loop = Rotorflight(p)
    for g_deg, gain in ((-50.0, 1.2), (50.0, 0.8)):  # error +50 -> cw stop gain, -50 -> ccw
        out, _, _ = loop.tick(loop.initial_memory(), np.zeros(3), np.radians([0.0, 0.0, g_deg]))
        assert_allclose(out[2], 6.666666e-5 * 80 * (-g_deg) * gain, rtol=1e-9)


# -------------------------------------------------------------------------------------- linearisation
def test_ardupilot_linearisation_is_the_pd_it_maps_to(shipped):
    """Filters off, I, FF and D zero: ``u = s·(A·P·e − P·g)``, i.e. ``kp = s·A·P``, ``kd = s·P`` (and with FF
    the attitude stiffness ``A·(FF + P)``)."""
    signs = np.sign(shipped.params.control_gains)
    for ff in (0.0, 0.1):
        p = ArduPilotHeliParams(**NO_FILTERS_AP, rat_i=0.0, rat_d=0.0, rat_ff=(ff,) * 3, rat_p=(0.05, 0.06, 0.2),
                                ang_p=(4.0, 5.0, 6.0))
        lin = linearise(ArduPilotHeli(p, 2.0, signs))
        kp = 2.0 * np.array([4.0, 5.0, 6.0]) * (np.array([0.05, 0.06, 0.2]) + ff)
        kd = 2.0 * np.array([0.05, 0.06, 0.2])
        assert_allclose(lin.D[0], np.hstack([np.diag(signs * kp), np.diag(-signs * kd)]), atol=1e-9)
        assert_allclose(lin.C[0], 0.0, atol=1e-9)


def test_rotorflight_linearisation_is_the_pd_it_maps_to(shipped):
    signs = np.sign(shipped.params.control_gains)
    p = RotorflightParams(**NO_FILTERS_RF, i=(0.0,) * 3, d=(0.0,) * 3, f=(0.0,) * 3, p=(150.0, 200.0, 80.0),
                          level_strength=30.0, yaw_cw_stop_gain=100.0, yaw_ccw_stop_gain=100.0)
    lin = linearise(Rotorflight(p, 1.0, signs))
    kd = np.degrees(np.array([150 * 6.66666e-6, 200 * 6.66666e-6, 80 * 6.666666e-5]))
    kp = kd * np.array([3.0, 3.0, 0.0])
    assert_allclose(lin.D[0], np.hstack([np.diag(signs * kp), np.diag(-signs * kd)]), rtol=1e-7, atol=1e-12)


def test_linear_firmware_loop_equals_the_sweeps_pd(shipped):
    """At 100 Hz (one tick per control period) the PD-equivalent ArduPilot loop gives the PD sweep's
    frequency-domain error and margins (controllers.closed_loop, controllers.sweep_margins)."""
    from controllers.closed_loop import disturbance_spectrum, hover_plant, predict_std
    from controllers.sweep_margins import loop_margins

    params = shipped.params
    signs = np.sign(params.control_gains)
    rat_p, ang_p = np.array([0.4, 0.5, 0.08]), np.array([5.0, 5.0, 4.0])
    p = ArduPilotHeliParams(**NO_FILTERS_AP, rat_i=0.0, rat_d=0.0, rat_ff=0.0, rat_p=tuple(rat_p),
                            ang_p=tuple(ang_p), loop_rate_hz=100.0)
    cl = closed_loop(params, ArduPilotHeli([p], 1.0, signs))
    freq, psd = disturbance_spectrum(shipped, 0.01)
    nominal = np.column_stack([ang_p * rat_p, rat_p])
    plant = hover_plant(params, 0.01)
    pd = predict_std(plant, 0, [nominal[0, 0]], [nominal[0, 1]], nominal, freq, psd)[0, 0]
    assert_allclose(attitude_std(cl, 1, 0, freq, psd), [pd], rtol=2e-3)
    gm, pm = loop_margins(plant, 0, [nominal[0, 0]], [nominal[0, 1]], nominal)
    fgm, fpm = stick_margins(cl, 0)
    assert_allclose(fgm, gm, rtol=2e-3)
    assert_allclose(fpm, pm, rtol=2e-3)


# ---------------------------------------------------------------------------- the plain implementation
def _random_inputs(n, seed):
    rng = np.random.default_rng(seed)
    e = np.cumsum(rng.normal(0.0, 0.004, (3, n)), axis=1)
    g = np.cumsum(rng.normal(0.0, 0.05, (3, n)), axis=1) + rng.normal(0.0, 0.02, (3, n))
    return e, g


AP_NAMES = {"ATC_ANG_RLL_P": 6.0, "ATC_ANG_PIT_P": 5.0, "ATC_ANG_YAW_P": 4.0, "ATC_RAT_RLL_P": 0.08,
            "ATC_RAT_PIT_P": 0.07, "ATC_RAT_YAW_P": 0.25, "ATC_RAT_RLL_I": 0.3, "ATC_RAT_RLL_D": 0.003,
            "ATC_RAT_RLL_FF": 0.12, "ATC_RAT_RLL_IMAX": 0.2, "ATC_RAT_RLL_FLTD": 30.0, "ATC_RAT_PIT_FLTT": 10.0,
            "ATC_RAT_RLL_D_FF": 0.001, "SCHED_LOOP_RATE": 400.0, "INS_GYRO_FILTER": 30.0, "H_CYC_MAX": 3000.0}


def _ap_params_from_names(names):
    p = {f: list(v) for f, v in vars(ArduPilotHeliParams()).items() if isinstance(v, tuple)}
    fields = {"ANG": "ang_p", "P": "rat_p", "I": "rat_i", "D": "rat_d", "FF": "rat_ff", "IMAX": "rat_imax",
              "FLTD": "rat_fltd", "FLTT": "rat_fltt", "D_FF": "rat_d_ff"}
    for name, value in names.items():
        parts = name.split("_")
        if parts[0] != "ATC":
            continue
        axis = ("RLL", "PIT", "YAW").index(parts[2])
        key = "ANG" if parts[1] == "ANG" else "_".join(parts[3:])
        p[fields[key]][axis] = value
    return ArduPilotHeliParams(**{k: tuple(v) for k, v in p.items()}, loop_rate_hz=names["SCHED_LOOP_RATE"],
                               gyro_filter_hz=names["INS_GYRO_FILTER"], cyc_max=names["H_CYC_MAX"])


def test_plain_ardupilot_reproduces_the_package_tick_by_tick():
    """2000 ticks of random attitude errors and gyro rates, saturations and leaks included."""
    loop = ArduPilotHeli(_ap_params_from_names(AP_NAMES))
    ref = plain.PlainArduPilot(AP_NAMES)
    e, g = _random_inputs(2000, 3)
    e[:, 1200:1300] += 0.5  # a stretch that saturates
    mem = loop.initial_memory()
    worst = 0.0
    for k in range(e.shape[1]):
        out, mem, _ = loop.tick(mem, e[:, k], g[:, k])
        worst = max(worst, float(np.max(np.abs(out - ref.update(e[:, k], g[:, k])))))
    assert worst < 1e-12


RF_NAMES = {"roll_p_gain": 120, "pitch_p_gain": 90, "yaw_p_gain": 70, "roll_i_gain": 150, "yaw_i_gain": 100,
            "roll_d_gain": 300, "pitch_d_gain": 30, "roll_f_gain": 80, "pitch_b_gain": 200,
            "angle_level_strength": 60, "error_limit": [20, 30, 45], "roll_gyro_cutoff": 60,
            "gyro_lpf1_static_hz": 120, "error_decay_time_cyclic": 50}


def test_plain_rotorflight_reproduces_the_package_tick_by_tick():
    p = RotorflightParams(p=(120, 90, 70), i=(150, 100, 100), d=(300, 30, 40), f=(80, 100, 0), b=(0, 200, 0),
                          level_strength=60, error_limit=(20, 30, 45), gyro_cutoff=(60, 50, 100),
                          gyro_lpf1_hz=120, decay_time_cyclic=50)
    loop = Rotorflight(p)
    ref = plain.PlainRotorflight(RF_NAMES, 1000.0, 1.25)
    e, g = _random_inputs(3000, 4)
    e[:, 1500:1600] += 0.8
    mem = loop.initial_memory()
    worst = 0.0
    for k in range(e.shape[1]):
        out, mem, _ = loop.tick(mem, e[:, k], g[:, k])
        worst = max(worst, float(np.max(np.abs(out - ref.update(e[:, k], g[:, k])))))
    assert worst < 1e-11


def test_plain_closed_loop_flies_like_the_replay(shipped):
    """The package's loop in controllers.replay (exact discrete step at the tick) and the plain loop around the
    physics core's scalar RK4 fly the same 2 s of gusts to within 1e-5 rad."""
    from controllers.firmware.autopilot import FirmwareAutopilot, fly_firmware
    from controllers.sweep_inputs import prepare

    params = shipped.params
    signs = tuple(np.sign(params.control_gains))
    rp = prepare(shipped, "roll", 2.0, 0.01, 0, [(0, 500)], None, sensors=False)
    ap_params = _ap_params_from_names(AP_NAMES)
    auto = FirmwareAutopilot(ArduPilotHeli, [ap_params], (1.0, 1.0, 1.0), signs, 0.01)
    (_, rec), = list(fly_firmware(params, rp.inputs, auto, progress=False))
    ins = rp.inputs
    errors = plain.fly(params, plain.PlainArduPilot(AP_NAMES), (1.0, 1.0, 1.0), signs, ins.torque[:, :, 0],
                       ins.col[:, 0], ins.trim[:, :, 0])
    assert_allclose(np.array(errors), rec.axes[:, 0, :, 0], atol=1e-5)
    assert np.max(np.abs(rec.axes)) > 1e-3  # the gusts moved it


# ---------------------------------------------------------------------------------- policy interface
def test_predict_interface_and_rate_mapping():
    loop = ArduPilotHeli(ArduPilotHeliParams(), 0.5, (1.0, -1.0, 1.0))
    obs = np.zeros((4, 12))
    obs[:, 0] = 0.1
    action, state = loop.predict(obs)
    assert action.shape == (4, 3) and action.dtype == np.float32 and state.shape == (7, 3, 4)
    again, state2 = loop.predict(obs, state)
    assert np.all(np.abs(again[:, 0]) > np.abs(action[:, 0]))  # the I-term and filters carry memory
    reset, _ = loop.predict(obs, state2, episode_start=np.array([True, False, False, False]))
    assert_allclose(reset[0], action[0])
    single, _ = loop.predict(obs[0])
    assert single.shape == (3,)
    with pytest.raises(FirmwareMappingError, match="whole multiple"):
        loop.predict(obs, control_dt=0.0033)
    with pytest.raises(ValueError, match=r"observation must have shape"):
        loop.predict(np.zeros(5))


def test_bad_scale_and_sets_are_refused():
    with pytest.raises(FirmwareMappingError, match="command scale"):
        ArduPilotHeli(ArduPilotHeliParams(), 0.0)
    with pytest.raises(FirmwareMappingError, match="share a loop rate"):
        ArduPilotHeli([ArduPilotHeliParams(), ArduPilotHeliParams(loop_rate_hz=200.0)])
    with pytest.raises(ValueError, match="rat_p must be finite"):
        ArduPilotHeliParams(rat_p=(-1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="p gain must be finite"):
        RotorflightParams(p=(2000.0, 0.0, 0.0))


# ---------------------------------------------------------------------- the environment at the loop's rate
def test_the_env_at_the_tick_flies_like_the_replay(shipped):
    """On the library held at the loop's rate (controllers.firmware.loop_rate_env) the vector environment runs at
    the tick and the loop acts every tick through predict: the same 2 s of gusts as the replay (the physics
    sub-stepped to the tick) to within 1e-5 rad (the observation is float32)."""
    from controllers.firmware.autopilot import FirmwareAutopilot, fly_firmware
    from controllers.firmware.loop_rate_env import TickAgent, held_library
    from controllers.sweep_inputs import prepare
    from heli_env.vector_env import HeliAttitudeVectorEnv

    params = shipped.params
    signs = tuple(np.sign(params.control_gains))
    ap_params = _ap_params_from_names(AP_NAMES)
    rp = prepare(shipped, "roll", 2.0, 0.01, 0, [(0, 500)], None, sensors=False)
    auto = FirmwareAutopilot(ArduPilotHeli, [ap_params], (1.0, 1.0, 1.0), signs, 0.01)
    (_, rec), = list(fly_firmware(params, rp.inputs, auto, progress=False))
    replay = rec.axes[:, 0, :, 0]  # (3, 200): attitude error at each period's start

    loop = ArduPilotHeli(ap_params, (1.0, 1.0, 1.0), signs)
    held = held_library(shipped, 4)
    assert held.sample_rate == 4 * shipped.sample_rate and held_library(shipped, 1) is shipped
    assert_allclose(held.sensors.gyro_noise, 2.0 * np.asarray(shipped.sensors.gyro_noise))

    def fly(model, agent, dt, per_period):
        env = HeliAttitudeVectorEnv(1, model=model, dt=dt, episode_seconds=2.0, obs_noise=0.0, init_angle_deg=0.0,
                                    init_rate_deg=0.0)
        obs, info = env.reset(seed=0, options={"trace": 0, "offset": 500 * per_period})
        state, errors = None, []
        for k in range(int(round(2.0 / dt))):
            if k % per_period == 0:
                errors.append(np.radians(info["attitude_error_deg"][0]))
            a, state = agent.predict(obs, state, episode_start=np.array([k == 0]))
            obs, _, _, _, info = env.step(a)
        return np.array(errors).T

    at_tick = fly(held, TickAgent(loop), loop.dt, 4)
    assert_allclose(at_tick, replay, atol=1e-5)
    assert np.max(np.abs(replay)) > 1e-3  # the gusts moved it


def test_evaluate_firmware_flies_every_tick(shipped):
    """controllers.firmware.loop_rate_env.evaluate_firmware: the evaluator at the loop's tick on the held library,
    a sample per tick; dt cannot be given; a rate the library's period cannot hold is refused."""
    from controllers.firmware.loop_rate_env import evaluate_firmware

    signs = tuple(np.sign(shipped.params.control_gains))
    loop = ArduPilotHeli(ArduPilotHeliParams(), (12.0, 12.0, 1.4), signs)
    result = evaluate_firmware(loop, shipped, episodes_per_trace=1, episode_seconds=2.0)
    assert result.settings["dt"] == 0.0025 and result.settings["sample_rate"] == pytest.approx(400.0)
    assert result.summary()["terminated_episodes"] == 0
    assert result.metrics["roll"]["n_samples"] == 800 * len(result.episodes)
    with pytest.raises(FirmwareMappingError, match="own tick"):
        evaluate_firmware(loop, shipped, dt=0.01)
    slow = ArduPilotHeli(ArduPilotHeliParams(loop_rate_hz=250.0), 1.0, signs)
    with pytest.raises(FirmwareMappingError, match="whole multiple"):
        evaluate_firmware(slow, shipped)
