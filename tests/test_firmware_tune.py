"""The pieces of ``heli tune`` below the command: the delay margin, the joint choice of Rotorflight's roll and
pitch, the step response of the flight-test card, and what the log flew against its desired attitude."""

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from controllers.firmware import ArduPilotHeli, ArduPilotHeliParams, RotorflightParams
from controllers.firmware.firmwares import FIRMWARES
from controllers.firmware.flown import flown_errors, steady_errors
from controllers.firmware.linear import closed_loop, stick_margins
from controllers.firmware.step_response import step_response
from controllers.firmware.tune_sweep import AxisSweep, joint_choices

LOGS = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "logs"


def test_delay_margin_is_the_phase_margin_over_the_crossover(shipped):
    """At 100 Hz the PD-equivalent loop's delay margin is PM / ω at the gain crossover of the same sampled loop
    (controllers.sweep_margins' broken loop) as python-control evaluates it, the crossover found to 1e-12 rad/s.
    Not ``control.stability_margins(method="frd")``: python-control 0.10.2's grid put this crossover at 1.0361
    rad/s for 1.0356 and the phase margin 0.26 degrees low."""
    import control
    from scipy.optimize import brentq

    from controllers.closed_loop import hover_plant
    from controllers.sweep_margins import _broken_loop

    params = shipped.params
    signs = np.sign(params.control_gains)
    rat_p, ang_p = np.array([0.4, 0.5, 0.08]), np.array([5.0, 5.0, 4.0])
    p = ArduPilotHeliParams(rat_fltt=0.0, rat_flte=0.0, rat_fltd=0.0, gyro_filter_hz=0.0, rat_i=0.0, rat_d=0.0,
                            rat_ff=0.0, rat_p=tuple(rat_p), ang_p=tuple(ang_p), loop_rate_hz=100.0)
    gm, pm, dm = stick_margins(closed_loop(params, ArduPilotHeli([p], 1.0, signs)), 0, delay=True)
    plant = hover_plant(params, 0.01)
    nominal = np.column_stack([ang_p * rat_p, rat_p])
    A_o, b, c_angle, c_rate = _broken_loop(plant, 0, nominal)
    loop = control.ss(A_o, b[:, None], (nominal[0, 0] * c_angle + nominal[0, 1] * c_rate)[None, :], 0.0, 0.01)
    response = lambda w: complex(loop(np.exp(1j * w * 0.01)))  # noqa: E731
    grid = np.geomspace(0.01, np.pi / 0.01, 4000)
    above = np.abs([response(w) for w in grid]) > 1.0
    first = int(np.flatnonzero(above[:-1] != above[1:])[0])
    wc = brentq(lambda w: abs(response(w)) - 1.0, grid[first], grid[first + 1], xtol=1e-12)
    pm_ref = np.degrees(np.angle(response(wc))) % 360.0 - 180.0
    assert_allclose(pm, [pm_ref], rtol=1e-4)
    assert_allclose(dm, [np.radians(pm_ref) / wc], rtol=1e-4)


def _sweep(axis, a, b, p90, robust=True):
    n = len(a)
    ones = np.ones(n)
    return AxisSweep(axis, ("P", "L"), np.array(a, float), np.array(b, float), tuple(range(n)), ones * 0.9,
                     np.ones(n, bool), np.array(p90, float), ones * (10.0 if robust else 1.0), ones * 60.0,
                     ones * 0.1)


def test_roll_and_pitch_share_the_level_strength():
    """Rotorflight's roll and pitch are chosen at one angle_level_strength, by the sum of their p90s."""
    roll = _sweep(0, [10, 10, 20, 20], [5, 9, 5, 9], [1.0, 0.5, 0.9, 0.6])
    pitch = _sweep(1, [10, 10, 20, 20], [5, 9, 5, 9], [0.4, 0.9, 0.3, 0.8])
    choices = joint_choices({0: roll, 1: pitch}, (0, 1), 2)
    assert choices[0] == {0: 2, 1: 2} and choices[1] == {0: 1, 1: 3}  # level 5: 0.9 + 0.3; level 9: 0.5 + 0.8
    assert joint_choices({0: _sweep(0, [1], [1], [1.0], robust=False)}, (0,), 3) == []


