"""Rotor lines a slow log folds into the aircraft's band (identification.vibration.remove_folded_lines)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid
from scipy.signal import butter, sosfiltfilt

from identification.bench.cells import BENCH_CELLS
from identification.bench.synthetic import simulate_flight
from identification.integral.method import IntegralIdentifier
from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier
from identification.sensors import identify_sensors
from identification.validation.fit_warnings import folded_lines_warning
from identification.vibration import remove_fed_back_lines, remove_folded_lines

FS = 25.0
T = np.arange(7500) / FS  # 300 s


def _motion(seed: int):
    """Rates of a random motion below 3 Hz (0.05 rad/s: a hover in gusts) and the attitude they integrate to."""
    rng = np.random.default_rng(seed)
    rates = sosfiltfilt(butter(4, 3.0, fs=FS, output="sos"), 0.1 * rng.standard_normal((3, T.size)), axis=1)
    return rates, cumulative_trapezoid(rates, dx=1 / FS, axis=1, initial=0.0)


def test_a_line_in_the_gyro_alone_is_removed_and_the_motion_kept():
    rates, attitude = _motion(0)
    line = 0.03 * np.sin(2 * np.pi * 2.0 * T + 0.4)  # 27 Hz logged at 25 Hz
    cleaned, lines = remove_folded_lines(rates + line, attitude, FS)
    assert [(ln["axis"], round(ln["frequency_hz"], 2), ln["folded"]) for ln in lines] == [
        ("roll", 2.0, True), ("pitch", 2.0, True), ("yaw", 2.0, True)]
    assert all(abs(ln["amplitude"] - 0.03) < 0.002 for ln in lines)
    assert np.std(cleaned - rates) < 0.002


def test_a_sine_the_aircraft_flew_is_its_motion_and_stays():
    """A pilot's sine-dwell is as narrow a line as a rotor's; the attitude shows it, so it is kept whole."""
    rates, attitude = _motion(1)
    w = 2 * np.pi * 1.3
    rates, attitude = rates + 0.2 * np.cos(w * T), attitude + 0.2 / w * np.sin(w * T)
    cleaned, lines = remove_folded_lines(rates, attitude, FS)
    assert lines == [] and np.array_equal(cleaned, rates)


def test_behind_an_autopilot_only_the_sensors_share_is_removed():
    """An autopilot that flew on the folded gyro made the aircraft move at the line's frequency too."""
    rates, attitude = _motion(2)
    w = 2 * np.pi * 2.0
    sensor, moved = 0.03 * np.sin(w * T), -0.01 * np.sin(w * T + 0.5)
    cleaned, lines = remove_folded_lines(rates + sensor + moved, attitude + 0.01 / w * np.cos(w * T + 0.5), FS)
    assert len(lines) == 3 and all(abs(ln["amplitude"] - 0.03) < 0.002 for ln in lines)
    assert np.std(cleaned - (rates + moved)) < 0.002


def test_a_line_a_controller_fed_back_leaves_its_commands_and_the_gyro_together():
    """A loop flying on the vibrating gyro commands the line too; the aircraft answered it at 27 Hz, not at the
    2 Hz the log shows: the line goes from the command, and the gyro's motion share with it."""
    rates, attitude = _motion(5)
    w = 2 * np.pi * 2.0
    sensor, moved = 0.03 * np.sin(w * T), -0.01 * np.sin(w * T + 0.5)
    cleaned, folded = remove_folded_lines(rates + sensor + moved, attitude + 0.01 / w * np.cos(w * T + 0.5), FS)
    rng = np.random.default_rng(6)
    sticks = sosfiltfilt(butter(4, 3.0, fs=FS, output="sos"), 0.05 * rng.standard_normal((3, T.size)), axis=1)
    commands = sticks.copy()
    commands[2] += 0.008 * np.sin(w * T + 1.1)  # only the yaw's command carries it
    out, felt, fed = remove_fed_back_lines(cleaned, commands, FS, folded)
    assert [(ln["axis"], round(ln["frequency_hz"], 2), ln["signal"]) for ln in fed] == [("yaw", 2.0, "command")]
    assert abs(fed[0]["amplitude"] - 0.008) < 0.001
    assert np.std(felt[2] - sticks[2]) < 0.001 and np.array_equal(felt[:2], commands[:2])
    assert np.std(out[2] - rates[2]) < 0.002  # the motion share gone too
    assert np.array_equal(out[:2], cleaned[:2])  # behind sticks without the line, the motion share stays
    same, kept, none = remove_fed_back_lines(cleaned, sticks, FS, folded)  # a pilot's sticks carry no line
    assert none == [] and np.array_equal(kept, sticks) and np.array_equal(same, cleaned)


