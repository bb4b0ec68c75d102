"""Tests of the log importers (:mod:`identification.io` px4 / ardupilot / blackbox) against real logs.

The logs live outside the repository: in the folder ``$HELI_FIXTURES`` names, else
in ``../shared/fixtures/logs/`` beside the repository (see its README); the
real-log tests skip with a reason naming both when neither exists, or when a
parser of the ``logs`` extra is absent. Each log is decoded once per module
(``raw`` fixture); the options are then exercised on the decoded streams, which
is cheap.

The corpus tests read every fixture as it comes and check each one imports or is
refused with a named error whose message says what to try next; truncated and
padded copies (made in ``tmp_path``) must do the same.

Figures worth reading (attitude-derivative vs rate correlation, detected
segment, identified control gain and R² per axis) are printed; run with ``-s``.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from identification.errors import FlightLogError
from identification.io import (
    DamagedLogError, InputSourceError, LogFormatError, LogSelectionError, MissingStreamError, NotAirborneError,
    SegmentError, detect_format, list_logs, read_csv_flight, read_log, sticks_from_servos, write_csv_flight,
)
from identification.io.clock import UINT32_US_PERIOD_S, continue_clock
from identification.io.container import PAD_MIN, locate_bytes
from identification.io.raw_log import RawLog, h3_120_calibration, rate_attitude_agreement, to_flight
from identification.io.resample import make_stream, resample_stream, uniform_grid, valid_on_grid
from identification.io.segment import SegmentSignals

DEFAULT_LOGS = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "logs"
"""Where the fixture logs sit beside the repository (``../shared/fixtures/logs``)."""


def fixture_dir() -> Path | None:
    """The fixture logs: the folder ``$HELI_FIXTURES`` names if it exists, else ``../shared/fixtures/logs``."""
    env = os.environ.get("HELI_FIXTURES")
    for candidate in ([Path(env)] if env else []) + [DEFAULT_LOGS]:
        if candidate.is_dir():
            return candidate
    return None


def _logs_dir() -> Path:
    folder = fixture_dir()
    if folder is None:
        pytest.skip(f"real flight logs not found: set HELI_FIXTURES to their folder (now "
                    f"{os.environ.get('HELI_FIXTURES')!r}) or provide {DEFAULT_LOGS} (they sit outside the repository)")
    return folder

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
    return _fixture(CASES[name][0], CASES[name][1])


def _fixture(filename: str, parser: str) -> Path:
    """A fixture log by file name (skip, naming where it was looked for, when absent)."""
    folder = _logs_dir()
    path = folder / filename
    if not path.exists():
        pytest.skip(f"fixture log {filename} missing from {folder}")
    pytest.importorskip(parser, reason=f"parser {parser!r} of the 'logs' extra is not installed")
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


LOOP_RATE_HZ = {"px4": 400.0, "ardupilot": None, "betaflight": 4000.0, "rotorflight": 2000.0}
"""The flight controller's loop rate each log states: the blackbox headers' ``looptime`` (125 µs) times
``pid_process_denom`` (2, 4); PX4's ``IMU_GYRO_RATEMAX`` (its rate controller runs on each gyro sample published,
at most this fast: the log's ``vehicle_angular_velocity`` at 404 Hz); this ArduCopter log has no
``SCHED_LOOP_RATE`` parameter."""


def test_the_logs_own_loop_rate_is_kept_for_the_fit_s_warning(raw):
    """The controller's loop rate rides on the flight's metadata (heli identify warns when its commands are fitted
    slower than it)."""
    name, r = raw
    assert to_flight(r, segment="all").metadata.get("loop_rate_hz") == LOOP_RATE_HZ[name]


def test_a_px4_logs_loop_is_its_gyro_publication_rate():
    """PX4's rate controller runs on each published gyro sample: ``IMU_GYRO_RATEMAX`` is its loop (800 Hz on the
    tagged log, whose controller outputs are logged at 21 Hz)."""
    from identification.io.px4 import load_px4

    assert load_px4(_corpus_path("px4_tagged_default_params.ulg")).metadata["loop_rate_hz"] == 800.0


GYRO_FILTER_HZ = {"px4": 40.0, "ardupilot": 20.0, "betaflight": None, "rotorflight": None}
"""The gyro's 2-pole low-pass each log states: PX4's ``IMU_GYRO_CUTOFF``, ArduPilot's ``INS_GYRO_FILTER``; the
blackbox logs' first-order filters are not read as one."""


