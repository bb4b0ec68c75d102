"""Readers and writers that turn files into one validated :class:`~identification.flight.Flight`.

:func:`read_log` reads any supported file, recognised by its content (not its
name): the canonical CSV, PX4 ULog, ArduPilot DataFlash ``.bin`` and
Betaflight/Rotorflight blackbox logs. An old ArduPilot *text* DataFlash log is
recognised and refused with :class:`InsufficientLogError`, whose one line says what
it holds and what is missing (:mod:`.dataflash_text`). The flight-controller formats need the
``logs`` extra (pyulog, pymavlink, orangebox), imported only when used. What each
format must contain, and how padding and several logs in one file are handled, is
listed in :mod:`identification.io.container`.

Logs are read as they come from real loggers: a last message cut short (power
lost while logging) is dropped, 0xFF/0x00 padding is skipped, a clock that restarts
is continued, a log without attitude gets its attitude reconstructed from the
rates; each of these is recorded in ``flight.metadata["import_warnings"]`` (one
line each). Damage in the *middle* of a log is refused unless ``allow_damaged``.
Every refusal is an error of :mod:`identification.io.errors` (a
:class:`~identification.errors.FlightLogError`) or
:class:`~identification.errors.MissingDependency`; a parser's own exception never
escapes.
"""

from __future__ import annotations

from pathlib import Path

from .csv_log import (
    SERVO_COLUMNS, csv_header, read_csv_flight, read_servo_csv, sticks_from_servos, write_csv_flight,
)
from .errors import (
    DamagedLogError, InputSourceError, InsufficientLogError, LogFormatError, LogSelectionError, MissingStreamError,
    NotAirborneError, SegmentError,
)

__all__ = [
    "read_csv_flight", "read_servo_csv", "sticks_from_servos", "write_csv_flight", "read_flight", "read_log",
    "read_log_runs", "detect_format", "list_logs", "LogFormatError", "DamagedLogError", "MissingStreamError",
    "InputSourceError", "LogSelectionError", "NotAirborneError", "SegmentError", "InsufficientLogError", "FORMATS",
    "meta_path",
]

FORMATS = ("csv", "px4-ulog", "ardupilot-dataflash", "ardupilot-dataflash-text", "blackbox")
"""Formats :func:`read_log` recognises (a text DataFlash log only to describe and refuse it)."""


def detect_format(path) -> str:
    """The format of a log file, from its content (robust to 0xFF/0x00 padding; :mod:`.container`).

    Returns
    -------
    str
        One of :data:`FORMATS`.

    Raises
    ------
    LogFormatError
        Empty, only padding, or none of the known signatures.
    FileNotFoundError
    """
    from .container import locate

    return locate(path).format


def _read_csv(path, inputs, segment, calibration):
    if inputs not in (None, "sticks", "servos"):
        raise InputSourceError(f"{path}: a CSV flight holds sticks (or servo pulses), not {inputs!r} inputs")
    if segment in ("auto", "each"):
        raise SegmentError(f"{path}: segment={segment!r} needs a flight-controller log (throttle, vibration); a CSV "
                           "flight is used as it is: pass 'all' or T0:T1")
    from .raw_log import _parse_segment

    span = None if segment is None else "all" if segment == "all" else _parse_segment(segment)[1]
    header, _ = csv_header(path)
    if inputs == "servos" or (calibration is not None and all(c in header for c in SERVO_COLUMNS)):
        if calibration is None:
            from .raw_log import h3_120_calibration

            calibration = h3_120_calibration()
        flight = read_servo_csv(path, calibration, span)
    else:
        if calibration is not None:
            raise InputSourceError(f"{path}: a servo calibration was given but the CSV has no servo columns "
                                   f"{','.join(SERVO_COLUMNS)}")
        flight = read_csv_flight(path, span).with_metadata(input_source="sticks", **_imported_from(path))
    if span is None or span == "all":  # (where the logging stopped, "all" read the longest stretch)
        return flight
    return flight.segment(*span)


def meta_path(csv_path) -> Path:
    """Where ``heli import`` writes the metadata of the CSV it writes: ``flight.csv`` -> ``flight.meta.json``."""
    csv_path = Path(csv_path)
    return csv_path.with_name(csv_path.stem + ".meta.json")