def test_a_fed_back_line_on_half_the_rate_leaves_the_command_too():
    """At 20 Hz a 30 Hz rotor sits on 10 Hz, where the samples alternate: the command's alternation goes with the
    gyro's."""
    fs, n = 20.0, 6000
    rng = np.random.default_rng(7)
    rates = sosfiltfilt(butter(4, 3.0, fs=fs, output="sos"), 0.1 * rng.standard_normal((3, n)), axis=1)
    attitude = cumulative_trapezoid(rates, dx=1 / fs, axis=1, initial=0.0)
    alternating = np.where(np.arange(n) % 2, -1.0, 1.0)
    cleaned, folded = remove_folded_lines(rates + 0.02 * alternating, attitude, fs)
    sticks = sosfiltfilt(butter(4, 3.0, fs=fs, output="sos"), 0.05 * rng.standard_normal((3, n)), axis=1)
    commands = sticks + 0.01 * alternating
    out, felt, fed = remove_fed_back_lines(cleaned, commands, fs, folded)
    assert sorted((ln["axis"], ln["frequency_hz"]) for ln in fed) == [("pitch", 10.0), ("roll", 10.0), ("yaw", 10.0)]
    assert np.std(felt - sticks) < 0.001 and np.std(out - rates) < 0.002


def test_the_edge_of_a_band_a_logger_filtered_is_no_line():
    """Nothing above 2.4 Hz in the log (the T-REX hover): every bin below the edge stands far above the empty
    side beyond it; a line must stand above both sides."""
    rng = np.random.default_rng(3)
    rates = sosfiltfilt(butter(8, 2.2, fs=100.0, output="sos"), rng.standard_normal((3, 8000)), axis=1)
    cleaned, lines = remove_folded_lines(rates, cumulative_trapezoid(rates, dx=0.01, axis=1, initial=0.0), 100.0)
    assert lines == [] and np.array_equal(cleaned, rates)


def test_at_20_hz_lines_between_8_hz_and_half_the_rate_and_on_it_are_found():
    """At 20 Hz the search above 8 Hz has too narrow a band to run: a 31 Hz rotor folds to 9 Hz, a 30 Hz one
    onto 10 Hz, where the samples alternate."""
    fs = 20.0
    t = np.arange(6000) / fs
    rng = np.random.default_rng(4)
    rates = sosfiltfilt(butter(4, 3.0, fs=fs, output="sos"), 0.1 * rng.standard_normal((3, t.size)), axis=1)
    attitude = cumulative_trapezoid(rates, dx=1 / fs, axis=1, initial=0.0)
    lines = 0.04 * np.sin(2 * np.pi * 9.0 * t + 1.0) + 0.02 * np.where(np.arange(t.size) % 2, -1.0, 1.0)
    cleaned, found = remove_folded_lines(rates + lines, attitude, fs)
    assert sorted({round(ln["frequency_hz"], 2) for ln in found}) == [9.0, 10.0]
    assert np.std(cleaned - rates) < 0.002


@pytest.fixture(scope="module")
def slow_log():
    """The bench's flight logged at 25 Hz: its gyro lines at 27, 30 and 40 Hz appear at 2, 5 and 10 Hz."""
    return simulate_flight(300, seed=931, config=replace(BENCH_CELLS["independent"], duration=300, sample_rate=FS))