def test_the_logs_own_gyro_filter_is_kept_for_the_fit_rate_and_the_check(raw):
    """The corner sets the rate the log is fitted at (identification.fit_rate.stated_every) and the filter the
    closed-loop check flies a controller's loop through (identification.likelihood.loop_world.gyro_biquad)."""
    name, r = raw
    assert to_flight(r, segment="all").metadata.get("gyro_filter_hz") == GYRO_FILTER_HZ[name]


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
    from identification.integral.method import IntegralIdentifier

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


# ------------------------------------------------------------ the corpus as it comes
PARSER = {".ulg": "pyulog", ".bin": "pymavlink"}
HINT = re.compile(r"--segment|--inputs|--allow-damaged|--log ")
"""Every refusal of a real log says what to try next."""

# file: (options, expected) -- expected "import" or (error class, pattern of the message)
CORPUS = {
    "px4_sample_log_small.ulg": ({}, (NotAirborneError, r"thrust demand \(actuator_controls_0\.control\[3\] "
                                                         r"\(instance 0\)\).*armed for .*--segment all")),
    "px4_tagged_default_params.ulg": ({}, (NotAirborneError, r"never armed \(actuator_armed\.armed \(instance 0\) is "
                                                             r"0 throughout\).*--segment all")),
    "ardupilot_copter_log171.bin": ({}, "import"),
    "ardupilot_plane_v3.8.bin": ({}, (NotAirborneError, r"holds 0\.\d+ s of continuous data.*--segment all")),
    "betaflight_quad_btfl_035.bbl": ({}, "import"),
    "betaflight_multi_btfl_all.bbl": ({}, "import"),
    "betaflight_gps_rescue.bbl": ({}, (NotAirborneError, r"holds 1\.\d+ s of continuous data.*--segment all")),
    "blackbox_LOG00037.BFL": ({}, "import"),
    "blackbox_error_recovery.bbl": ({}, (DamagedLogError, r"3 of 13 frames invalid.*--allow-damaged")),
    "rotorflight_k110_LOG246.TXT": ({}, (NotAirborneError, r"never left the ground.*--segment all")),
}
# ... and what the advice of each refusal leads to
ADVICE = {
    "px4_sample_log_small.ulg": {"segment": "all"},
    "px4_tagged_default_params.ulg": {"segment": "all"},
    "ardupilot_plane_v3.8.bin": {"segment": "all"},
    "betaflight_gps_rescue.bbl": {"segment": "all"},
    "blackbox_error_recovery.bbl": {"segment": "all", "allow_damaged": True},
    "rotorflight_k110_LOG246.TXT": {"segment": "all"},
}


def _corpus_path(filename: str) -> Path:
    return _fixture(filename, PARSER.get(Path(filename).suffix.lower(), "orangebox"))


_READ_CACHE: dict = {}


def _read_default(filename: str):
    """read_log of a corpus file with the default options, once per module (the flash dump decodes 44 logs)."""
    if filename not in _READ_CACHE:
        _READ_CACHE[filename] = read_log(_corpus_path(filename))
    return _READ_CACHE[filename]


@pytest.mark.parametrize("filename", list(CORPUS))
def test_every_fixture_imports_or_says_why_and_what_to_try(filename):
    path = _corpus_path(filename)
    options, expected = CORPUS[filename]
    if expected == "import":
        flight = _read_default(filename) if not options else read_log(path, **options)
        m = flight.metadata
        print(f"\n{filename}: {flight.duration:.1f} s at {flight.sample_rate:.0f} Hz, segment {m['segment']}, "
              f"attitude {m['attitude_source']}; warnings {m.get('import_warnings')}")
        assert flight.duration > 10.0 and m["segment_mode"] == "auto"
        return
    cls, pattern = expected
    with pytest.raises(cls, match=pattern) as info:
        read_log(path, **options)
    assert HINT.search(str(info.value)), f"the refusal says what to try next: {info.value}"
    if filename in ADVICE:
        flight = read_log(path, **ADVICE[filename])
        print(f"\n{filename} with {ADVICE[filename]}: {flight.duration:.2f} s; warnings "
              f"{flight.metadata.get('import_warnings')}")
        assert flight.n >= 2