def _imported_from(csv_path) -> dict:
    """``{"imported_from": {"format", "input_source"[, "loop_rate_hz", "gyro_filter_hz"]}}`` when ``heli import``
    wrote this CSV from a log (its ``.meta.json`` beside it names the log's format), else ``{}``: advice to import the
    log again with another input source (``heli import --inputs``) is given only for such a flight, where it can change the
    outcome; the flight controller's loop rate, where the log stated it, tells whether its commands moved between
    the samples fitted (:func:`identification.validation.fit_warnings.controller_loop_warning`), and its gyro
    filter's corner what the closed-loop check's world reads the gyro through
    (:func:`identification.validation.fit_warnings.gyro_filter`)."""
    import json

    try:
        meta = json.loads(meta_path(csv_path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(meta, dict) or not isinstance(meta.get("format"), str):
        return {}
    stated = {k: float(meta[k]) for k in ("loop_rate_hz", "gyro_filter_hz")
              if isinstance(meta.get(k), (int, float)) and meta[k] > 0}
    return {"imported_from": {"format": meta["format"], "input_source": str(meta.get("input_source", "")), **stated}}


def _check_regular_file(path: Path) -> None:
    """Refuse a folder, or a pipe or device that reading would block on for ever (``LogFormatError``)."""
    if path.exists() and not path.is_file():
        kind = "a folder" if path.is_dir() else "not a regular file (a pipe, socket or device)"
        raise LogFormatError(f"{path}: {kind}; expected a flight log file")


def read_log(path, inputs: str | None = None, segment=None, rate: float | None = None, calibration=None,
             allow_damaged: bool = False, log: int | None = None):
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
        Import what decodes from a log damaged in the middle instead of raising ``DamagedLogError``
        (a cut last message never needs it).
    log : int, optional
        Which log of a blackbox file holding several (from 1, as :func:`list_logs` numbers them);
        default the one with the longest airborne segment. Other formats hold one log.

    Raises
    ------
    LogFormatError, DamagedLogError, MissingStreamError
        The file cannot be read as a log, is damaged in the middle, or lacks a needed stream.
    InsufficientLogError
        An ArduPilot text DataFlash log: the message says what it holds and what identification needs.
    LogSelectionError
        ``log`` names no log of the file.
    InputSourceError
        The input source does not apply (e.g. ``servos`` on a multirotor).
    NotAirborneError
        ``segment="auto"`` and the log never leaves the ground.
    SegmentError
        A segment outside the log or across a gap in its data.
    UnitError
        Time, rates, attitude or sticks in another unit (:func:`~identification.flight.make_flight`).
    MissingDependency
        The parser of the format (extra ``logs``) is not installed.
    """
    path, fmt = _located(path, log)
    if fmt == "csv":
        return _read_csv(path, inputs, segment, calibration)
    from .raw_log import to_flight

    return to_flight(_load_raw(path, fmt, allow_damaged, log), inputs=inputs, segment=segment, rate=rate,
                     calibration=calibration)


def read_log_runs(path, inputs: str | None = None, rate: float | None = None, calibration=None,
                  allow_damaged: bool = False, log: int | None = None) -> list:
    """Every airborne run of a flight-controller log as a validated :class:`~identification.flight.Flight`
    of its own, in time order (:func:`~identification.io.raw_log.to_flights`; ``heli import --segment
    each``): :func:`read_log` with ``segment="auto"`` keeps the longest run alone. An estimator's ``fit``
    and ``heli identify`` (the runs' CSVs) take the flights together. Arguments and errors as :func:`read_log`'s;
    a CSV flight raises ``SegmentError`` (it has no throttle or vibration to find runs by)."""
    path, fmt = _located(path, log)
    if fmt == "csv":
        raise SegmentError(f"{path}: segment 'each' needs a flight-controller log (throttle, vibration) to find "
                           "the airborne runs; a CSV flight is used as it is: pass 'all' or T0:T1")
    from .raw_log import to_flights

    return to_flights(_load_raw(path, fmt, allow_damaged, log), inputs=inputs, rate=rate, calibration=calibration)


def _located(path, log) -> tuple[Path, str]:
    """``path`` as a Path and its format, after checking it is a readable file and ``log`` can exist in it."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"flight log {str(path)!r} does not exist")
    _check_regular_file(path)
    from .container import locate

    fmt = locate(path).format
    if log is not None and fmt != "blackbox" and int(log) != 1:
        raise LogSelectionError(f"{path}: a {fmt} file holds one log; there is no log {log} "
                                "(only blackbox flash dumps hold several)")
    return path, fmt


def _load_raw(path: Path, fmt: str, allow_damaged: bool, log: int | None = None):
    """The decoded :class:`~identification.io.raw_log.RawLog` of a flight-controller log of format ``fmt`` (an
    ArduPilot text log raises ``InsufficientLogError``, saying what it holds)."""
    if fmt == "ardupilot-dataflash-text":
        from .dataflash_text import load_dataflash_text

        load_dataflash_text(path)  # raises InsufficientLogError
    if fmt == "px4-ulog":
        from .px4 import load_px4

        return load_px4(path, allow_damaged=allow_damaged)
    if fmt == "ardupilot-dataflash":
        from .ardupilot import load_ardupilot

        return load_ardupilot(path, allow_damaged=allow_damaged)
    from .blackbox import load_blackbox

    return load_blackbox(path, allow_damaged=allow_damaged, log=log)


def list_logs(path, allow_damaged: bool = False, progress=None) -> list[dict]:
    """The logs a file holds, as ``heli import --list`` shows them.

    Parameters
    ----------
    path : str or Path
        A log file of any supported format.
    allow_damaged : bool
        Decode what decodes of a log damaged in the middle (see :func:`read_log`).
    progress : callable or None
        Called as ``progress(done, total)`` before the first log is decoded and after each one (a blackbox
        flash dump holds several; decoding one takes up to a few seconds); None (default) shows nothing.

    Returns
    -------
    list of dict
        One per log: ``{"log": N, "format", "firmware", "start_s", "duration_s", "attitude": bool,
        "airborne_s": length of the airborne segment [s] (0 when it never flies) or None, "status":
        "ok" or why it cannot be imported}``. A blackbox flash dump lists each of its logs; other
        formats hold one.
    """
    from ..errors import FlightLogError
    from .container import locate
    from .errors import NotAirborneError

    path = Path(path)
    _check_regular_file(path)
    fmt = locate(path).format
    if fmt == "blackbox":
        from .blackbox import blackbox_log_summaries

        return [{"format": "blackbox", **row} for row in blackbox_log_summaries(path, allow_damaged,
                                                                                progress=progress)]
    if fmt == "ardupilot-dataflash-text":
        from .dataflash_text import text_log_summary

        return [{"log": 1, "format": fmt, **text_log_summary(path)}]
    row = {"log": 1, "format": fmt, "firmware": None, "start_s": None, "duration_s": None, "attitude": None,
           "airborne_s": None, "status": "ok"}
    if progress is not None:
        progress(0, 1)
    try:
        if fmt == "csv":
            whole = read_log(path, segment="all")
        else:  # decoded once, mapped twice: the whole log and its airborne segment
            from .raw_log import to_flight

            raw = _load_raw(path, fmt, allow_damaged)
            whole = to_flight(raw, segment="all")
    except FlightLogError as e:
        row["status"] = f"{type(e).__name__}: {str(e).split(': ', 1)[-1]}"
        return [row]
    finally:
        if progress is not None:
            progress(1, 1)
    row.update(firmware=whole.metadata.get("firmware"), start_s=round(float(whole.time[0]), 3),
               duration_s=round(whole.duration, 3), attitude=whole.metadata.get("attitude_source") == "measured")
    if fmt != "csv":
        try:
            row["airborne_s"] = round(to_flight(raw, segment="auto").duration, 3)
        except NotAirborneError:
            row["airborne_s"] = 0.0
        except FlightLogError as e:
            row["status"] = f"{type(e).__name__}: {str(e).split(': ', 1)[-1]}"
    return [row]


def read_flight(path):
    """Read a flight log of any supported format with the defaults of :func:`read_log`."""
    return read_log(path)
