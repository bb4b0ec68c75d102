"""Tests of the log importers (:mod:`identification.io` px4 / ardupilot / blackbox) against real logs.

The logs live outside the repository, in ``../shared/fixtures/logs/`` (see its
README); the real-log tests skip with a reason when the folder or a parser of the
``logs`` extra is absent. Each log is decoded once per module (``raw`` fixture);
the options are then exercised on the decoded streams, which is cheap.

Figures worth reading (attitude-derivative vs rate correlation, detected
segment, identified control gain and R² per axis) are printed; run with ``-s``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from identification.errors import FlightLogError
from identification.io import (
    DamagedLogError, InputSourceError, LogFormatError, NotAirborneError, SegmentError, detect_format, read_csv_flight,
    read_log, sticks_from_servos, write_csv_flight,
)
from identification.io.raw_log import RawLog, h3_120_calibration, rate_attitude_agreement, to_flight
from identification.io.resample import make_stream, resample_stream, uniform_grid, valid_on_grid
from identification.io.segment import SegmentSignals

LOGS = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "logs"

# name: (file, parser module, loader, expected default input, vehicle)
CASES = {
    "px4": ("px4_sample_log_small.ulg", "pyulog", "identification.io.px4:load_px4", "controller", "multirotor"),
    "ardupilot": ("ardupilot_copter_log171.bin", "pymavlink", "identification.io.ardupilot:load_ardupilot",
                  "controller", "multirotor"),
    "betaflight": ("betaflight_quad_btfl_035.bbl", "orangebox", "identification.io.blackbox:load_blackbox",
                   "controller", "multirotor"),
    "rotorflight": ("rotorflight_k110_LOG246.TXT", "orangebox", "identification.io.blackbox:load_blackbox",
                    "controller", "helicopter"),
}
GAIN = {"roll": "k2", "pitch": "k6", "yaw": "k10"}


def _log_path(name: str) -> Path:
    if not LOGS.is_dir():
        pytest.skip(f"real flight logs not found at {LOGS} (they sit outside the repository, in shared/fixtures)")
    path = LOGS / CASES[name][0]
    if not path.exists():
        pytest.skip(f"fixture log {path.name} missing from {LOGS}")
    pytest.importorskip(CASES[name][1], reason=f"parser {CASES[name][1]!r} of the 'logs' extra is not installed")
    return path


def _loader(name):
    import importlib

    module, func = CASES[name][2].split(":")
    return getattr(importlib.import_module(module), func)


_RAW_CACHE: dict = {}


@pytest.fixture(scope="module", params=list(CASES))
def raw(request):
    """Each real log decoded once (RawLog), with its case name."""
    name = request.param
    path = _log_path(name)
    if name not in _RAW_CACHE:
        _RAW_CACHE[name] = _loader(name)(path)
    return name, _RAW_CACHE[name]


def _raw(name) -> RawLog:
    path = _log_path(name)
    if name not in _RAW_CACHE:
        _RAW_CACHE[name] = _loader(name)(path)
    return _RAW_CACHE[name]


# ------------------------------------------------------------------ real logs
def test_each_log_parses_into_a_canonical_flight(raw):
    name, r = raw
    flight = to_flight(r, segment="all")
    assert r.vehicle == CASES[name][4]
    assert flight.metadata["input_source"] == CASES[name][3], "default input: the one closest to the bare airframe"
    assert flight.metadata["format"] == r.format
    assert flight.n > 500 and np.all(np.isfinite(flight.rates)) and np.all(np.isfinite(flight.attitude))
    assert np.abs(flight.sticks).max() <= 1.0
    assert_allclose(np.diff(flight.time), 1.0 / flight.metadata["resampling"]["rate_hz"], rtol=1e-6)
    assert flight.metadata["sha256"] and flight.metadata["inputs_clipped"].keys() == {"lat", "lon", "col", "ped"}


# Least correlation of the attitude derivative with the rates per axis: the two flights
# (ArduCopter, Betaflight) move a lot; the PX4 sample sits on a bench (rates ~0.1 deg/s)
# and the Rotorflight log on the ground, so only the sign is checked there.
MIN_AGREEMENT = {"px4": 0.5, "ardupilot": 0.98, "betaflight": 0.98, "rotorflight": 0.3}


def test_mapped_rates_agree_with_the_logs_own_attitude(raw):
    name, r = raw
    flight = to_flight(r, segment="all" if name in ("px4", "rotorflight") else "auto")
    agreement = rate_attitude_agreement(flight)
    print(f"\n{name}: attitude-derivative vs rate correlation {agreement}")
    for axis, c in agreement.items():
        assert c is not None and c >= MIN_AGREEMENT[name], f"{name} {axis}: correlation {c}"


def test_rotorflight_ground_log_is_not_airborne():
    r = _raw("rotorflight")
    with pytest.raises(NotAirborneError, match=r"no airborne segment.*never left the ground"):
        to_flight(r, segment="auto")
    # ... but it is read: the whole log is a valid flight.
    assert to_flight(r, segment="all").duration > 15.0


def test_px4_bench_log_is_not_airborne():
    with pytest.raises(NotAirborneError, match="power >= 0.15"):
        to_flight(_raw("px4"), segment="auto")


def test_detected_airborne_segments():
    ap = to_flight(_raw("ardupilot"))  # default segment: auto
    t0, t1 = ap.metadata["segment"]
    print(f"\nardupilot airborne segment {t0:.2f}..{t1:.2f} s; betaflight", end=" ")
    assert 72.0 <= t0 <= 90.0 and 230.0 <= t1 <= 240.0, "README: airborne ~72-240 s, crash (flip) at ~238 s"
    assert np.degrees(np.abs(ap.attitude[:2])).max() < 60.0
    bf = to_flight(_raw("betaflight"))
    t0, t1 = bf.metadata["segment"]
    print(f"{t0:.2f}..{t1:.2f} s")
    assert t1 - t0 > 20.0
    assert bf.metadata["airborne_detection"]["criteria_share"]["power"] > 0.9


@pytest.mark.parametrize("name, supported", [("betaflight", ("roll", "pitch", "yaw")), ("ardupilot", ("yaw",))])
def test_identification_finds_positive_control_gains(name, supported):
    from identification.integral_method import IntegralIdentifier

    flight = to_flight(_raw(name))
    ident = IntegralIdentifier().fit(flight)
    report = {a: (round(f.params[GAIN[a]], 3), round(f.r2, 3)) for a, f in ident.axes_.items()}
    print(f"\n{name} ({flight.metadata['input_source']} inputs): control gain, R² per axis {report}")
    # Axes where the data supports the model (R² >= 0.3) must show a positive gain; the
    # ArduCopter's 10 Hz RATE logging leaves roll and pitch below that (R² ~0.02-0.05).
    assert {a for a, f in ident.axes_.items() if f.r2 >= 0.3} >= set(supported)
    for axis in supported:
        assert ident.axes_[axis].params[GAIN[axis]] > 0, report


@pytest.mark.parametrize("name", ["px4", "ardupilot", "betaflight"])
def test_servos_do_not_apply_to_multirotors(name):
    with pytest.raises(InputSourceError, match="'servos' does not apply.*multirotor"):
        to_flight(_raw(name), inputs="servos", segment="all")


def test_rotorflight_without_servo_fields_says_so():
    with pytest.raises(InputSourceError, match="no servo.*fields"):
        to_flight(_raw("rotorflight"), inputs="servos", segment="all")


def test_unknown_input_source():
    with pytest.raises(InputSourceError, match="one of sticks, controller, servos, got 'motors'"):
        to_flight(_raw("betaflight"), inputs="motors")


def test_sticks_are_clipped_with_a_recorded_count():
    # Before the receiver links, ArduPilot logs RCIN as PWM 0, i.e. -3 after scaling.
    flight = to_flight(_raw("ardupilot"), inputs="sticks", segment=(12.0, 70.0))  # before arming
    assert np.abs(flight.sticks).max() <= 1.0
    assert flight.metadata["inputs_clipped"]["lon"] > 0
    assert "RCMAP" in flight.metadata["input_mapping"]


def test_explicit_segments():
    r = _raw("ardupilot")
    f = to_flight(r, segment="100:120")
    assert_allclose([f.time[0], f.time[-1]], [100.0, 120.0], atol=0.02)
    with pytest.raises(SegmentError, match="spans a gap in the logged data"):
        to_flight(r, segment=(70.0, 80.0))  # logging paused 72.6-74.6 s
    with pytest.raises(SegmentError, match="outside the log's data"):
        to_flight(r, segment="0:5000")
    with pytest.raises(SegmentError, match="'auto', 'all' or 'T0:T1'"):
        to_flight(r, segment="soon")


def test_same_input_same_output(tmp_path):
    path = _log_path("betaflight")
    a = read_log(path, segment="380:390")
    b = read_log(path, segment="380:390")
    for x, y in ((a.time, b.time), (a.rates, b.rates), (a.attitude, b.attitude), (a.sticks, b.sticks)):
        assert_array_equal(x, y)
    out = write_csv_flight(a, tmp_path / "f.csv")
    back = read_log(out)
    assert back.metadata["format"] == "csv"
    assert_allclose(back.rates, a.rates, rtol=0, atol=1e-12)


def test_content_sniffing_not_extension(tmp_path):
    path = _log_path("ardupilot")
    disguised = tmp_path / "flight.csv"
    disguised.write_bytes(path.read_bytes()[:200_000])
    assert detect_format(disguised) == "ardupilot-dataflash"
    junk = tmp_path / "log.bin"
    junk.write_bytes(b"\x00\x01garbage" * 10)
    with pytest.raises(LogFormatError, match="unknown log format"):
        read_log(junk)
    empty = tmp_path / "empty.ulg"
    empty.write_bytes(b"")
    with pytest.raises(LogFormatError, match="empty file"):
        read_log(empty)


# ----------------------------------------------------------- damaged copies
def _damaged_copies(path: Path, tmp_path: Path):
    data = path.read_bytes()
    rng = np.random.default_rng(7)
    copies = {
        "cut-early": data[: max(int(len(data) * 0.002), 40)],
        "cut-30%": data[: int(len(data) * 0.3)],
    }
    for where in (0.001, 0.5):
        b = bytearray(data)
        i = int(len(b) * where)
        b[i:i + 2000] = rng.integers(0, 256, 2000, dtype=np.uint8).tobytes()
        copies[f"garbled-at-{where:.1%}"] = bytes(b)
    out = {}
    for label, content in copies.items():
        p = tmp_path / f"{label}-{path.name}"
        p.write_bytes(content)
        out[label] = p
    return out


@pytest.mark.parametrize("name", list(CASES))
def test_damaged_copies_raise_a_named_error(name, tmp_path):
    path = _log_path(name)
    for label, copy in _damaged_copies(path, tmp_path).items():
        with pytest.raises(LogFormatError) as info:
            _loader(name)(copy)
        msg = str(info.value)
        assert copy.name in msg, f"{label}: the message names the file: {msg}"
        print(f"\n{name} {label}: {type(info.value).__name__}: {msg[:160]}")


def test_allow_damaged_imports_what_decodes(tmp_path):
    path = _log_path("betaflight")
    cut = tmp_path / "cut.bbl"
    cut.write_bytes(path.read_bytes()[: int(path.stat().st_size * 0.6)])
    with pytest.raises(DamagedLogError, match="allow_damaged=True"):
        read_log(cut)
    flight = read_log(cut, allow_damaged=True, segment="all")
    assert flight.metadata["damage"] and flight.duration > 10.0


# ------------------------------------------------------------- CLI
def test_cli_import_writes_csv_and_metadata(tmp_path, capsys):
    from heli_cli.main import main

    path = _log_path("ardupilot")
    out = tmp_path / "flight.csv"
    assert main(["import", str(path), "--out", str(out), "--segment", "100:140", "--inputs", "sticks"]) == 0
    flight = read_csv_flight(out)
    assert_allclose(flight.duration, 40.0, atol=0.05)
    meta = json.loads((tmp_path / "flight.meta.json").read_text())
    assert meta["input_source"] == "sticks" and meta["format"] == "ardupilot-dataflash"
    assert set(meta["rate_attitude_correlation"]) == {"roll", "pitch", "yaw"}
    assert "attitude-derivative vs rate correlation" in capsys.readouterr().out


def test_cli_ground_log_is_one_line_exit_2(tmp_path, capsys):
    from heli_cli.main import main

    path = _log_path("rotorflight")
    assert main(["import", str(path), "--out", str(tmp_path / "f.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "NotAirborneError" in err[0]
    assert not (tmp_path / "f.csv").exists()


# ------------------------------------------------- synthetic: no real log needed
def test_resampling_of_streams_at_different_rates_and_a_gap():
    t_fast = np.arange(0, 10, 0.002)  # 500 Hz
    fast = make_stream(t_fast, [np.sin(t_fast)], "fast")
    t_slow = np.concatenate([np.arange(0, 4, 0.1), np.arange(6, 10, 0.1)])  # 10 Hz, gap 3.9-6 s
    slow = make_stream(t_slow, [np.cos(t_slow)], "slow")
    grid = uniform_grid(0.0, 9.9, 100.0)
    assert_allclose(resample_stream(fast, grid)[0][50:-50], np.sin(grid)[50:-50], atol=2e-3)
    ok = valid_on_grid(grid, slow)
    assert not ok[(grid > 3.95) & (grid < 5.95)].any() and ok[grid < 3.85].all()
    assert_allclose(resample_stream(slow, grid)[0][ok], np.cos(grid)[ok], atol=5e-3)  # linear between samples


def test_angles_are_interpolated_across_the_wrap():
    t = np.arange(0, 2, 0.1)
    yaw = np.angle(np.exp(1j * (3.0 + 0.5 * t)))  # crosses +pi
    s = make_stream(t, [yaw], "yaw", angles=True)
    grid = uniform_grid(0.0, 1.9, 50.0)
    assert_allclose(np.exp(1j * resample_stream(s, grid)[0]), np.exp(1j * (3.0 + 0.5 * grid)), atol=1e-9)


def test_time_base_glitches_are_dropped_and_counted():
    s = make_stream([5.0, 4.0, 3.0, 6.0, 7.0, 7.0, 8.0], [[1, 2, 3, 4, 5, 6, 7]], "x")
    assert_array_equal(s.time, [5.0, 6.0, 7.0, 8.0])
    assert s.dropped == 3


def _synthetic_heli(servo_pulses, t):
    rates = make_stream(t, np.zeros((3, t.size)) + 0.01 * np.sin(t), "gyro")
    att = make_stream(t, np.zeros((3, t.size)), "att", angles=True)
    return RawLog(path=Path(__file__), format="test", vehicle="helicopter", rates=rates, attitude=att, inputs={},
                  input_notes={}, unavailable={}, default_input="servos", segment_signals=SegmentSignals(),
                  servos=make_stream(t, servo_pulses, "servo"))


def test_servos_through_the_default_h3_120_mixing_and_a_calibration(tmp_path):
    cal = h3_120_calibration()
    G, trim = np.array(cal["G"]), np.array(cal["U_trim"])
    # Collective lifts all three swash servos; pure roll moves only the two front ones, oppositely.
    assert_allclose(G[:3, 2], 500.0) and assert_allclose(G[2, 1], 0.0, atol=1e-9)
    assert G[0, 1] > 0 > G[1, 1]
    t = np.arange(0, 5, 0.01)
    sticks = np.array([0.5 * np.sin(t), 0.4 * np.cos(t), 0.2 * np.sin(2 * t), 0.3 * np.sin(3 * t)])  # lat lon col ped
    delta = sticks[[1, 0, 2, 3]]  # eq. (65) order: lon, lat, col, ped
    pulses = G @ delta + trim[:, None]
    assert_allclose(sticks_from_servos(pulses, G, trim), sticks, atol=1e-9)
    flight = to_flight(_synthetic_heli(pulses, t), segment="all")
    assert flight.metadata["input_source"] == "servos"
    assert_allclose(flight.sticks, np.clip(sticks[:, : flight.n], -1, 1), atol=1e-9)
    # A calibration file replaces the default (here: servo 1 reversed).
    G2 = G.copy()
    G2[0] *= -1
    (tmp_path / "cal.json").write_text(json.dumps({"G": G2.tolist(), "U_trim": trim.tolist()}))
    flight2 = to_flight(_synthetic_heli(G2 @ delta + trim[:, None], t), calibration=tmp_path / "cal.json",
                        segment="all")
    assert_allclose(flight2.sticks, flight.sticks, atol=1e-9)


def test_named_errors_are_flight_log_errors():
    for cls in (LogFormatError, DamagedLogError, InputSourceError, NotAirborneError, SegmentError):
        assert issubclass(cls, FlightLogError)
