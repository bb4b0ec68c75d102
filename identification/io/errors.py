"""Named errors of the log importers (:mod:`identification.io`).

All subclass :class:`~identification.errors.FlightLogError`, so ``heli`` prints
them as one line and exits with status 2, and a caller catching
``FlightLogError`` (or ``ValueError``) catches them too. Messages say what was
expected and what came.
"""

from __future__ import annotations

from ..errors import FlightLogError


class LogFormatError(FlightLogError):
    """The file is not a log of a supported format, or its parser cannot decode it (corrupt header, garbage)."""


class DamagedLogError(LogFormatError):
    """The log is damaged in the middle: some of its messages/frames are corrupt or the decoder loses them.

    A log whose *last* message is cut (logging stopped mid-write) is not damaged:
    the partial message is dropped with a note. Pass ``allow_damaged=True``
    (``heli import --allow-damaged``) to import what decodes; the flight's metadata
    then records the damage.
    """


class MissingStreamError(LogFormatError):
    """The log lacks a stream the import needs (body rates, attitude, or the chosen input source)."""


class InsufficientLogError(MissingStreamError):
    """The log is recognised and read, but what it holds cannot identify attitude dynamics.

    Raised for an ArduPilot text DataFlash log (:mod:`.dataflash_text`): the message says
    what the log is (firmware, vehicle, length), what it holds (message types and rates) and
    what is missing (gyro rates, an input stream, time stamps, a sample rate high enough).
    """


class LogSelectionError(FlightLogError):
    """``log=N`` names no log of the file (a blackbox flash dump holds several; ``heli import --list``)."""


class InputSourceError(FlightLogError):
    """The requested input source does not apply to this log (e.g. ``servos`` on a multirotor)."""


class NotAirborneError(FlightLogError):
    """``segment="auto"`` found no airborne part of the log (it never left the ground)."""


class SegmentError(FlightLogError):
    """An explicit segment ``T0:T1`` lies outside the log or spans a gap in its data."""