def test_step_response_of_the_card(ideal):
    spec = FIRMWARES["ardupilot"]
    signs = tuple(np.sign(ideal.params.control_gains))
    st = step_response(spec, ArduPilotHeliParams(), ideal.params, (12.0, 12.0, 1.4), signs, 0, seconds=2.0)
    assert not st["diverged"] and 0.1 < st["rise_90_s"] < 1.5 and st["overshoot_pct"] >= 0.0
    assert_allclose(st["angle_deg"][0], 0.0, atol=1e-9)
    rf = FIRMWARES["rotorflight"]
    assert step_response(rf, RotorflightParams(), ideal.params, (1.0, 1.0, 1.0), signs, 2) is None


def test_steady_blocks_of_the_flown_error():
    t = np.arange(0, 20, 0.1)
    desired = np.zeros((3, t.size))
    desired[0, (t >= 4) & (t < 6)] = np.linspace(0, 20, int(np.sum((t >= 4) & (t < 6))))  # a commanded move
    actual = desired + 0.5 * np.sin(t)[None, :]
    actual[2] += 360.0  # yaw wraps
    out = steady_errors(t, desired, actual)
    assert out.available and out.seconds == pytest.approx(18.0, abs=0.2)
    assert out.axes["roll"]["p90_deg"] < 0.5 + 1e-9 and out.axes["yaw"]["p99_deg"] < 0.5 + 1e-9


@pytest.mark.skipif(not LOGS.is_dir(), reason="the shared real-log fixtures are absent")
def test_what_the_log_flew():
    pytest.importorskip("pymavlink")
    out = flown_errors(LOGS / "ardupilot_copter_log171.bin", (83.958, 237.358))
    assert out.available and out.seconds > 20
    assert_allclose([out.axes[a]["p90_deg"] for a in ("roll", "pitch", "yaw")], [1.108, 0.754, 0.414], atol=1e-3)
    assert not flown_errors(LOGS / "rotorflight_k110_LOG246.TXT").available


def test_a_firmware_loop_flies_through_the_evaluator(shipped):
    """The one policy interface: controllers.evaluate flies a firmware loop as it flies PD and RL agents."""
    from controllers.evaluate import evaluate_agent

    loop = ArduPilotHeli(ArduPilotHeliParams(), (12.0, 12.0, 1.4), tuple(np.sign(shipped.params.control_gains)))
    summary = evaluate_agent(loop, None, episodes_per_trace=1, episode_seconds=4.0, name="ardupilot").summary()
    assert summary["terminated_episodes"] == 0
    assert 0.0 < summary["axes"]["roll"]["att_p90_deg"] < 5.0


def test_legacy_arducopter_outputs_are_converted_to_the_firmwares_unit():
    """ArduCopter <= 3.3 logs RATE.ROut/POut against +-5000 (the importer's divisor) where the motors' full scale,
    the unit of the later +-1 output, is +-4500: one imported unit is 0.9 of the loop's output unit."""
    from controllers.firmware.scale import legacy_output_unit

    legacy = ("RATE ROut/5000->lat, POut/5000->lon, 2*AOut/1000-1->col, YOut/4500->ped (rate-controller outputs, "
              "ArduCopter <= 3.3 motor-mix units)")
    assert legacy_output_unit(legacy) == (0.9, 0.9, 1.0)
    assert legacy_output_unit("RATE ROut/1->lat, POut/1->lon, 2*AOut/1-1->col, YOut/1->ped") == (1.0, 1.0, 1.0)


