"""Tests of :mod:`identification.io.csv_timing`: a CSV flight's clock made uniform before anything is fitted.

A CSV from another tool may have stamps rounded to a millisecond, jitter, a dropped sample, or a pause in the
logging. Before, such a file was fitted as if uniform and then refused minutes later, when its wind was written
to the disturbance library (jitter), or refused at once with advice no command could follow (a dropped sample).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from heli_core.params import ModelParams
from heli_core.physics import QUAT, simulate
from heli_core.quaternion import euler_from_quaternion
from heli_core.sampling import is_uniform
from identification.errors import FlightLogError
from identification.flight import CSV_COLUMNS, make_flight
from identification.io import SegmentError, read_log
from identification.io.csv_timing import clock_of

FINE = 2000.0  # Hz: the "continuous" truth the stamps sample


@pytest.fixture(scope="module")
def truth():
    """A 20 s flight simulated at 2 kHz: the values at any stamp by interpolation (within 1e-6 of the truth)."""
    params = ModelParams(k2=8.0, k3=3.0, k6=6.0, k7=3.0, k10=10.0, k11=4.0, k12=1.0, tau_roll=0.05, tau_pitch=0.05)
    t = np.arange(int(20 * FINE) + 1) / FINE
    sticks = np.array([0.3 * np.sin(2 * np.pi * 0.4 * t) + 0.1 * np.sin(2 * np.pi * 1.3 * t),
                       0.3 * np.sin(2 * np.pi * 0.3 * t + 1.0), 0.2 * np.sin(2 * np.pi * 0.2 * t),
                       0.3 * np.sin(2 * np.pi * 0.5 * t + 2.0)])
    x = simulate(params, t, sticks)
    return t, np.vstack([x[:3], euler_from_quaternion(x[QUAT]), sticks])  # p q r phi theta psi lat lon col ped


def _sample(truth, stamps, values_at=None):
    """Rows (time, the canonical columns) of the truth at ``values_at`` (default ``stamps``), stamped ``stamps``."""
    t, values = truth
    at = stamps if values_at is None else values_at
    return np.column_stack([stamps, *(np.interp(at, t, v) for v in values)])


def _write(path, rows, fmt="%.17g"):
    np.savetxt(path, rows, delimiter=",", header=",".join(CSV_COLUMNS), comments="", fmt=fmt)
    return path


def test_a_uniform_csv_is_read_bit_for_bit(tmp_path, truth):
    rows = _sample(truth, np.arange(1000) * 0.01)
    flight = read_log(_write(tmp_path / "f.csv", rows))
    assert_array_equal(flight.time, rows[:, 0])
    assert_array_equal(flight.rates, rows[:, 1:4].T)
    assert "resampling" not in flight.metadata and "import_warnings" not in flight.metadata


def test_dropped_samples_are_interpolated_and_said(tmp_path, truth):
    stamps = np.arange(2001) * 0.01
    drop = np.zeros(stamps.size, bool)
    drop[[10, 500, 501, 1600]] = True  # one, two in a row, one
    flight = read_log(_write(tmp_path / "f.csv", _sample(truth, stamps[~drop])))
    assert_allclose(flight.time, stamps, atol=1e-12)
    assert is_uniform(flight.time)
    reference = _sample(truth, stamps)
    assert_allclose(flight.rates[:, ~drop], reference[~drop, 1:4].T, atol=1e-12)  # the samples logged, unchanged
    assert_allclose(flight.rates[:, drop], reference[drop, 1:4].T, atol=0.02)  # the missing ones, interpolated
    (warning,) = flight.metadata["import_warnings"]
    assert "4 sample(s) missing (the longest interval 30 ms)" in warning and "heli import" in warning
    assert flight.metadata["resampling"]["missing_samples"] == 4


def test_jittered_stamps_are_read_at_their_slots_of_the_clock(tmp_path, truth):
    """Samples taken up to 2 ms off a 100 Hz clock: each row is read at its slot, its values kept (a white error
    the estimator's noise takes in; interpolating them moved the fitted dampings more:
    scripts/csv_clock_study.py), and the jitter is said."""
    rng = np.random.default_rng(3)
    grid = np.arange(2001) * 0.01
    taken = grid + rng.uniform(-0.002, 0.002, grid.size)
    rows = _sample(truth, taken)
    flight = read_log(_write(tmp_path / "f.csv", rows))
    assert_allclose(np.diff(flight.time), 0.01, rtol=1e-9)
    assert_allclose(flight.time, grid, atol=1e-4)
    assert_array_equal(flight.rates, rows[:, 1:4].T)
    assert flight.metadata["resampling"]["missing_samples"] == 0
    assert "stamps up to 2" in flight.metadata["import_warnings"][0]
    assert "each row read at its slot of the clock" in flight.metadata["import_warnings"][0]


def test_a_logger_off_any_clock_is_interpolated(tmp_path, truth):
    """Stamps more than half an interval off any uniform clock (a rate that wanders 80-120 Hz): the stamps are
    the sample times, so the values are interpolated onto a uniform grid, close to the truth's there."""
    intervals = 0.01 * (1.0 + 0.2 * np.sin(np.arange(1500) * 2 * np.pi / 300))
    stamps = np.concatenate(([0.0], np.cumsum(intervals)))
    flight = read_log(_write(tmp_path / "f.csv", _sample(truth, stamps)))
    assert is_uniform(flight.time) and flight.metadata["resampling"]["jitter_fraction"] > 0.5  # off its mean rate
    assert_allclose(flight.rates, _sample(truth, flight.time)[:, 1:4].T, atol=0.02)
    assert "taken as the sample times and resampled" in flight.metadata["import_warnings"][0]


