"""ArduPilot *text* DataFlash logs (``.log``): recognised, described, and refused for identification.

Before binary ``.bin`` logs, ArduPilot logs were downloaded as text, one record a
line: a few header lines (a record count, the firmware ``ArduCopter V3.0.1``, the
free RAM, the board ``APM 2``), then ``FMT`` lines that describe each message type

.. code-block:: text

    FMT, 1, 17, ATT, cccccCC, RollIn,Roll,PitchIn,Pitch,YawIn,Yaw,NavYaw
    PARM, H_SV1_POS, -60.000000
    ATT, 0.00, 0.23, 0.00, 0.75, 0.00, 215.88, 215.88

and then the records, with their values already scaled (``c`` = centi-units written
as units) and flight modes by name. pymavlink does not read these logs: ArduCopter
3.0's records carry no time stamps, and its binary readers expect bytes.

:func:`parse_text_log` reads the records into one column array per message field,
counting what it skips (a line with the wrong number of fields or a value that is
not a number is malformed; a record without an ``FMT`` line is of an unknown type).
The log's clock, when it has none of its own, is the GPS time of week (``GPS.Time``,
ms): its intervals longer than :data:`~identification.io.resample.GAP_FACTOR` median
intervals are pauses of the logging (ArduCopter 3.0 logs only while armed).

Such a log is never imported: without body rates there is no flight to identify.
:func:`load_dataflash_text` raises :class:`~identification.io.errors.InsufficientLogError`
whose one line says what the log is, what it holds and what is missing, and
:func:`text_log_summary` gives the same for ``heli import --list``.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .ardupilot_vehicle import vehicle_of
from .errors import InsufficientLogError
from .resample import GAP_FACTOR, MIN_GAP_S

FORMAT = "ardupilot-dataflash-text"
MIN_IDENTIFY_RATE_HZ = 50.0
"""Hz: the slowest body-rate and input streams worth identifying rate dynamics from. The servo lag the
estimator profiles spans 10-200 ms, and the ArduCopter fixture's 10 Hz ``RATE`` stream fits roll and pitch
with R² < 0.05 (docs/file-formats.md); its 49 Hz ``IMU`` and ``RCOU`` streams are what imports."""
TEXT_COLUMNS = frozenset("nNZM")
"""FMT format characters whose values are text (4, 16 and 64 characters; a flight mode by name)."""
NAME = re.compile(r"^[A-Z][A-Z0-9_]{0,7}$")
"""A message name as FMT lines give them (``ATT``, ``CTUN``, ``DU32``)."""
TIME_COLUMNS = (("TimeUS", 1e-6), ("TimeMS", 1e-3))
"""Per-record time stamps of later firmware (column name, seconds per unit)."""
GPS_TIME_COLUMNS = (("Time", 1e-3), ("GMS", 1e-3), ("TimeMS", 1e-3))
"""GPS time of week in ms (ArduCopter 3.0 ``GPS.Time``; later ``GMS``)."""
BOARD = re.compile(r"^(APM\s*\d|PX4|Pixhawk|Navio|Linux)", re.IGNORECASE)
"""A header line naming the flight-controller board."""


@dataclass(frozen=True)
class MessageFormat:
    """One ``FMT`` line: a message type's number, binary length, name, format characters and field names."""

    type: int
    length: int
    name: str
    format: str
    columns: tuple


@dataclass(frozen=True)
class TextLog:
    """A text DataFlash log as read (:func:`parse_text_log`).

    Attributes
    ----------
    header : tuple of str
        The lines before the first ``FMT`` line (record count, firmware, free RAM, board).
    formats : dict
        Message name -> :class:`MessageFormat`.
    messages : dict
        Message name -> {field name -> array of the records' values (float, or str for text fields)}; every
        message also has ``"_line"``, the records' line numbers (from 1).
    params : dict
        ``PARM`` name -> value.
    texts : tuple of str
        The ``MSG`` records' texts.
    malformed : tuple of (int, str)
        Lines skipped: (line number, why).
    unknown : dict
        Record names without an ``FMT`` line -> how many records.
    """

    header: tuple
    formats: dict
    messages: dict
    params: dict
    texts: tuple
    malformed: tuple
    unknown: dict

    def count(self, name: str) -> int:
        """How many records of message ``name`` were read (0 if none)."""
        return len(self.messages[name]["_line"]) if name in self.messages else 0