def test_a_cut_last_message_is_dropped_and_recorded():
    """ArduPlane 3.8: the last message (AHR2) is cut 24 bytes in; the log imports, and says so."""
    flight = read_log(_corpus_path("ardupilot_plane_v3.8.bin"), segment="all")
    cut = flight.metadata["cut_last_message"]
    assert cut == {"message": "AHR2", "bytes_present": 24, "message_bytes": 45}
    assert any("ends 24 bytes into its last message" in w for w in flight.metadata["import_warnings"])
    assert flight.metadata["vehicle"] == "fixed-wing"
    assert any("not a rotorcraft" in w for w in flight.metadata["import_warnings"])
    assert flight.metadata["loop_rate_hz"] == 50.0  # its SCHED_LOOP_RATE parameter


def test_logs_without_attitude_reconstruct_it_and_say_so():
    flight = _read_default("blackbox_LOG00037.BFL")
    m = flight.metadata
    assert m["attitude_source"] == "reconstructed"
    assert any("no attitude stream" in w for w in m["import_warnings"])
    assert m["airborne_detection"]["activity_source"].startswith("rates integrated")
    assert m["airborne_detection"]["upright_source"] == "accelerometer"
    assert 12.0 < flight.duration < 17.0


def test_the_longest_airborne_log_of_a_flash_dump_is_the_default():
    path = _corpus_path("betaflight_multi_btfl_all.bbl")
    flight = _read_default("betaflight_multi_btfl_all.bbl")
    m = flight.metadata
    assert (m["log_index"], m["logs_in_file"]) == (4, 44)
    assert "longest airborne segment" in m["log_choice"]
    assert m["import_warnings"][0].startswith("the file holds 44 logs (7 with flight data): imported log 4")
    with pytest.raises(MissingStreamError, match=r"\(log 2 of 44\): .*0 decodable frames.*--log N"):
        read_log(path, log=2)
    with pytest.raises(LogSelectionError, match="holds 44 blackbox logs; there is no log 45"):
        read_log(path, log=45)
    with pytest.raises(LogSelectionError, match="holds one log; there is no log 2"):
        read_log(_corpus_path("ardupilot_plane_v3.8.bin"), log=2)


def _heads(path: Path, limit: int = 200_000) -> bytes:
    """A fixture's bytes, at most its first ``limit`` (a big log's head stands in for it, to keep tests fast)."""
    return path.read_bytes()[:limit]


def _outcome(path: Path, **options):
    """(flight, None) or (None, the named error) of read_log; any other exception propagates."""
    try:
        return read_log(path, **options), None
    except FlightLogError as e:
        return None, e


@pytest.mark.parametrize("filename", list(CORPUS))
def test_padded_copies_import_exactly_like_the_original(filename, tmp_path):
    """Leading 0xFF (a flash dump), trailing 0xFF or 0x00 padding: the same flight, the padding recorded."""
    data = _heads(_corpus_path(filename))
    base = tmp_path / filename
    base.write_bytes(data)
    options = {"segment": "all"}
    ref, ref_error = _outcome(base, **options)
    for label, content in {"lead-ff": b"\xff" * 4096 + data, "trail-ff": data + b"\xff" * 8192,
                           "trail-00": data + b"\x00" * 8192, "both": b"\xff" * 100 + data + b"\xff" * 3000}.items():
        copy = tmp_path / label / filename
        copy.parent.mkdir()
        copy.write_bytes(content)
        got, error = _outcome(copy, **options)
        if ref is None:
            assert type(error) is type(ref_error), f"{label}: {error!r} vs {ref_error!r}"
            continue
        assert got is not None, f"{label}: {error}"
        assert_array_equal(got.time, ref.time)
        assert_array_equal(got.rates, ref.rates)
        assert_array_equal(got.sticks, ref.sticks)
        if got.metadata.get("log_index", 1) == 1 or label != "lead-ff":  # leading padding is log 1's
            assert any("padding" in w for w in got.metadata["import_warnings"]), label


