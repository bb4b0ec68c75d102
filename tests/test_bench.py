"""The test bench (identification.bench.cells) and the generator's wind, pilot, sensor and log-timing options."""

from __future__ import annotations

import hashlib
from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from identification.bench.cells import BENCH_CELLS, PAPER_LEVEL_CLOSED_LOOP_BROADBAND, bench_flight
from identification.bench.flight_config import MANOEUVRE_CONFIG, FlightConfig
from identification.bench.synthetic import simulate_flight


def _digest(sim) -> str:
    f = sim.flight
    return hashlib.sha256(np.ascontiguousarray(np.vstack([f.rates, f.sticks, f.attitude, sim.wind])).tobytes()).hexdigest()


_DEFAULT_FLIGHT_DIGESTS = {
    True: ("1f71f6ae07c52ed632504ff652b818041687fa37f048095374fb0148439119ce",
           "4ad377e0b8126d214c9ccd330c0e082d539728e113c6dba786070787cb7c8501"),
    False: ("1deaf60e08e85d82f00c0d7b1de5a0ac118139d4884f70fc6eb36f86ea31cdaf",
            "f4c60666a43e7fc28a6ad1e8c127cba5596edce6bca4fd69a97bf1c90cee7640"),
}
"""Digests of two flights made before the bench options existed, by whether numpy computes its float64 sin, cos
and exp with AVX-512 (Intel's SVML, on the Xeons and the Zen 4/5 machines the first were made on) or with its
other code (an AVX2 machine, AMD EPYC Zen 3, 2026-12-03): the two differ in a last bit, and so do the flights."""


def _numpy_uses_avx512() -> bool:
    from numpy._core._multiarray_umath import __cpu_features__

    return bool(__cpu_features__.get("AVX512_SKX"))


def test_default_flights_are_unchanged_by_the_new_options():
    default, manoeuvre = _DEFAULT_FLIGHT_DIGESTS[_numpy_uses_avx512()]
    assert _digest(simulate_flight(60, seed=1)) == default
    assert _digest(simulate_flight(60, seed=3, config=MANOEUVRE_CONFIG, effects=("servo_delay",))) == manoeuvre


@pytest.mark.parametrize("cell", list(BENCH_CELLS))
def test_every_cell_flies_a_finite_flight_at_its_wind_level(cell):
    sim = bench_flight(cell, seed=2, duration=60)
    assert np.all(np.isfinite(sim.flight.rates)) and np.all(np.abs(sim.flight.sticks) <= 1.0)
    level = np.asarray(BENCH_CELLS[cell].wind_level)
    half90 = np.percentile(np.abs(sim.wind - sim.wind.mean(axis=1, keepdims=True)), 90, axis=1)
    np.testing.assert_allclose(half90, level, rtol=0.2)
    assert _digest(sim) == _digest(bench_flight(cell, seed=2, duration=60))  # same seed, same flight


def test_headline_cells_are_closed_loop_broadband_at_the_paper_level():
    for cell in PAPER_LEVEL_CLOSED_LOOP_BROADBAND:
        cfg = BENCH_CELLS[cell]
        assert cfg.pilot in ("pd", "pid") and cfg.wind_model != "lowpass"
        assert cfg.wind_level == (0.09, 0.09, 0.03)


def test_gauss_markov_gusts_are_broader_than_the_lowpass_ones():
    fs = 100.0
    broad = simulate_flight(120, seed=1, config=FlightConfig(wind_model="gauss_markov", wind_fast_tau=0.35)).wind[0]
    smooth = simulate_flight(120, seed=1).wind[0]
    f, pb = signal.welch(broad, fs, nperseg=2048)
    _, ps = signal.welch(smooth, fs, nperseg=2048)
    band = (f > 2) & (f < 5)
    assert pb[band].sum() / pb.sum() > 10 * ps[band].sum() / ps.sum()


def test_autopilot_holds_its_commands_and_input_shift_moves_the_logged_sticks():
    base = FlightConfig(pilot="autopilot", duration=30)
    sim = simulate_flight(config=base, seed=1)
    shifted = simulate_flight(config=replace(base, input_shift=0.05), seed=1)
    np.testing.assert_array_equal(shifted.flight.sticks[:, 5:], sim.flight.sticks[:, :-5])
    np.testing.assert_array_equal(shifted.flight.rates, sim.flight.rates)
    assert shifted.flight.metadata["input_shift_s"] == pytest.approx(0.05)


def test_the_autopilot_flies_on_what_its_sensors_read():
    # a flight controller's commands carry its gyro's vibration (through its D-term low-pass); a human's do not
    auto = simulate_flight(60, seed=1, config=FlightConfig(pilot="autopilot", vibration_lines=((27.0, 0.05),)))
    human = simulate_flight(60, seed=1, config=FlightConfig(pilot="pd", vibration_lines=((27.0, 0.05),)))
    for sim, carries in ((auto, True), (human, False)):
        f, p = signal.welch(sim.flight.sticks[0], 100.0, nperseg=1024)
        line = p[np.argmin(np.abs(f - 27.0))]
        assert (line > 100 * np.median(p[(f > 20) & (f < 26)])) == carries
    with pytest.raises(ValueError, match="autopilot_dterm_hz"):
        FlightConfig(autopilot_dterm_hz=0.0)


def test_vibration_line_shows_at_its_frequency():
    sim = simulate_flight(60, seed=1, config=FlightConfig(vibration_lines=((27.0, 0.05),), vibration=0.0))
    f, p = signal.welch(sim.flight.rates[0] - sim.true_rates[0], 100.0, nperseg=1024)
    assert abs(f[np.argmax(p)] - 27.0) < 0.2


@pytest.mark.parametrize("field, value, match", [
    ("wind_model", "karman", "wind_model"), ("pilot", "robot", "pilot"), ("wind_slow_fraction", 1.5, "fraction"),
    ("vibration_lines", ((-1.0, 0.1),), "vibration_lines"), ("input_shift", 200.0, "half the duration"),
])
def test_bad_settings_are_named(field, value, match):
    with pytest.raises(ValueError, match=match):
        FlightConfig(**{field: value})
    with pytest.raises(ValueError, match="unknown bench cell"):
        bench_flight("stormy", 1)


def test_heli_simulate_flight_cell_and_options(tmp_path, capsys):
    from heli_cli.main import main

    assert main(["simulate-flight", "--cell", "independent", "--duration", "20", "--out", str(tmp_path / "a.csv")]) == 0
    assert main(["simulate-flight", "--duration", "20", "--pilot", "autopilot", "--wind-model", "dryden",
                 "--vibration-line", "27:0.03", "--wind-scale", "2", "--out", str(tmp_path / "b.csv")]) == 0
    assert main(["simulate-flight", "--duration", "20", "--input-shift", "30", "--out", str(tmp_path / "c.csv")]) == 2
    assert "half the duration" in capsys.readouterr().err
    assert not (tmp_path / "c.csv").exists()
