"""Where a log lies inside a file: format signatures, padding, and several logs in one file.

A file is recognised by its content, never by its name. Real files hold more than
the log: flash chips are erased to ``0xFF`` (a Cleanflight/Betaflight flash dump
starts and ends with erased bytes, and pads every log to a page boundary), some
tools pre-allocate files with ``0x00``, and a blackbox flash dump holds every log
recorded since the chip was erased. :func:`locate` finds the log(s) and the padding;
:func:`span_file` hands a parser exactly one log's bytes.

What each format must contain
-----------------------------
=========================  =================================================================================
format                     what :func:`locate` and the loaders need
=========================  =================================================================================
canonical CSV              A header line naming ``time`` and ``p, q, r, lat, lon, col, ped`` (``phi, theta,
                           psi`` optional), comma separated (or by ``;``, a decimal comma allowed, or tabs),
                           then numbers or empty fields: time [s], rates [rad/s],
                           angles [rad], sticks in [-1, 1]. Or the servo columns ``u_aile, u_aux, u_elev,
                           u_rudd`` [us] instead of the sticks (``--inputs servos``).
PX4 ULog (``.ulg``)        The bytes ``ULog`` 0x01 0x12 0x35 at the start (after any padding); topic
                           ``vehicle_angular_velocity`` or ``sensor_combined`` (body rates); for inputs
                           ``actuator_controls_0`` or ``vehicle_torque_setpoint`` + ``vehicle_thrust_setpoint``
                           (controller) or ``manual_control_setpoint`` (sticks). ``vehicle_attitude`` is
                           used when present.
ArduPilot DataFlash        The bytes 0xA3 0x95 0x80 (an FMT message) at the start; ``IMU`` messages
(``.bin``)                 (GyrX/Y/Z); for inputs ``RATE`` (controller), ``RCIN`` + the ``RCMAP_*``/``RC<n>_*``
                           parameters (sticks) or ``RCOU`` on a helicopter (servos). ``ATT`` is used when
                           present.
ArduPilot text DataFlash   A line ``FMT, 128, <length>, FMT, ...`` (the format record describing itself)
(``.log``, ArduCopter      within the first :data:`DF_TEXT_HEAD` bytes, after a few header lines (firmware,
<= 3.0)                    board). Recognised and described, never imported (:mod:`.dataflash_text`).
Betaflight / Rotorflight   ``H Product:Blackbox flight data recorder`` at the start of each log (after any
blackbox (``.bbl``,        padding); the header's field definitions; main-frame fields ``time`` and
``.bfl``, ``LOGnnn.TXT``)  ``gyroADC[0..2]``; for inputs ``axisP/I/D[0..2]`` (controller, Betaflight),
                           ``mixer[0..3]`` (Rotorflight) or ``rcCommand[0..3]`` (sticks).
                           ``imuQuaternion[0..2]`` or ``attitude[0..2]`` is used when present.
=========================  =================================================================================

Attitude is optional in every format: without it the flight's attitude is
reconstructed from the rates (eqs. 25-29) and the metadata says so.

Padding
-------
Any run of ``0xFF``/``0x00`` bytes before a format's signature is skipped. A run of
at least :data:`PAD_MIN` such bytes at the end of the file (or of one blackbox log,
before the next log's header) is padding and is cut off before the parser sees it;
a shorter run is left to the format's own end-of-log analysis (a message that
happens to end in zero bytes is not padding). Padding is recorded in the metadata,
never treated as damage.
"""

from __future__ import annotations

import contextlib
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path

from .errors import LogFormatError

ULOG_MAGIC = b"ULog\x01\x12\x35"
"""A ULog file starts with these 7 bytes (then the version byte and the start timestamp)."""
DF_HEAD = b"\xa3\x95\x80"
"""A DataFlash log starts with the header bytes 0xA3 0x95 and the FMT message type 0x80."""
BLACKBOX_MAGIC = b"H Product:Blackbox flight data recorder"
"""Every blackbox log (also each one of several in a flash dump) starts with this header line."""
DF_TEXT_FMT = re.compile(rb"^FMT,[ \t]*128,[ \t]*\d+,[ \t]*FMT,", re.MULTILINE)
"""A text DataFlash log: the line of the FMT record that describes FMT itself (type 128)."""
DF_TEXT_HEAD = 4096
"""bytes: a text DataFlash log's FMT line for FMT lies within this many bytes of its start (header lines first)."""
SIGNATURES = {"px4-ulog": ULOG_MAGIC, "ardupilot-dataflash": DF_HEAD, "blackbox": BLACKBOX_MAGIC}
PAD = b"\xff\x00"
"""Bytes that erased flash (0xFF) or a pre-allocated file (0x00) is filled with."""
PAD_MIN = 64
"""A trailing run of at least this many pad bytes is padding; a shorter one may be the end of a message."""