@pytest.mark.parametrize("filename", list(CORPUS))
def test_cut_copies_import_what_is_there_or_say_why(filename, tmp_path):
    """Cut mid-log (battery unplugged), alone or followed by erased flash: import, recording the cut, or refuse
    with a named error that says what to try."""
    data = _heads(_corpus_path(filename))
    for label, content in {"cut-60%": data[: int(0.6 * len(data))],
                           "cut-60%-then-erased": data[: int(0.6 * len(data))] + b"\xff" * 4096,
                           "cut-87%": data[: int(0.87 * len(data)) + 3]}.items():
        copy = tmp_path / label / filename
        copy.parent.mkdir()
        copy.write_bytes(content)
        flight, error = _outcome(copy, segment="all")
        if flight is None:
            print(f"\n{filename} {label}: {type(error).__name__}: {str(error)[:200]}")
            assert isinstance(error, (NotAirborneError, MissingStreamError, DamagedLogError, LogFormatError))
            assert copy.name in str(error)
            continue
        m = flight.metadata
        print(f"\n{filename} {label}: imported {flight.duration:.1f} s; {m.get('import_warnings')}")
        notes = " ".join(m.get("import_warnings", []))
        assert "cut_last_message" in m or "unreadable bytes" in notes or "padding" in notes or \
            filename == "blackbox_error_recovery.bbl", notes


def test_damage_in_the_middle_is_refused_unless_allowed(tmp_path):
    for name in ("px4", "ardupilot", "betaflight", "rotorflight"):
        data = bytearray(_heads(_log_path(name)))
        i = len(data) // 2
        data[i:i + 2000] = np.random.default_rng(7).integers(0, 256, 2000, dtype=np.uint8).tobytes()
        copy = tmp_path / f"garbled-{name}"
        copy.write_bytes(bytes(data))
        with pytest.raises(DamagedLogError, match=r"damaged in the middle.*--allow-damaged") as info:
            read_log(copy, segment="all")
        assert copy.name in str(info.value)
        flight, error = _outcome(copy, segment="all", allow_damaged=True)
        print(f"\n{name} garbled at 50%: {str(info.value)[:160]}; with allow_damaged: "
              f"{'imported %.1f s' % flight.duration if flight else type(error).__name__}")
        if flight is not None:
            assert flight.metadata["damage"]


def test_several_logs_in_one_file_are_listed_and_chosen(tmp_path):
    """Two blackbox logs in one file, padded with erased flash between: --list shows both; the default is the
    airborne one; --log picks the other."""
    short = _corpus_path("betaflight_gps_rescue.bbl").read_bytes()
    flying = _corpus_path("blackbox_LOG00037.BFL").read_bytes()
    dump = tmp_path / "LOG00001.TXT"
    dump.write_bytes(b"\xff" * 16 + short + b"\xff" * 3000 + flying + b"\xff" * 2000)
    rows = list_logs(dump)
    assert [r["log"] for r in rows] == [1, 2]
    assert rows[0]["airborne_s"] == 0.0 and rows[1]["airborne_s"] > 10.0 and rows[1]["attitude"] is False
    assert read_log(dump).metadata["log_index"] == 2
    one = read_log(dump, log=1, segment="all")
    assert one.metadata["log_index"] == 1 and one.duration < 2.0
    assert detect_format(dump) == "blackbox"


