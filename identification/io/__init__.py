"""Readers and writers that turn files into one validated :class:`~identification.flight.Flight`.

:func:`read_log` reads any supported file, recognised by its content (not its
name): the canonical CSV, PX4 ULog, ArduPilot DataFlash ``.bin`` and
Betaflight/Rotorflight blackbox logs. The flight-controller formats need the
``logs`` extra (pyulog, pymavlink, orangebox), imported only when used.
"""

from __future__ import annotations

from pathlib import Path

from .csv_log import SERVO_COLUMNS, read_csv_flight, read_servo_csv, sticks_from_servos, write_csv_flight
from .errors import (
    DamagedLogError, InputSourceError, LogFormatError, MissingStreamError, NotAirborneError, SegmentError,
)

__all__ = [
    "read_csv_flight", "read_servo_csv", "sticks_from_servos", "write_csv_flight", "read_flight", "read_log",
    "detect_format", "LogFormatError", "DamagedLogError", "MissingStreamError", "InputSourceError",
    "NotAirborneError", "SegmentError", "FORMATS",
]

FORMATS = ("csv", "px4-ulog", "ardupilot-dataflash", "blackbox")
"""Formats :func:`read_log` recognises."""


def detect_format(path) -> str:
    """The format of a log file, from its first bytes.

    Returns
    -------
    str
        One of :data:`FORMATS`.

    Raises
    ------
    LogFormatError
        Empty, or none of the known signatures.
    FileNotFoundError
    """
    from .ardupilot import is_dataflash
    from .blackbox import is_blackbox
    from .px4 import is_ulog

    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.read(256)
    if not head:
        raise LogFormatError(f"{path}: empty file; expected a CSV, ULog, DataFlash or blackbox log")
    if is_ulog(head):
        return "px4-ulog"
    if is_dataflash(head):
        return "ardupilot-dataflash"
    if is_blackbox(head):
        return "blackbox"
    first = head.split(b"\n", 1)[0].lstrip(b"\xef\xbb\xbf").decode("ascii", "replace")
    if "," in first and "time" in [c.strip() for c in first.split(",")]:
        return "csv"
    raise LogFormatError(
        f"{path}: unknown log format (first bytes {head[:16]!r}); expected a canonical CSV (header with 'time'), "
        "a PX4 ULog, an ArduPilot DataFlash .bin or a Betaflight/Rotorflight blackbox log"
    )


def _read_csv(path, inputs, segment, calibration):
    if inputs not in (None, "sticks", "servos"):
        raise InputSourceError(f"{path}: a CSV flight holds sticks (or servo pulses), not {inputs!r} inputs")
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        header = [h.strip() for h in fh.readline().split(",")]
    if inputs == "servos" or (calibration is not None and all(c in header for c in SERVO_COLUMNS)):
        if calibration is None:
            from .raw_log import h3_120_calibration

            calibration = h3_120_calibration()
        flight = read_servo_csv(path, calibration)
    else:
        if calibration is not None:
            raise InputSourceError(f"{path}: a servo calibration was given but the CSV has no servo columns "
                                   f"{','.join(SERVO_COLUMNS)}")
        flight = read_csv_flight(path).with_metadata(input_source="sticks")
    if segment in (None, "all"):
        return flight
    if segment == "auto":
        raise SegmentError(f"{path}: segment='auto' needs a flight-controller log (throttle, vibration); a CSV "
                           "flight is used as it is: pass 'all' or T0:T1")
    from .raw_log import _parse_segment

    _, (t0, t1) = _parse_segment(segment)
    return flight.segment(t0, t1)


def read_log(path, inputs: str | None = None, segment=None, rate: float | None = None, calibration=None,
             allow_damaged: bool = False):
    """Read a flight log of any supported format into a validated :class:`~identification.flight.Flight`.

    Parameters
    ----------
    path : str or Path
        Canonical CSV, PX4 ULog, ArduPilot DataFlash ``.bin`` or Betaflight/Rotorflight blackbox log;
        the format is recognised from the content.
    inputs : {"sticks", "controller", "servos"} or None
        Input source mapped to ``lat, lon, col, ped``; None takes the format's default, the
        one closest to the bare airframe (rate-controller output for a multirotor; servos through
        eq. 67 for a helicopter that logs them, else the stabilised mixer input). Recorded in
        ``flight.metadata["input_source"]``.
    segment : "auto", "all", (t0, t1), "T0:T1" or None
        Part of the log: "auto" detects the airborne segment; "all" is the longest stretch without a
        logging gap; times are on the log's own clock [s]. None means "auto" for flight-controller logs
        and "all" for a CSV.
    rate : float, optional
        Uniform grid rate [Hz]; default the gyro stream's rate capped at 200 Hz.
    calibration : dict or path, optional
        Servo mixing ``{"G": 4x4, "U_trim": 4}`` of eq. (66) for ``inputs="servos"``; default the
        documented H3-120 mixing (:func:`identification.io.raw_log.h3_120_calibration`).
    allow_damaged : bool
        Import what decodes from a truncated or corrupt log instead of raising ``DamagedLogError``.

    Raises
    ------
    LogFormatError, DamagedLogError, MissingStreamError
        The file cannot be read as a log, is damaged, or lacks a needed stream.
    InputSourceError
        The input source does not apply (e.g. ``servos`` on a multirotor).
    NotAirborneError
        ``segment="auto"`` and the log never leaves the ground.
    SegmentError
        A segment outside the log or across a gap in its data.
    MissingDependency
        The parser of the format (extra ``logs``) is not installed.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"flight log {str(path)!r} does not exist")
    fmt = detect_format(path)
    if fmt == "csv":
        return _read_csv(path, inputs, segment, calibration)
    from .raw_log import to_flight

    if fmt == "px4-ulog":
        from .px4 import load_px4 as load
    elif fmt == "ardupilot-dataflash":
        from .ardupilot import load_ardupilot as load
    else:
        from .blackbox import load_blackbox as load
    raw = load(path, allow_damaged=allow_damaged)
    return to_flight(raw, inputs=inputs, segment=segment, rate=rate, calibration=calibration)


def read_flight(path):
    """Read a flight log of any supported format with the defaults of :func:`read_log`."""
    return read_log(path)