@pytest.mark.slow
@pytest.mark.skipif(not LOGS.is_dir(), reason="the shared real-log fixtures are absent")
def test_the_scale_of_an_arducopter_3_3_log():
    """log171 (ArduCopter 3.3, identified on its RATE outputs): the scale is 0.9, 0.9, 1, not 1 (6 s: the 3 MB log is read twice)."""
    from controllers.firmware.scale import measure_scale

    scale = measure_scale(LOGS / "ardupilot_copter_log171.bin", None)
    assert scale.source == "identity" and scale.scale == (0.9, 0.9, 1.0)


def test_the_delay_margin_criterion_and_its_option(tmp_path, flight_csv, ideal_model_dir):
    """A robust set keeps 25 ms of delay margin by default (the agile bench aircraft's measurement in
    docs/firmware.md); --delay-margin 0 drops the criterion, and a value outside [0, 1] s is refused by the parser."""
    from controllers.firmware.tune import TuneConfig
    from controllers.firmware.tune_sweep import ROBUST_DELAY_MARGIN_S, robust
    from heli_cli.main import main

    ones = np.ones(3)
    dm = np.array([0.01, 0.03, np.inf])
    assert ROBUST_DELAY_MARGIN_S == 0.025 and TuneConfig().delay_margin_s == 0.025
    assert robust(ones > 0, 10 * ones, 60 * ones, dm).tolist() == [False, True, True]
    assert robust(ones > 0, 10 * ones, 60 * ones, dm, 0.0).tolist() == [True, True, True]
    assert _sweep(0, [1, 2], [1, 1], [1.0, 1.0]).robust.all()  # 0.1 s of delay margin: robust
    with pytest.raises(ValueError, match="delay_margin_s"):
        TuneConfig(delay_margin_s=-0.01)
    with pytest.raises(SystemExit) as e:
        main(["tune", str(flight_csv), "--firmware", "ardupilot", "--model", str(ideal_model_dir),
              "--delay-margin", "2", "--out", str(tmp_path / "o")])
    assert e.value.code == 2


def test_the_stop_gains_act_near_hover_through_their_mean_only(shipped):
    """Rotorflight's tail P is scaled by transition(error, -10, 10, ccw, cw) (pid.c pidApplyYawMode3): about hover
    the linearised loop sees (cw + ccw)/2 alone, so (120, 80), (100, 100), (150, 50) and (80, 120) give the same
    margins and spectrum p90, and (150, 150) is yaw P x 1.5. The yaw sweep's P covers their mean; their ratio
    answers an asymmetry of the tail the symmetric model (eq. 21) does not have, so it is not swept
    (docs/firmware.md has the time-domain check)."""
    from dataclasses import replace

    from controllers.closed_loop import disturbance_spectrum
    from controllers.firmware.linear import attitude_std

    base = RotorflightParams()
    pairs = ((120, 80), (100, 100), (150, 50), (80, 120), (150, 150))
    sets = [replace(base, yaw_cw_stop_gain=cw, yaw_ccw_stop_gain=ccw) for cw, ccw in pairs]
    sets.append(replace(base, p=base.p[:2] + (base.p[2] * 1.5,), yaw_cw_stop_gain=100, yaw_ccw_stop_gain=100))
    loop = FIRMWARES["rotorflight"].loop_class(sets, 1.0, tuple(np.sign(shipped.params.control_gains)))
    cl = closed_loop(shipped.params, loop, float(np.mean(shipped.collective)))
    freq, psd = disturbance_spectrum(shipped, 0.01)
    table = np.vstack([*stick_margins(cl, 2, delay=True), attitude_std(cl, 10, 2, freq, psd)])
    assert_allclose(table[:, 1:4], table[:, [0] * 3], rtol=1e-9)
    assert_allclose(table[:, 5], table[:, 4], rtol=1e-9)
    assert not np.allclose(table[:, 4], table[:, 0], rtol=1e-3)