def test_a_clock_restart_is_continued_and_never_spanned(tmp_path):
    """A DataFlash file holding the same log twice (the clock restarts at the second FMT): continued, recorded."""
    from pymavlink.DFReader import DFReader_binary

    path = _log_path("ardupilot")
    head = path.read_bytes()[:700_000]
    (tmp_path / "head.bin").write_bytes(head)
    f = DFReader_binary(str(tmp_path / "head.bin"), zero_time_base=False)
    boundary = max(int(o) for o in f.offsets[f.name_to_id["IMU"]] if int(o) < 600_000)  # a message start
    twice = tmp_path / "twice.bin"
    twice.write_bytes(head[:boundary] + head[:boundary])
    flight = read_log(twice, segment="all")
    clock = flight.metadata["clock"]
    assert len(clock) == 1 and clock[0]["kind"] == "restart" and clock[0]["first_after_s"] < clock[0]["last_before_s"]
    assert any("clock is not monotonic" in w for w in flight.metadata["import_warnings"])
    assert np.all(np.diff(flight.time) > 0)


def test_continue_clock_undoes_wrap_around_restart_and_glitch():
    t = np.arange(0.0, 10.0, 0.01)
    wrapped = np.concatenate([UINT32_US_PERIOD_S - 2.0 + t[:200], t[200:] - 2.0])
    fixed, keep, events = continue_clock(wrapped)
    assert keep.all() and events[0]["kind"] == "wrap-around"
    assert_allclose(np.diff(fixed), 0.01, atol=1e-6)
    restarted = np.concatenate([100.0 + t, t])
    fixed, _, events = continue_clock(restarted)
    assert events[0]["kind"] == "restart" and np.all(np.diff(fixed) > 0)
    assert fixed[1000] - fixed[999] == pytest.approx(1.0, abs=1e-9)  # RESTART_GAP_S: a gap no segment spans
    glitch = t.copy()
    glitch[500] = 1e9
    fixed, keep, events = continue_clock(glitch)
    assert not events and not keep[500] and keep.sum() == t.size - 1


def test_format_is_found_inside_padding_and_logs_are_split():
    ulog = b"ULog\x01\x12\x35" + b"\x01" * 200
    located = locate_bytes(b"\xff" * 10 + ulog + b"\x00" * PAD_MIN)
    assert located.format == "px4-ulog"
    assert (located.logs[0].start, located.logs[0].lead, located.logs[0].trail) == (10, 10, PAD_MIN)
    short_tail = locate_bytes(ulog + b"\x00" * (PAD_MIN - 1))  # a message may end in zeros: not padding
    assert short_tail.logs[0].stop == len(ulog) + PAD_MIN - 1
    with pytest.raises(LogFormatError, match="only 0xFF/0x00 bytes"):
        locate_bytes(b"\xff" * 1000)
    with pytest.raises(LogFormatError, match=r"unknown log format \(first bytes after 3 bytes of 0xFF/0x00"):
        locate_bytes(b"\xff\xff\xffGARBAGE")


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
    # the stage line ("import: reading ...") is progress; the error is one line of its own
    err = [line for line in capsys.readouterr().err.strip().splitlines() if not line.startswith("import: ")]
    assert len(err) == 1 and "NotAirborneError" in err[0] and "--segment all" in err[0]
    assert not list(tmp_path.iterdir()), "nothing is written for a refused log"


def test_cli_warns_one_line_each_and_records_the_cut(tmp_path, capsys):
    from heli_cli.main import main

    out = tmp_path / "plane.csv"
    assert main(["import", str(_corpus_path("ardupilot_plane_v3.8.bin")), "--out", str(out), "--segment", "all"]) == 0
    err = [line for line in capsys.readouterr().err.strip().splitlines() if not line.startswith("import: ")]
    assert err and all(line.startswith("heli import: warning: ") for line in err)
    assert any("last message (AHR2" in line for line in err)
    meta = json.loads((tmp_path / "plane.meta.json").read_text())
    assert meta["cut_last_message"]["message"] == "AHR2" and meta["import_warnings"]