def test_a_clock_rounded_to_a_millisecond_is_read_on_its_own_clock(tmp_path, truth):
    """400 Hz stamped in whole milliseconds (intervals of 2 and 3 ms): uniform samples, rounded stamps. The
    stamps are replaced by the 2.5 ms clock, the values kept, and nothing is interpolated."""
    clock = 1.0 + np.arange(4001) / 400.0
    rows = _sample(truth, np.round(clock, 3), values_at=clock - 1.0)
    flight = read_log(_write(tmp_path / "f.csv", rows, fmt="%.3f,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,"
                                                           "%.17g,%.17g"))
    assert_allclose(np.diff(flight.time), 0.0025, rtol=1e-9)
    assert_allclose(flight.time, clock, atol=3e-4)  # (the file's own stamps: within rounding of the clock)
    assert_array_equal(flight.rates, rows[:, 1:4].T)
    resampling = flight.metadata["resampling"]
    assert resampling["quantum_s"] == 1e-3 and resampling["rate_hz"] == 400.0
    assert "import_warnings" not in flight.metadata


def test_clock_of_tells_rounding_from_jitter():
    t = np.arange(3000) / 400.0
    rounded = clock_of(np.round(t, 3))
    assert (rounded.quantum, rounded.interval, rounded.missing, rounded.warning("f.csv")) == (1e-3, 0.0025, 0, None)
    rng = np.random.default_rng(0)
    t = np.arange(3000) / 100.0
    jittered = clock_of(np.round(t + rng.uniform(-0.002, 0.002, t.size), 3))  # a stamp up to 25 % off its slot
    assert jittered.quantum is None and jittered.on_clock  # further off the clock than the rounding puts them
    assert (jittered.interval, jittered.missing) == (0.01, 0) and "stamps up to" in jittered.warning("f.csv")
    far = clock_of(np.delete(t + rng.uniform(-0.004, 0.004, t.size), [50, 1200]))  # up to 40 %: counted by phase
    assert far.on_clock and far.interval == 0.01 and far.missing == 2 and far.slots[1199] == 1201
    wandering = np.concatenate(([0.0], np.cumsum(0.01 * (1.0 + 0.2 * np.sin(np.arange(2999) * 2 * np.pi / 300)))))
    lost = clock_of(wandering)  # a rate that wanders 8-12 ms: no clock places the rows
    assert not lost.on_clock and lost.interval == pytest.approx(0.01, rel=1e-3)
    assert "taken as the sample times" in lost.warning("f.csv") and 0.5 < lost.jitter < 20
    clock = clock_of(np.round(np.delete(np.arange(3000) / 400.0, [7, 900]), 6))
    assert (clock.missing, clock.interval, clock.slots[8], clock.slots[-1]) == (2, 0.0025, 9, 2999)


def test_a_pause_in_the_logging_is_refused_naming_the_stretches(tmp_path, truth):
    stamps = np.concatenate([np.arange(600) * 0.01, 8.0 + np.arange(900) * 0.01])  # a 2 s pause at 6 s
    path = _write(tmp_path / "f.csv", _sample(truth, stamps))
    with pytest.raises(SegmentError, match=r"the logging stopped once \(for over 50 ms\); the flight is 2 stretches \(0\.00-5\.99 s, "
                                           r"8\.00-16\.99 s\)\. Read one: --segment all \(the longest, 8\.00-16\.99 s\)"):
        read_log(path)
    longest = read_log(path, segment="all")
    assert (longest.time[0], longest.time.size) == (8.0, 900)
    assert longest.metadata["segment"] == pytest.approx([8.0, 16.99])
    first = read_log(path, segment="1:5")
    assert_allclose(first.time[[0, -1]], [1.0, 5.0])
    with pytest.raises(SegmentError, match="spans a gap in the logged data"):
        read_log(path, segment="3:10")