@dataclass(frozen=True)
class LogClock:
    """How long a text log ran, from its time stamps or the GPS clock.

    Attributes
    ----------
    source : str
        The field timed by (``"GPS.Time"``, ``"ATT.TimeMS"``).
    duration_s : float
        Logged time [s]: the sum of the clock's intervals, pauses left out.
    stretches : int
        Runs of logging between pauses (a pause: an interval over ``GAP_FACTOR`` median intervals, or a
        clock that does not increase); a lone record between two pauses is no stretch.
    """

    source: str
    duration_s: float
    stretches: int


def parse_text_log(text: str) -> TextLog:
    """Read the records of a text DataFlash log (see the module docstring), skipping and counting bad lines.

    Parameters
    ----------
    text : str
        The whole log (any line ends).

    Returns
    -------
    TextLog
    """
    header, formats, rows, malformed, unknown = [], {}, {}, [], Counter()
    for number, line in enumerate(text.splitlines(), start=1):
        fields = [f.strip() for f in line.split(",")]
        name = fields[0]
        if name == "FMT":
            fmt = _format_of(fields)
            if fmt is None:
                malformed.append((number, "an FMT line that does not describe a message"))
            elif formats.get(fmt.name, fmt) != fmt:
                malformed.append((number, f"an FMT line redefining {fmt.name} (the first definition holds)"))
            else:
                formats[fmt.name] = fmt
        elif not formats:
            if line.strip():
                header.append(line.strip())
        elif name in formats:
            if len(fields) - 1 == len(formats[name].columns):
                rows.setdefault(name, []).append((number, fields[1:]))
            else:
                malformed.append((number, f"{name} with {len(fields) - 1} fields, its FMT names "
                                          f"{len(formats[name].columns)}"))
        elif NAME.match(name):
            unknown[name] += 1
        elif line.strip():
            malformed.append((number, "not a record"))
    messages = {}
    for name, records in rows.items():
        columns, bad = _columns(formats[name], records)
        messages[name] = columns
        malformed.extend((n, f"{name} with a value that is not a number") for n in bad)
    params = _params(messages.pop("PARM", None))
    texts = tuple(str(t) for t in messages.get("MSG", {}).get("Message", ()))
    return TextLog(header=tuple(header), formats=formats, messages=messages, params=params, texts=texts,
                   malformed=tuple(sorted(malformed)), unknown=dict(unknown))


def _format_of(fields: list) -> MessageFormat | None:
    """The :class:`MessageFormat` of an ``FMT`` line's fields, or None if they are not one."""
    if len(fields) < 5 or not NAME.match(fields[3]):
        return None
    try:
        kind, length = int(fields[1]), int(fields[2])
    except ValueError:
        return None
    columns = tuple(c for c in fields[5:] if c)  # may be fewer than the format characters (FMT's own line)
    return MessageFormat(kind, length, fields[3], fields[4], columns)


def _columns(fmt: MessageFormat, records: list) -> tuple[dict, list]:
    """One array per field of a message's records; records with a value that is not a number are dropped.

    Returns
    -------
    columns : dict
        Field name -> array (float, or str for text fields), plus ``"_line"``.
    bad : list of int
        Line numbers of the dropped records.
    """
    lines = np.array([n for n, _ in records], dtype=int)
    table = np.array([f for _, f in records], dtype=object).reshape(len(records), len(fmt.columns))
    keep = np.ones(len(records), dtype=bool)
    values = {}
    chars = fmt.format.ljust(len(fmt.columns), "Z")  # a field named beyond the format characters: kept as text
    for j, (name, char) in enumerate(zip(fmt.columns, chars)):
        if char in TEXT_COLUMNS:
            values[name] = table[:, j].astype(str)
            continue
        values[name], ok = _floats(table[:, j])
        keep &= ok
    columns = {name: v[keep] for name, v in values.items()}
    columns["_line"] = lines[keep]
    return columns, lines[~keep].tolist()