def test_cli_damaged_log_writes_nothing_and_names_the_flag(tmp_path, capsys):
    from heli_cli.main import main

    path = _corpus_path("blackbox_error_recovery.bbl")
    assert main(["import", str(path), "--out", str(tmp_path / "f.csv")]) == 2
    assert "--allow-damaged" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
    assert main(["import", str(path), "--out", str(tmp_path / "f.csv"), "--allow-damaged", "--segment", "all"]) == 0
    assert json.loads((tmp_path / "f.meta.json").read_text())["damage"]


def test_cli_list_and_log(tmp_path, capsys):
    from heli_cli.main import main

    dump = tmp_path / "LOG00002.TXT"
    dump.write_bytes(_corpus_path("betaflight_gps_rescue.bbl").read_bytes() + b"\xff" * 700
                     + _corpus_path("betaflight_gps_rescue.bbl").read_bytes())
    assert main(["import", str(dump), "--list"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].endswith("2 logs") and len(out) == 4
    assert not (tmp_path / "f.csv").exists()
    assert main(["import", str(dump), "--log", "2", "--segment", "all", "--out", str(tmp_path / "f.csv")]) == 0
    assert "log 2 of 2" in capsys.readouterr().out
    assert main(["import", str(dump)]) == 2
    assert "--out FLIGHT.csv is required" in capsys.readouterr().err


def test_fixture_folder_from_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("HELI_FIXTURES", str(tmp_path))
    assert fixture_dir() == tmp_path
    monkeypatch.setenv("HELI_FIXTURES", str(tmp_path / "absent"))
    assert fixture_dir() in (None, DEFAULT_LOGS)


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


def test_not_airborne_names_the_condition_that_failed():
    """Issue 31: the peaks were all above their thresholds yet 'longest such run 0.0 s'; the message now says
    which condition kept every run short (the Rotorflight log's power holds 2.6 s at most, not 3)."""
    with pytest.raises(NotAirborneError, match=r"'power >= 0\.15' holds at most 2\.\d s at a time"):
        read_log(_log_path("rotorflight"))


def test_cli_errors_advise_options_and_the_python_api_its_arguments(tmp_path, capsys):
    """Issue 31: the CLI advised ``segment='all'``; it advises ``--segment all``, the Python API its argument."""
    from heli_cli.main import main

    with pytest.raises(NotAirborneError, match=r"pass segment='all'"):
        read_log(_log_path("rotorflight"))
    assert main(["import", str(_log_path("rotorflight")), "--out", str(tmp_path / "f.csv"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "pass --segment all or" in err and "segment='all'" not in err
    assert main(["import", str(_corpus_path("blackbox_error_recovery.bbl")), "--out", str(tmp_path / "f.csv"),
                 "-q"]) == 2
    err = capsys.readouterr().err
    assert "pass --allow-damaged to import" in err and "allow_damaged=True" not in err


def test_cli_list_says_each_refusal_once_and_shows_progress(capsys):
    """Issue 31: --list printed nothing for 6 s, then 37 identical error sentences in 44 rows."""
    from heli_cli.main import main

    assert main(["import", str(_corpus_path("betaflight_multi_btfl_all.bbl")), "--list"]) == 0
    captured = capsys.readouterr()
    out = captured.out.splitlines()
    assert out[0].endswith("44 logs")
    refused = [line for line in out if "MissingStreamError" in line]
    assert refused == [line for line in out if line.startswith("37 logs (2-3, 5-11, 13-15, 17-27, 29-32, 34, 36-44): "
                                                                "MissingStreamError: ")] and len(refused) == 1
    assert len(out) == 2 + 7 + 1  # title, header, the 7 logs that decode, the one refusal
    assert "import: decoding 44 logs of " in captured.err  # off a terminal: one line as decoding starts


def test_list_logs_reports_progress_per_log():
    from identification.io import list_logs

    calls = []
    rows = list_logs(_corpus_path("betaflight_gps_rescue.bbl"), progress=lambda done, total: calls.append((done, total)))
    assert len(rows) == 1 and calls == [(0, 1), (1, 1)]
    calls.clear()
    list_logs(_corpus_path("px4_sample_log_small.ulg"), progress=lambda done, total: calls.append((done, total)))
    assert calls == [(0, 1), (1, 1)]