@pytest.fixture(scope="module")
def slow_fit(slow_log):
    return MaximumLikelihoodIdentifier(closed_loop=None).fit(slow_log.flight)


def test_a_flight_logged_at_25_hz_is_fitted_as_at_100(slow_log, slow_fit):
    """Before the folded lines were removed, this flight's dampings came out 570 % high."""
    fit = slow_fit
    truth, got = slow_log.truth.values(), fit.params_.values()
    for name in ("k2", "k6", "k10", "k3", "k7", "k11"):
        assert abs(got[name] / truth[name] - 1) < 0.08, name
    folded = sorted({round(ln["frequency_hz"], 1) for ln in fit.vibration_lines_[0] if ln.get("folded")})
    assert folded == [2.0, 5.0]


def test_the_sensor_model_keeps_the_lines_as_the_log_shows_them(slow_log):
    model = identify_sensors(slow_log.flight)
    assert sorted({round(ln.frequency_hz, 1) for ln in model.gyro_lines}) == [2.0, 5.0, 10.0]


def test_the_user_is_told_the_gyro_carried_folded_lines(slow_fit):
    (warning,) = folded_lines_warning(slow_fit)
    assert "(roll, pitch, yaw)" in warning and "at 2, 5 Hz" in warning and "twice the rotor's" in warning
    assert folded_lines_warning(MaximumLikelihoodIdentifier()) == []  # nothing fitted, nothing said


def test_the_integral_method_removes_them_too(slow_log):
    """The paper's method low-passes at 4/8 Hz, which cannot reach a line folded to 2 Hz: left in, roll's damping
    came out 77 % high and pitch's 64 % low on this flight (31-35 % RMS over five 25 Hz flights); the same
    search removes them first and says so."""
    truth = slow_log.truth.values()
    fit = IntegralIdentifier().fit(slow_log.flight)
    got = fit.params_.values()
    assert all(abs(got[k] / truth[k] - 1) < 0.05 for k in ("k2", "k6", "k10"))
    assert all(abs(got[k] / truth[k] - 1) < 0.15 for k in ("k3", "k7", "k11"))
    assert "at 2, 5 Hz" in folded_lines_warning(fit)[0]
    left = IntegralIdentifier(remove_folded=False).fit(slow_log.flight)
    assert max(abs(left.params_.values()[k] / truth[k] - 1) for k in ("k3", "k7")) > 0.5
    assert left.vibration_lines_ == [[]] and folded_lines_warning(left) == []


def test_an_autopilot_logged_at_25_hz_is_not_given_a_servo_lag_by_its_own_commands():
    """The bench's autopilot, its 200 Hz loop logged every 8th tick at 25 Hz, flies on a gyro whose 27 and 30 Hz
    lines fold to 2 and 5 Hz, and commands them: kept in the commands, the yaw took a 46 ms servo lag and its damping
    came out +296 % (the gains 12-45 % off); regressed out of commands and gyro together, no timing is found and the
    fit is the loop's alone (its dampings high by the correction inside each sample, which the closed-loop check
    measures: docs/method.md)."""
    config = replace(BENCH_CELLS["broadband-autopilot"], duration=300, sample_rate=FS, log_every=8)
    sim = simulate_flight(300, seed=1701, config=config)
    fit = MaximumLikelihoodIdentifier(**CLI_TIMING, closed_loop=None).fit(sim.flight)
    truth, got = sim.truth.values(), fit.params_.values()
    assert all(f.delay == 0.0 and f.lag == 0.0 for f in fit.axes_.values())
    assert all(abs(got[k] / truth[k] - 1) < 0.06 for k in ("k2", "k6", "k10"))
    assert all(0.2 < got[k] / truth[k] - 1 < 0.6 for k in ("k3", "k7", "k11"))  # the loop's own, left here
    fed = {ln["axis"] for ln in fit.vibration_lines_[0] if ln.get("signal") == "command" and ln.get("folded")}
    assert fed == {"roll", "pitch", "yaw"}
    assert "commands carry them too" in folded_lines_warning(fit)[0]