@dataclass(frozen=True)
class Span:
    """Where one log lies in a file.

    Attributes
    ----------
    start, stop : int
        Byte range [start, stop) of the log, padding excluded.
    lead, trail : int
        Pad bytes (0xFF/0x00) before ``start`` and after ``stop`` that belong to this log's stretch.
    """

    start: int
    stop: int
    lead: int = 0
    trail: int = 0

    @property
    def size(self) -> int:
        return self.stop - self.start

    def padding_note(self) -> str | None:
        """One line describing the padding around the log, or None without padding."""
        parts = []
        if self.lead:
            parts.append(f"{self.lead} bytes before the log")
        if self.trail:
            parts.append(f"{self.trail} bytes after it" if self.lead else f"{self.trail} bytes after the log")
        return (f"skipped 0xFF/0x00 padding (erased flash or a pre-allocated file): {' and '.join(parts)}"
                if parts else None)


@dataclass(frozen=True)
class Located:
    """A file's format and the log(s) inside it (:func:`locate`).

    Attributes
    ----------
    format : str
        ``"csv"``, ``"px4-ulog"``, ``"ardupilot-dataflash"``, ``"ardupilot-dataflash-text"`` or ``"blackbox"``.
    size : int
        File size [bytes].
    logs : tuple of Span
        One span, or one per blackbox log of a flash dump (in file order; ``--log N`` counts from 1).
    """

    format: str
    size: int
    logs: tuple


def _trail_pad(data: bytes, start: int, stop: int) -> int:
    """Length of the run of pad bytes ending at ``stop`` (within [start, stop)), if it is at least PAD_MIN."""
    run = (stop - start) - len(data[start:stop].rstrip(PAD))
    return run if run >= PAD_MIN else 0


def _blackbox_logs(data: bytes, start: int, stop: int) -> tuple:
    """Split a blackbox file at each log's header line; each log's trailing padding is cut off."""
    heads = []
    i = data.find(BLACKBOX_MAGIC, start, stop)
    while i >= 0:
        heads.append(i)
        i = data.find(BLACKBOX_MAGIC, i + len(BLACKBOX_MAGIC), stop)
    bounds = heads + [stop]
    logs = []
    for k, a in enumerate(heads):
        b = bounds[k + 1]
        pad = _trail_pad(data, a, b)
        logs.append(Span(a, b - pad, trail=pad))
    return tuple(logs)


def locate_bytes(data: bytes, name: str = "file") -> Located:
    """:func:`locate` on bytes already read (``name`` appears in messages)."""
    size = len(data)
    if not size:
        raise LogFormatError(f"{name}: empty file; expected a CSV, ULog, DataFlash or blackbox log")
    lead = size - len(data.lstrip(PAD))
    if lead == size:
        raise LogFormatError(f"{name}: the file holds only 0xFF/0x00 bytes ({size} bytes: erased flash or an "
                             "empty pre-allocated file); there is no log in it")
    fmt = next((f for f, magic in SIGNATURES.items() if data.startswith(magic, lead)), None)
    if fmt is None and DF_TEXT_FMT.search(data, lead, lead + DF_TEXT_HEAD):
        fmt = "ardupilot-dataflash-text"
    if fmt is None:
        first = data[lead:].split(b"\n", 1)[0].lstrip(b"\xef\xbb\xbf").decode("ascii", "replace")
        if not lead and any(d in first and "time" in [c.strip().lower() for c in first.split(d)] for d in ",;\t"):
            return Located("csv", size, (Span(0, size),))
        after = f" after {lead} bytes of 0xFF/0x00 padding" if lead else ""
        raise LogFormatError(
            f"{name}: unknown log format (first bytes{after} {data[lead:lead + 16]!r}); expected a canonical CSV "
            "(header with 'time'), a PX4 ULog, an ArduPilot DataFlash .bin or text .log, or a Betaflight/Rotorflight "
            "blackbox log"
        )
    trail = _trail_pad(data, lead, size)
    stop = size - trail
    if fmt == "blackbox":
        logs = list(_blackbox_logs(data, lead, stop))
        logs[0] = Span(logs[0].start, logs[0].stop, lead, logs[0].trail)
        logs[-1] = Span(logs[-1].start, logs[-1].stop, logs[-1].lead, logs[-1].trail + trail)
        return Located(fmt, size, tuple(logs))
    return Located(fmt, size, (Span(lead, stop, lead, trail),))


def locate(path) -> Located:
    """The format of a file and where its log(s) lie, from the content (see the module docstring).

    Raises
    ------
    LogFormatError
        Empty, only padding, or none of the known signatures.
    FileNotFoundError
    """
    path = Path(path)
    return locate_bytes(path.read_bytes(), str(path))


@contextlib.contextmanager
def span_file(path, span: Span, size: int, transform=None):
    """Yield a path holding exactly the bytes of ``span``: ``path`` itself when the span is the whole file.

    Parsers that only read files (pymavlink, orangebox) get a temporary copy named like the original,
    removed on exit. ``transform`` (bytes -> bytes), if given, rewrites the span's bytes for the parser.
    """
    path = Path(path)
    with open(path, "rb") as fh:
        fh.seek(span.start)
        data = fh.read(span.size)
    if transform is not None:
        data = transform(data)
    if span.start == 0 and span.stop == size and len(data) == span.size:
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="heli-log-") as tmp:
        copy = Path(tmp) / path.name
        copy.write_bytes(data)
        yield copy
