"""Tests of the ArduPilot text DataFlash reader (:mod:`identification.io.dataflash_text`).

A tiny text log written here exercises the parser (good records, a malformed line,
a value that is not a number, a record type without an FMT line, a GPS clock with a
pause); the real ArduCopter 3.0.1 helicopter log of ``../shared/fixtures/logs/`` (or
``$HELI_FIXTURES``; the tests that need it skip, naming both, when it is absent)
checks that ``read_log``, ``list_logs`` and ``heli import`` recognise the format and
refuse it in one line that says what the log holds and what is missing.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from identification.errors import FlightLogError
from identification.io import (
    FORMATS, InsufficientLogError, MissingStreamError, detect_format, list_logs, read_log,
)
from identification.io.dataflash_text import log_clock, parse_text_log, read_text_log

DEFAULT_LOGS = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "logs"
"""Where the fixture logs sit beside the repository (``../shared/fixtures/logs``)."""
TRADHELI = "ardupilot_tradheli_v3.0_brownout.log"

FMT_LINES = [
    "FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format",
    "FMT, 129, 23, PARM, Nf, Name,Value",
    "FMT, 130, 35, GPS, BIBcLLeeEe, Status,Time,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs",
    "FMT, 1, 17, ATT, cccccCC, RollIn,Roll,PitchIn,Pitch,YawIn,Yaw,NavYaw",
    "FMT, 3, 6, MODE, Mh, Mode,ThrCrs",
    "FMT, 10, 3, STRT, , ",
]


def _gps(t_ms: float) -> str:
    return f"GPS, 3, {t_ms:.0f}, 10, 1.49, 24.2398205, 54.5793101, 0.19, 9.48, 0.01, 347.24"


def _att(k: int) -> str:
    return f"ATT, {k * 0.5:.2f}, {k * 0.25:.2f}, 0.00, 0.75, 0.00, 215.88, 215.88"


def _synthetic_lines() -> list[str]:
    """Header, FMT lines, parameters, then GPS at 5 Hz with ATT at 10 Hz: 2 s, a 10 s pause, 1 s.

    Line 16 is ATT with a field missing, line 17 ATT with a value that is not a number, line 18 a record
    type without an FMT line, line 19 not a record at all.
    """
    lines = ["", "58", "ArduCopter V3.0.1", "Free RAM: 1273", "APM 2", *FMT_LINES,
             "PARM, H_SV1_POS, -60.000000", "PARM, FRAME, 0.000000", "MODE, STABILIZE, 494", "STRT",
             "ATT, 1.00, 2.00, 3.00",
             "ATT, 1.00, x, 0.00, 0.75, 0.00, 215.88, 215.88",
             "XYZ, 1, 2, 3",
             "Free RAM: 1273"]
    times = [1000.0 + 200.0 * i for i in range(11)] + [13000.0 + 200.0 * i for i in range(6)]
    k = 0
    for t in times:
        lines.append(_gps(t))
        for _ in range(2):
            lines.append(_att(k))
            k += 1
    return lines


def _write(path: Path, lines: list[str]) -> Path:
    path.write_bytes("\r\n".join(lines).encode("ascii") + b"\r\n")
    return path


def _tradheli() -> Path:
    """The real ArduCopter 3.0.1 text log (skip, naming where it was looked for, when absent)."""
    env = os.environ.get("HELI_FIXTURES")
    folders = [Path(env)] if env else []
    folder = next((f for f in folders + [DEFAULT_LOGS] if f.is_dir()), None)
    if folder is None:
        pytest.skip(f"real flight logs not found: set HELI_FIXTURES to their folder (now {env!r}) or provide "
                    f"{DEFAULT_LOGS} (they sit outside the repository)")
    if not (folder / TRADHELI).exists():
        pytest.skip(f"fixture log {TRADHELI} missing from {folder}")
    return folder / TRADHELI


# ------------------------------------------------------------------ the parser, on a log written here
def test_records_are_read_per_message_and_bad_lines_counted():
    log = parse_text_log("\n".join(_synthetic_lines()))
    assert log.header == ("58", "ArduCopter V3.0.1", "Free RAM: 1273", "APM 2")
    assert log.formats["ATT"].columns == ("RollIn", "Roll", "PitchIn", "Pitch", "YawIn", "Yaw", "NavYaw")
    assert log.count("GPS") == 17 and log.count("ATT") == 34
    assert_allclose(log.messages["ATT"]["Roll"], 0.25 * np.arange(34), atol=1e-12)
    assert_allclose(log.messages["GPS"]["Time"][:2], [1000.0, 1200.0])
    assert_array_equal(log.messages["MODE"]["Mode"], ["STABILIZE"])  # a text field stays text
    assert log.count("STRT") == 1
    assert log.params == {"H_SV1_POS": -60.0, "FRAME": 0.0}
    assert [n for n, _ in log.malformed] == [16, 17, 19]
    assert "ATT with 3 fields, its FMT names 7" in log.malformed[0][1]
    assert "not a number" in log.malformed[1][1]
    assert log.unknown == {"XYZ": 1}


def test_the_gps_clock_leaves_out_pauses():
    clock = log_clock(parse_text_log("\n".join(_synthetic_lines())))
    assert clock.source == "GPS.Time" and clock.stretches == 2
    assert_allclose(clock.duration_s, 3.0, atol=1e-9)  # 10 + 5 intervals of 0.2 s; the 10 s pause left out


def test_a_log_without_a_clock_gives_counts_not_rates(tmp_path):
    lines = [line for line in _synthetic_lines() if not line.startswith("GPS")]
    with pytest.raises(InsufficientLogError, match=r"length unknown: no time stamps and no GPS time.*"
                                                    r"\(ATT\) in 34 records"):
        read_log(_write(tmp_path / "noclock.log", lines))


def test_a_redefined_format_keeps_the_first_and_says_so():
    log = parse_text_log("\n".join(FMT_LINES + ["FMT, 1, 9, ATT, cc, Roll,Pitch", _att(0)]))
    assert log.count("ATT") == 1 and "redefining ATT" in log.malformed[0][1]


def test_text_dataflash_is_found_by_content_after_a_header_and_padding(tmp_path):
    path = _write(tmp_path / "flight.bin", _synthetic_lines())  # the name says .bin; the content decides
    assert detect_format(path) == "ardupilot-dataflash-text" and "ardupilot-dataflash-text" in FORMATS
    padded = tmp_path / "padded"
    padded.write_bytes(b"\xff" * 10 + path.read_bytes() + b"\xff" * 512)
    assert detect_format(padded) == "ardupilot-dataflash-text"
    assert read_text_log(padded).count("ATT") == 34  # the pad bytes fall in no record


def test_the_synthetic_log_is_refused_saying_what_it_holds_and_lacks(tmp_path):
    path = _write(tmp_path / "old.log", _synthetic_lines())
    with pytest.raises(InsufficientLogError) as info:
        read_log(path, segment="all")
    msg = str(info.value)
    for part in ("ArduPilot text DataFlash log (ArduCopter V3.0.1, APM 2, traditional helicopter",
                 "3 s logged in 2 stretches, timed by GPS.Time", "attitude and desired attitude (ATT) at 11 Hz",
                 "GPS at 5.7 Hz", "2 parameters", "no gyro rates (IMU)", "no servo outputs (RCOU)",
                 "no time stamps of its own", "too coarse to identify rate dynamics",
                 "3 malformed lines skipped (first at line 16)", "1 record of types without an FMT line skipped (XYZ)"):
        assert part in msg, f"{part!r} not in {msg!r}"
    assert "\n" not in msg


def test_a_text_log_with_what_identification_needs_points_to_the_bin(tmp_path):
    lines = ["ArduCopter V3.1", "FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format",
             "FMT, 131, 31, IMU, Iffffff, TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ",
             "FMT, 132, 23, RCOU, Ihhhh, TimeMS,Chan1,Chan2,Chan3,Chan4"]
    for i in range(301):  # 3 s at 100 Hz
        lines += [f"IMU, {1000 + 10 * i}, 0.01, 0.02, 0.03, 0.0, 0.0, -9.8",
                  f"RCOU, {1000 + 10 * i}, 1500, 1500, 1500, 1500"]
    with pytest.raises(InsufficientLogError, match=r"3 s logged, timed by (IMU|RCOU)\.TimeMS\): IMU at 100 Hz, "
                                                    r"RCOU at 100 Hz; heli import reads the binary \.bin"):
        read_log(_write(tmp_path / "v31.log", lines))


def test_bytes_that_are_not_text_are_skipped_not_raised(tmp_path):
    path = tmp_path / "garbled.log"
    path.write_bytes("\r\n".join(_synthetic_lines()).encode() + b"\r\nATT, \xff\xfe\x00, 1\r\n\x00\x01\x02\r\n")
    with pytest.raises(InsufficientLogError, match="5 malformed lines skipped"):
        read_log(path)


def test_the_refusal_is_a_named_flight_log_error():
    assert issubclass(InsufficientLogError, MissingStreamError) and issubclass(InsufficientLogError, FlightLogError)


# ------------------------------------------------------------------ the real ArduCopter 3.0.1 helicopter log
def test_real_tradheli_log_is_recognised_and_refused_in_one_line():
    path = _tradheli()
    assert detect_format(path) == "ardupilot-dataflash-text"
    with pytest.raises(InsufficientLogError) as info:
        read_log(path)
    msg = str(info.value)
    print(f"\n{msg}")
    assert "\n" not in msg and msg.startswith(f"{path}: ArduPilot text DataFlash log (ArduCopter V3.0.1, APM 2, "
                                              "traditional helicopter (H_* swash parameters), 123 s logged in 2 "
                                              "stretches, timed by GPS.Time)")
    for part in ("attitude and desired attitude (ATT) at 9.8 Hz", "CTUN at 10 Hz", "312 parameters",
                 "no gyro rates (IMU)", "no servo outputs (RCOU)", "its 9.8 Hz attitude is too coarse to identify "
                 "rate dynamics", "at 50 Hz or more"):
        assert part in msg, f"{part!r} not in {msg!r}"
    assert "malformed" not in msg  # every line of the real log is a record


def test_real_tradheli_log_is_listed_with_its_description():
    path = _tradheli()
    (row,) = list_logs(path)
    assert row["format"] == "ardupilot-dataflash-text" and row["firmware"] == "ArduCopter V3.0.1"
    assert_allclose(row["duration_s"], 123.2, atol=0.05)  # GPS time 308906.4-308990.6 s and 309034.6-309073.6 s
    assert row["attitude"] is True and row["airborne_s"] is None
    assert row["status"].startswith("InsufficientLogError: ArduPilot text DataFlash log (ArduCopter V3.0.1")


def test_cli_refuses_the_real_tradheli_log_in_one_line_exit_2(tmp_path, capsys):
    from heli_cli.main import main

    path = _tradheli()
    assert main(["import", str(path), "--out", str(tmp_path / "f.csv"), "--quiet"]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("heli import: error: InsufficientLogError: ") and "no gyro rates (IMU)" in err[0]
    assert not captured.out and not list(tmp_path.iterdir()), "nothing is written for a refused log"


def test_cli_lists_the_real_tradheli_log(capsys):
    from heli_cli.main import main

    assert main(["import", str(_tradheli()), "--list"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].endswith("1 log") and len(out) == 3
    assert "123.2" in out[2] and "InsufficientLogError: ArduPilot text DataFlash log" in out[2]