def test_a_non_finite_value_is_named_at_its_row_in_the_file(tmp_path, truth):
    stamps = np.delete(np.arange(500) * 0.01, 100)  # irregular: would be resampled
    rows = _sample(truth, stamps)
    rows[250, 2] = np.nan
    with pytest.raises(FlightLogError, match=r"column 'q' has 1 non-finite values \(NaN first\), first at row 250"):
        read_log(_write(tmp_path / "f.csv", rows))


def test_make_flight_refuses_stamps_that_are_not_uniform():
    t = np.arange(200) * 0.01
    t[50] += 0.002
    with pytest.raises(FlightLogError, match=r"time is not uniformly sampled: intervals range 8\.*"):
        make_flight(t, np.zeros((3, 200)), np.zeros((4, 200)))


def test_heli_import_writes_the_flight_as_read(tmp_path, truth):
    stamps = np.delete(np.arange(1500) * 0.01, [300, 301])
    path = _write(tmp_path / "f.csv", _sample(truth, stamps))
    out = tmp_path / "uniform.csv"
    run = subprocess.run([sys.executable, "-m", "heli_cli.main", "import", str(path), "--out", str(out)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "2 sample(s) missing" in run.stdout + run.stderr
    again = read_log(out)
    assert again.time.size == 1500 and "resampling" not in again.metadata


def _write_with_blanks(path, rows, blank):
    """A CSV whose fields where ``blank`` (n, columns) are left empty, as a multi-rate export writes them."""
    lines = [",".join(CSV_COLUMNS)]
    lines += [",".join("" if b else repr(float(v)) for v, b in zip(row, empty)) for row, empty in zip(rows, blank)]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_slower_stream_leaves_fields_empty_and_is_interpolated_onto_the_rates(tmp_path, truth):
    """Rates at 100 Hz, sticks at 50 Hz, attitude at 25 Hz (its yaw crossing +-pi): the flight is the rates' rows,
    the slower columns interpolated between their values (angles unwrapped), and the user is told."""
    rows = _sample(truth, np.arange(2000) * 0.01)
    rows[:, 6] = np.angle(np.exp(1j * (rows[:, 6] + 3.1)))  # a heading near +-pi
    blank = np.zeros(rows.shape, bool)
    blank[1::2, 7:] = True
    blank[np.arange(rows.shape[0]) % 4 != 0, 4:7] = True
    flight = read_log(_write_with_blanks(tmp_path / "f.csv", rows, blank))
    n = flight.time.size
    assert n == 1997 and is_uniform(flight.time)  # to the last row every column has reached
    assert_array_equal(flight.rates, rows[:n, 1:4].T)
    assert_allclose(flight.sticks, rows[:n, 7:].T, atol=2e-3)
    assert np.max(np.abs(np.angle(np.exp(1j * (flight.attitude[2] - rows[:n, 6]))))) < 2e-3
    (warning,) = flight.metadata["import_warnings"]
    assert warning.startswith("fields left empty: phi, theta, psi, lat, lon, col, ped hold values on 25% / 50% of "
                              "the rows and were interpolated linearly")


def test_rows_without_a_rate_are_missing_samples(tmp_path, truth):
    rows = _sample(truth, np.arange(1000) * 0.01)
    blank = np.zeros(rows.shape, bool)
    blank[[100, 400], 1:4] = True
    flight = read_log(_write_with_blanks(tmp_path / "f.csv", rows, blank))
    assert flight.time.size == 1000 and flight.metadata["resampling"]["missing_samples"] == 2
    assert len(flight.metadata["import_warnings"]) == 2


def test_empty_fields_that_cannot_be_read(tmp_path, truth):
    rows = _sample(truth, np.arange(100) * 0.01)
    blank = np.zeros(rows.shape, bool)
    blank[1:, 10] = True  # the pedal logged once
    with pytest.raises(FlightLogError, match="column\\(s\\) ped hold fewer than two values"):
        read_log(_write_with_blanks(tmp_path / "f.csv", rows, blank))
    path = _write_with_blanks(tmp_path / "g.csv", rows, np.zeros(rows.shape, bool) | (np.arange(11) == 9))
    text = path.read_text().splitlines()
    text[5] = text[5].replace(",,", ",x,", 1)
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(FlightLogError, match="expected numbers in every field after the header"):
        read_log(path)
    text[5] = text[5] + ",1.0"
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(FlightLogError, match="header names 11 columns but row 5 has 12"):
        read_log(path)