def _floats(strings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Strings as floats, and which of them are numbers (the others NaN)."""
    try:
        return strings.astype(float), np.ones(len(strings), dtype=bool)
    except ValueError:
        pass

    def number(s):
        try:
            return float(s)
        except ValueError:
            return None

    parsed = [number(s) for s in strings]  # only for a message with a bad value
    ok = np.array([v is not None for v in parsed], dtype=bool)
    return np.array([np.nan if v is None else v for v in parsed], dtype=float), ok


def _params(parm: dict | None) -> dict:
    """``PARM`` records as {name: value} (the last value of a name written twice)."""
    if not parm or "Name" not in parm or "Value" not in parm:
        return {}
    values, ok = _floats(np.asarray(parm["Value"], dtype=object))  # numbers already, unless its FMT says text
    return {str(n): float(v) for n, v, good in zip(parm["Name"], values, ok) if good}


def log_clock(log: TextLog) -> LogClock | None:
    """How long the log ran: from the most frequent message with a time stamp, else the GPS time of week.

    Returns
    -------
    LogClock or None
        None when the log has no clock at all (no time stamps, no GPS time).
    """
    def numeric(m, c):
        return c in log.messages.get(m, {}) and log.messages[m][c].dtype.kind == "f"

    stamped = [(log.count(m), m, c, s) for m in log.messages for c, s in TIME_COLUMNS if numeric(m, c)]
    if stamped:
        _, message, column, scale = max(stamped)
    else:
        found = next(((c, s) for c, s in GPS_TIME_COLUMNS if numeric("GPS", c)), None)
        if found is None:
            return None
        message, (column, scale) = "GPS", found
    t = log.messages[message][column] * scale
    t = t[np.isfinite(t) & (t > 0)]  # GPS time 0: no fix yet
    if len(t) < 2:
        return None
    dt = np.diff(t)
    forward = dt[dt > 0]
    if not len(forward):
        return None
    limit = max(GAP_FACTOR * float(np.median(forward)), MIN_GAP_S)
    running = (dt > 0) & (dt <= limit)
    starts = np.count_nonzero(running[1:] & ~running[:-1]) + int(running[0])
    return LogClock(f"{message}.{column}", float(dt[running].sum()), int(starts))


def _hz(rate: float) -> str:
    """A rate as a reader says it: "9.8 Hz", "10 Hz", "100 Hz"."""
    return f"{rate:.0f} Hz" if rate >= 9.95 else f"{rate:.1f}".rstrip("0").rstrip(".") + " Hz"


def _n(count: int, noun: str) -> str:
    """A count with its noun: "1 record", "2 records"."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


def _rate(log: TextLog, name: str, clock: LogClock | None) -> str:
    """A message's rate ("at 9.8 Hz"), or its record count ("in 34 records") when the log has no clock."""
    if clock is None or clock.duration_s <= 0:
        return f"in {_n(log.count(name), 'record')}"
    return f"at {_hz(log.count(name) / clock.duration_s)}"


def _has(log: TextLog, name: str, *fields: str) -> bool:
    return log.count(name) >= 2 and all(f in log.messages[name] for f in fields)


def _identity(log: TextLog, clock: LogClock | None) -> str:
    """What the log is: "ArduPilot text DataFlash log (ArduCopter V3.0.1, APM 2, traditional helicopter, 123 s ...)"."""
    firmware, vehicle, heli = vehicle_of(list(log.header) + list(log.texts), log.params)
    if heli and any(k.startswith(("H_SW", "H_SV", "H_COL")) for k in log.params):
        vehicle = "traditional helicopter (H_* swash parameters)"
    board = next((h for h in log.header if BOARD.match(h)), None)
    if clock is None:
        length = "length unknown: no time stamps and no GPS time"
    else:
        pauses = f" in {clock.stretches} stretches" if clock.stretches > 1 else ""
        length = f"{clock.duration_s:.0f} s logged{pauses}, timed by {clock.source}"
    parts = [firmware] + ([board] if board else []) + [vehicle, length]
    return f"ArduPilot text DataFlash log ({', '.join(parts)})"


def _holdings(log: TextLog, clock: LogClock | None) -> list[str]:
    """What the log holds, the attitude first, then its other streams at 0.5 Hz or more, then the parameters."""
    held = []
    if _has(log, "ATT", "Roll", "Pitch", "Yaw"):
        desired = " and desired attitude" if any(f in log.messages["ATT"] for f in ("RollIn", "DesRoll")) else ""
        held.append(f"attitude{desired} (ATT) {_rate(log, 'ATT', clock)}")
    others = sorted((m for m in log.messages if m not in ("ATT", "MSG")), key=log.count, reverse=True)
    if clock is not None and clock.duration_s > 0:
        others = [m for m in others if log.count(m) >= 0.5 * clock.duration_s]
    held += [f"{m} {_rate(log, m, clock)}" for m in others]
    if log.params:
        held.append(_n(len(log.params), "parameter"))
    return held or ["no records"]


def _missing(log: TextLog) -> list[str]:
    """What identification needs and the log lacks: gyro rates, an input stream, time stamps."""
    missing = []
    if not _has(log, "IMU", "GyrX", "GyrY", "GyrZ"):
        missing.append("no gyro rates (IMU)")
    if not any(_has(log, m) for m in ("RCOU", "RATE", "RCIN")):
        missing.append("no servo outputs (RCOU) nor any other input stream (RATE, RCIN)")
    if not any(c in cols for cols in log.messages.values() for c, _ in TIME_COLUMNS):
        missing.append("no time stamps of its own")
    return missing


def _verdict(log: TextLog, clock: LogClock | None, missing: list) -> str:
    """Why the log cannot be identified from, and what a log that can would hold."""
    want = (f"log gyro rates (IMU) and servo outputs (RCOU) at {MIN_IDENTIFY_RATE_HZ:.0f} Hz or more to identify "
            "this aircraft")
    count, stream = max((log.count(m), what) for m, what in (("ATT", "attitude"), ("IMU", "gyro")))
    if count and clock is not None and clock.duration_s > 0 and count / clock.duration_s < MIN_IDENTIFY_RATE_HZ:
        return f"its {_hz(count / clock.duration_s)} {stream} is too coarse to identify rate dynamics: {want}"
    if missing:
        return f"nothing to identify rate dynamics from: {want}"
    return "heli import reads the binary .bin this firmware writes, not a text export: import the .bin"


def describe(log: TextLog) -> str:
    """One line: what the log is, what it holds, what is missing, and why it cannot be identified from."""
    clock = log_clock(log)
    missing = _missing(log)
    skipped = []
    if log.malformed:
        skipped.append(f"{_n(len(log.malformed), 'malformed line')} skipped (first at line {log.malformed[0][0]})")
    if log.unknown:
        skipped.append(f"{_n(sum(log.unknown.values()), 'record')} of types without an FMT line skipped "
                       f"({', '.join(sorted(log.unknown))})")
    tail = f" ({'; '.join(skipped)})" if skipped else ""
    return (f"{_identity(log, clock)}: {', '.join(_holdings(log, clock))}"
            f"{'; ' + ', '.join(missing) if missing else ''}; {_verdict(log, clock, missing)}{tail}")


def read_text_log(path) -> TextLog:
    """Read a text DataFlash log file (bytes that are not text are replaced, and the lines holding them skipped)."""
    return parse_text_log(Path(path).read_bytes().decode("utf-8", errors="replace"))


def load_dataflash_text(path):
    """Read a text DataFlash log and refuse it, saying what it holds and what is missing.

    Raises
    ------
    InsufficientLogError
        Always: a text DataFlash log is recognised and described, never imported (module docstring).
    """
    raise InsufficientLogError(f"{path}: {describe(read_text_log(path))}")


def text_log_summary(path) -> dict:
    """The ``heli import --list`` row of a text DataFlash log (see :func:`identification.io.list_logs`)."""
    log = read_text_log(path)
    clock = log_clock(log)
    firmware, _, _ = vehicle_of(list(log.header) + list(log.texts), log.params)
    return {"firmware": firmware, "start_s": None,
            "duration_s": None if clock is None else round(clock.duration_s, 3),
            "attitude": _has(log, "ATT", "Roll", "Pitch", "Yaw"), "airborne_s": None,
            "status": f"{InsufficientLogError.__name__}: {describe(log)}"}
