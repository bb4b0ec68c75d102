"""Betaflight and Rotorflight blackbox (``.bbl``, ``.bfl``, ``LOGnnn.TXT``) import with :mod:`orangebox`.

Both firmwares write the same blackbox format (main frames at the PID-loop rate
divided by the logging denominator, units in the header); Rotorflight is the
helicopter branch of Betaflight. Fields used:

================  ==========================================  =================================================
quantity          Betaflight (multirotor)                     Rotorflight (helicopter)
================  ==========================================  =================================================
p, q, r           ``gyroADC[0..2]`` deg/s -> rad/s. Roll      the same fields and signs
                  right and nose up positive as logged; the
                  yaw axis is logged nose-LEFT positive and
                  is negated (checked against the attitude)
phi, theta, psi   ``imuQuaternion[0..2]`` (x, y, z x 32767;   ``attitude[0..2]`` decidegrees -> rad; yaw
                  w from unit norm) -> ZYX Euler angles,      negated with the yaw rate
                  yaw negated with the yaw rate
sticks            ``rcCommand[0..2]`` +-500 -> /500 = lat,    ``rcCommand[0..2]`` /500 -> lat, lon, ped
                  lon, ped (yaw negated); ``rcCommand[3]``    (yaw negated); ``rcCommand[3]`` collective
                  1000..2000 throttle -> col = (x-1500)/500   +-500 -> /500 = col
controller        PID sum ``axisP+axisI+axisD+axisF`` of      ``mixer[0..3]`` (stabilised roll, pitch, yaw,
                  each axis / 1000 (mixer units, the sum is   collective mixer inputs, +-1000 = full) / 1000
                  limited at +-500 i.e. +-0.5) -> lat, lon,   -> lat, lon, ped (negated), col
                  ped (negated); col = throttle as above
servos            not available (multirotor)                  ``servo[0..3]`` [us] as u_aile, u_aux, u_elev,
                                                              u_rudd with eq. (67) (default H3-120 mixing or
                                                              a calibration file); absent unless the log's
                                                              field mask enables servos
================  ==========================================  =================================================

Default input: ``controller`` (the PID sum / mixer input reaches the airframe;
the sticks only set the rate setpoint). Airborne detection uses the mean motor
output (Betaflight) or the throttle channel times positive collective
(Rotorflight) as power, ``accSmooth`` (Betaflight; z negated so that upright reads
-1 g as in FRD) or the gyro for vibration, and ``baroAlt`` when logged. Time is
the log's clock (us since boot) in seconds, continued across a wrap-around of the
32-bit counter or a restart (:mod:`.clock`). Older firmware (Betaflight < 4.3,
Cleanflight) logs no attitude: the flight's attitude is then reconstructed from the
rates (eqs. 25-29).

Several logs in one file
------------------------
A flash dump holds every log since the chip was erased, each starting with its own
header and padded with 0xFF to a page boundary (:mod:`.container`). ``log=N``
(``heli import --log N``, counted from 1 as the Betaflight blackbox explorer does)
picks one; the default is the log with the longest airborne segment, or the
longest log when none is airborne. :func:`blackbox_log_summaries` lists them
(``heli import --list``). Logs that hold a header but no frames (armed and
disarmed at once) are listed and skipped.

The end of a log is read as the blackbox explorer does: a log without an
end-of-log event (power lost while logging) ends in a cut frame, which is dropped
with a note; frames of a type the header defines no fields for (e.g. GPS frames)
are skipped with a note. Decoding that fails in the middle of a log, or more than
0.1 % invalid frames, is damage (``allow_damaged``).
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from heli_core.errors import require

from .clock import continue_clock, describe
from .container import BLACKBOX_MAGIC, PAD, Span, locate, span_file
from .errors import LogFormatError, LogSelectionError, MissingStreamError, NotAirborneError
from .raw_log import RawLog, captured_output, check_damage
from .resample import make_stream
from .segment import SegmentSignals

CORRUPT_FRAME_SHARE = 1e-3
"""A log with more than this share of its frames invalid (orangebox's own count) is called corrupt."""
MAX_FRAME_SIZE = 256
"""bytes: orangebox's largest frame; decoding that stops closer than this to the end is a cut last frame."""
QUAT_SCALE = 32767.0
RC_SCALE = 500.0
PID_SCALE = 1000.0
MIXER_SCALE = 1000.0


def is_blackbox(head: bytes) -> bool:
    """True if the first bytes (after any 0xFF/0x00 padding) are a blackbox header."""
    return head.lstrip(PAD).startswith(BLACKBOX_MAGIC)


def _float_bits(value) -> float:
    try:
        return struct.unpack("<f", struct.pack("<I", int(value) & 0xFFFFFFFF))[0]
    except (TypeError, ValueError, OverflowError):
        return float("nan")


class _Skipped(logging.Handler):
    """Counts orangebox's warnings about frames it skips for want of field definitions."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.undefined: dict = {}

    def emit(self, record):
        msg = record.getMessage()
        if msg.startswith("No field def found for frame type"):
            kind = msg.rsplit(":", 1)[-1].strip(" '>")
            self.undefined[kind] = self.undefined.get(kind, 0) + 1


LEADING_EVENTS = {0: 1, 14: 2}
"""Event frames a log may start with (SYNC_BEEP: one varint; LOGGING_RESUME: two), by event type."""


def _varint_end(data: bytes, pos: int) -> int | None:
    """Offset just past the unsigned variable-byte integer at ``pos`` (blackbox encoding), or None."""
    for k in range(pos, min(pos + 5, len(data))):
        if data[k] < 0x80:
            return k + 1
    return None


def _drop_leading_event(data: bytes) -> bytes:
    """Remove an event frame that directly follows the header lines (orangebox would read it as a header line).

    Betaflight writes a LOGGING_RESUME (or SYNC_BEEP) event before the first main frame of some logs;
    orangebox 0.5 then swallows the event and the first I-frame up to the next 0x0A byte as one more
    header line and starts decoding mid-frame. The event carries no flight data.
    """
    pos = 0
    while data.startswith(b"H", pos):
        nl = data.find(b"\n", pos)
        if nl < 0:
            return data
        pos = nl + 1
    if len(data) < pos + 2 or data[pos] != ord("E") or data[pos + 1] not in LEADING_EVENTS:
        return data
    end = pos + 2
    for _ in range(LEADING_EVENTS[data[pos + 1]]):
        end = _varint_end(data, end)
        if end is None:
            return data
    return data[:pos] + data[end:]


@dataclass
class _Decoded:
    """One log of a blackbox file as orangebox decoded it.

    Attributes
    ----------
    headers : dict
        The log's header lines (``H name:value``).
    columns : dict of str to ndarray (n,)
        Each main-frame field over the decoded frames.
    notes, damage : list of str
        What the import tolerated, and what it found corrupt (:class:`~identification.io.raw_log.RawLog`).
    events : list of str
        Names of the log's event frames.
    metadata : dict
        How the log ends (a cut last frame, padding, a clock restart).
    """

    headers: dict
    columns: dict
    notes: list
    damage: list
    events: list
    metadata: dict


def _decode(path: Path, span: Span, size: int, allow_damaged: bool, where: str, hint: str = "") -> _Decoded:
    """Decode one log of the file.

    ``where`` names the log in messages; ``hint`` is appended to a refusal (another log to try).
    """
    orangebox = require("orangebox", "logs")
    from orangebox.types import FrameType

    damage, notes, meta = [], [], {}
    skipped = _Skipped()
    logger = logging.getLogger("orangebox")
    logger.addHandler(skipped)
    try:
        with span_file(path, span, size, transform=_drop_leading_event) as src:
            try:
                with captured_output():
                    parser = orangebox.Parser.load(str(src))
                    names = [f.name for f in parser.reader.field_defs[FrameType.INTRA]]
            except Exception as e:  # the parser's own failure on bad bytes: any exception type
                raise LogFormatError(f"{where}: orangebox cannot read the blackbox header "
                                     f"({type(e).__name__}: {e})") from e
            n = len(names)
            rows = []
            stop = None
            try:
                with captured_output():
                    for frame in parser.frames():
                        if len(frame.data) >= n:
                            rows.append(frame.data[:n])
            except Exception as e:  # a cut or garbled frame stream ends in an arbitrary exception inside orangebox
                stop = (e, parser.reader.tell(), len(parser.reader))
    finally:
        logger.removeHandler(skipped)
    events = [ev.type.name for ev in parser.events]
    stats = parser._ctx.stats if getattr(parser, "_ctx", None) is not None else {}
    if stop is not None and "LOG_END" not in events:
        e, pos, total = stop
        if total - pos <= MAX_FRAME_SIZE:
            notes.append(f"the log has no end-of-log event and ends in a cut frame ({len(rows)} frames decoded; "
                         "logging stopped without a disarm, e.g. power lost): dropped it")
            meta["cut_last_message"] = {"frames_decoded": len(rows), "end_of_log_event": False}
        else:
            damage.append(f"decoding stopped at byte {pos} of {total} of the frame data after {len(rows)} frames "
                          f"({type(e).__name__}: {e})")
    undefined = sum(skipped.undefined.values())
    if undefined:
        kinds = ", ".join(f"{k} {v}" for k, v in sorted(skipped.undefined.items()))
        notes.append(f"skipped {undefined} frames whose type the header defines no fields for ({kinds})")
    total = max(int(stats.get("total", 0)), 1)
    invalid = int(stats.get("invalid", 0)) - undefined
    if invalid > CORRUPT_FRAME_SHARE * total:
        damage.append(f"corrupt: {invalid} of {total} frames invalid (orangebox), more than "
                      f"{CORRUPT_FRAME_SHARE:.1%}")
    check_damage(damage, where, allow_damaged, "blackbox")
    if len(rows) < 2:
        raise MissingStreamError(
            f"{where}: the blackbox log holds {len(rows)} decodable frames (header only: armed and disarmed at "
            f"once, or logging never started); expected a flight{hint}")
    data = np.array(rows, dtype=float).T
    cols = {name: data[i] for i, name in enumerate(names)}
    return _Decoded(parser.headers, cols, notes, damage, events, meta)


def blackbox_spans(path) -> tuple:
    """(located file, spans of its logs in file order) of a blackbox file; raises LogFormatError otherwise."""
    path = Path(path)
    where = locate(path)
    if where.format != "blackbox":
        with open(path, "rb") as fh:
            head = fh.read(len(BLACKBOX_MAGIC))
        raise LogFormatError(f"{path}: not a blackbox log: expected it to start with {BLACKBOX_MAGIC.decode()!r}, "
                             f"got {head[:40]!r}")
    return where, where.logs


def _decode_log(path: Path, allow_damaged: bool, index: int) -> RawLog:
    """Decode log ``index`` (from 1) of a blackbox file."""
    where, spans = blackbox_spans(path)
    if not 1 <= index <= len(spans):
        raise LogSelectionError(f"{path}: the file holds {len(spans)} blackbox log{'s' if len(spans) > 1 else ''}; "
                                f"there is no log {index} (heli import --list shows them)")
    span = spans[index - 1]
    name = f"{path} (log {index} of {len(spans)})" if len(spans) > 1 else str(path)
    hint = "; choose another log with --log N (heli import --list shows them)" if len(spans) > 1 else ""
    decoded = _decode(path, span, where.size, allow_damaged, name, hint)
    if span.padding_note():
        decoded.notes.insert(0, span.padding_note())
        decoded.metadata["padding"] = {"before": span.lead, "after": span.trail}
    return _raw_from_columns(path, name, decoded, index, len(spans))


def load_blackbox(path, allow_damaged: bool = False, log: int | None = None) -> RawLog:
    """Decode one Betaflight or Rotorflight blackbox log of a file into a ``RawLog``.

    Parameters
    ----------
    path : str or Path
    allow_damaged : bool
        Import what decodes from a log damaged in the middle.
    log : int, optional
        Which log of a file holding several (from 1); default: the one with the longest airborne
        segment, else the longest (module docstring).

    Raises
    ------
    LogFormatError
        Not a blackbox log, or orangebox cannot decode its header.
    LogSelectionError
        ``log`` is not a log of the file.
    DamagedLogError
        Decoding fails in the middle of the log, or more than 0.1 % of its frames are invalid.
    MissingStreamError
        No frames, no gyro or no time field.
    """
    path = Path(path)
    if log is not None:
        return _decode_log(path, allow_damaged, int(log))
    _, spans = blackbox_spans(path)
    if len(spans) == 1:
        return _decode_log(path, allow_damaged, 1)
    summaries = blackbox_log_summaries(path, allow_damaged=allow_damaged, keep=True)
    usable = [s for s in summaries if s["raw"] is not None]
    if not usable:
        reasons = "; ".join(f"log {s['log']}: {s['status']}" for s in summaries[:5])
        raise MissingStreamError(f"{path}: none of its {len(spans)} blackbox logs can be imported ({reasons}"
                                 f"{'; ...' if len(summaries) > 5 else ''})")
    airborne = [s for s in usable if s["airborne_s"]]
    best = max(airborne, key=lambda s: s["airborne_s"]) if airborne else max(usable, key=lambda s: s["duration_s"])
    raw = best["raw"]
    why = (f"the longest airborne segment ({best['airborne_s']:.1f} s)" if airborne else
           f"the longest log ({best['duration_s']:.1f} s; none of the {len(usable)} readable logs is airborne)")
    raw.metadata["log_choice"] = why
    raw.notes.insert(0, f"the file holds {len(spans)} logs ({len(usable)} with flight data): imported log "
                        f"{best['log']}, {why}; choose another with --log N (heli import --list shows them)")
    return raw


def blackbox_log_summaries(path, allow_damaged: bool = False, keep: bool = False, progress=None) -> list[dict]:
    """One summary per log of a blackbox file (what ``heli import --list`` shows).

    Each log is decoded and its airborne segment detected
    (:func:`~identification.io.segment.detect_airborne`).

    Returns
    -------
    list of dict
        ``{"log": N, "bytes", "firmware", "start_s", "duration_s", "frames", "attitude": bool,
        "airborne_s": length of the airborne segment [s] or None, "status": "ok" or why it cannot be
        imported}``; with ``keep``, also ``"raw"``: the decoded RawLog (None when refused).

    ``progress``, when given, is called as ``progress(done, total)`` before the first log and after each.
    """
    from ..errors import FlightLogError
    from .raw_log import to_flight

    path = Path(path)
    _, spans = blackbox_spans(path)
    out = []
    if progress is not None:
        progress(0, len(spans))
    for k, span in enumerate(spans, start=1):
        if progress is not None and k > 1:
            progress(k - 1, len(spans))
        row = {"log": k, "bytes": span.size, "firmware": None, "start_s": None, "duration_s": 0.0, "frames": 0,
               "attitude": None, "airborne_s": None, "status": "ok", "raw": None}
        try:
            raw = _decode_log(path, allow_damaged, k)
        except FlightLogError as e:
            row["status"] = f"{type(e).__name__}: {_short(e)}"
            out.append(row)
            continue
        row.update(firmware=raw.metadata.get("firmware"), start_s=round(raw.rates.time[0], 3),
                   duration_s=round(raw.rates.time[-1] - raw.rates.time[0], 3), frames=int(raw.rates.time.size),
                   attitude=raw.attitude is not None, raw=raw)
        try:
            flight = to_flight(raw, segment="auto")
            row["airborne_s"] = round(flight.duration, 3)
        except FlightLogError as e:
            row["airborne_s"] = 0.0
            if not isinstance(e, NotAirborneError):
                row["status"] = f"{type(e).__name__}: {_short(e)}"
        out.append(row)
    if progress is not None:
        progress(len(spans), len(spans))
    if not keep:
        for row in out:
            row.pop("raw")
    return out


def _short(error: Exception) -> str:
    """An error's message without the file name in front and without the advice after ';' (for a table row)."""
    text = str(error).split("): ", 1)[-1] if "(log " in str(error) else str(error).split(": ", 1)[-1]
    return text.split("; choose another log")[0]


def _cols(c: dict, field: str, k: int):
    """The columns field[0..k-1] of a decoded log, or None when any is missing."""
    names = [f"{field}[{i}]" for i in range(k)]
    return [c[n] for n in names] if all(n in c for n in names) else None


def _num(hdr: dict, key: str, default: float) -> float:
    """A numeric header value, or ``default`` when absent or not a number."""
    v = hdr.get(key, default)
    try:
        v = float(v)
    except (TypeError, ValueError):
        return default
    return v if np.isfinite(v) else default


def _loop_rate(hdr) -> dict:
    """``{"loop_rate_hz": ...}``: the PID loop's rate from the headers (the gyro loop's ``looptime`` in µs, every
    ``pid_process_denom``-th of it), or ``{}`` where they do not say."""
    looptime, denom = _num(hdr, "looptime", 0.0), _num(hdr, "pid_process_denom", 1.0)
    return {"loop_rate_hz": 1e6 / (looptime * denom)} if looptime > 0 and denom >= 1 else {}


def _raw_from_columns(path, name: str, log: _Decoded, index: int, count: int) -> RawLog:
    """Map a decoded log's columns to the canonical streams (table in the module docstring).

    ``name`` names the log in messages; ``index`` is its number (from 1) among the ``count`` logs of the file.
    """
    hdr = log.headers
    firmware = str(hdr.get("Firmware type", "Betaflight"))
    rotorflight = "rotorflight" in firmware.lower()
    t, c, rates = _clock_and_rates(name, log)
    attitude = _attitude(c, t)
    inputs, notes, unavailable = _inputs(c, t, rotorflight)
    servos = None
    if rotorflight:
        if all(f"servo[{i}]" in c for i in range(4)):
            servos = make_stream(t, _cols(c, "servo", 4), "servo[0..3]")
        else:
            unavailable["servos"] = ("this Rotorflight log has no servo[0..3] fields (enable servos in the "
                                     "blackbox field mask); use inputs='controller' (mixer inputs)")
    else:
        unavailable["servos"] = (f"{firmware} multirotor log: motor outputs are not swash-plate servos of "
                                 "eqs. 65-67; use inputs='controller' (the PID sum)")
    signals = _segment_signals(c, t, hdr, rotorflight)
    inputs = {k: v for k, v in inputs.items() if v is not None}
    if not inputs and servos is None:
        raise MissingStreamError(f"{name}: no input stream: expected rcCommand[0..3] (sticks), axisP/I/D (controller, "
                                 "Betaflight) or mixer[0..3] (controller, Rotorflight) fields")
    default = "servos" if servos is not None else ("controller" if "controller" in inputs else "sticks")
    meta = {"firmware": str(hdr.get("Firmware revision", firmware)), "craft": hdr.get("Craft name"),
            "logs_in_file": int(count), "log_index": int(index), "events": sorted(set(log.events)),
            "parser": "orangebox", **log.metadata, **_loop_rate(hdr)}
    return RawLog(path=path, format="rotorflight-blackbox" if rotorflight else "betaflight-blackbox",
                  vehicle="helicopter" if rotorflight else "multirotor", rates=rates,
                  attitude=attitude, inputs=inputs, input_notes=notes, unavailable=unavailable,
                  default_input=default, servos=servos, segment_signals=signals, metadata=meta,
                  damage=log.damage, notes=log.notes)


def _clock_and_rates(name: str, log: _Decoded):
    """(time [s] on a continued clock, the columns of the frames kept on it, the body rates).

    A restart or wrap-around of the clock is recorded in ``log.notes`` and ``log.metadata["clock"]``.
    """
    c, hdr = log.columns, log.headers
    gyro = _cols(c, "gyroADC", 3)
    if "time" not in c or gyro is None:
        raise MissingStreamError(f"{name}: the blackbox log lacks the time or gyroADC[0..2] fields")
    clock, keep, restarts = continue_clock(c["time"] * 1e-6)
    if not keep.all():
        c = {k: v[keep] for k, v in c.items()}
        gyro = _cols(c, "gyroADC", 3)
    if restarts:
        log.notes.append(describe(restarts))
        log.metadata["clock"] = restarts
    scale = _float_bits(hdr.get("gyro_scale", 1065353216))
    to_rad = np.radians(1.0) if abs(scale - 1.0) < 1e-6 else scale * 1e6  # deg/s, or Cleanflight rad/us units
    # Yaw: the blackbox logs yaw rate positive nose-left; canonical r is positive nose-right.
    sign = np.array([1.0, 1.0, -1.0])
    rates = make_stream(clock, sign[:, None] * to_rad * np.array(gyro), "gyroADC")
    if rates is None:
        raise MissingStreamError(f"{name}: fewer than 2 frames with increasing time")
    return clock, c, rates


def _attitude(c: dict, t):
    """Rotorflight's ``attitude`` or Betaflight's ``imuQuaternion`` as ZYX Euler angles (yaw negated), or None."""
    if _cols(c, "attitude", 3) is not None:
        ang = np.radians(np.array(_cols(c, "attitude", 3)) / 10.0)
        return make_stream(t, ang, "attitude (decidegrees)", angles=True)
    if _cols(c, "imuQuaternion", 3) is not None:
        x, y, z = (v / QUAT_SCALE for v in _cols(c, "imuQuaternion", 3))
        w = np.sqrt(np.clip(1.0 - x * x - y * y - z * z, 0.0, 1.0))
        roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
        pitch = np.arcsin(np.clip(2.0 * (w * y - x * z), -1.0, 1.0))
        yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        return make_stream(t, [roll, pitch, -yaw], "imuQuaternion", angles=True)
    return None


def _inputs(c: dict, t, rotorflight: bool) -> tuple[dict, dict, dict]:
    """The sticks (``rcCommand``) and the controller (mixer inputs or PID sum): (inputs, notes, unavailable)."""
    inputs, notes, unavailable = {}, {}, {}
    rc = [c.get(f"rcCommand[{i}]") for i in range(4)]
    if all(r is not None for r in rc):
        if rotorflight:
            col = rc[3] / RC_SCALE
            col_note = "rcCommand[3]/500 (collective)"
        else:
            col = (rc[3] - 1500.0) / RC_SCALE
            col_note = "(rcCommand[3]-1500)/500 (throttle)"
        inputs["sticks"] = make_stream(t, [rc[0] / RC_SCALE, rc[1] / RC_SCALE, col, -rc[2] / RC_SCALE], "rcCommand")
        notes["sticks"] = f"rcCommand[0]/500->lat, rcCommand[1]/500->lon, {col_note}->col, -rcCommand[2]/500->ped"
    else:
        unavailable["sticks"] = "no rcCommand fields"
    if rotorflight:
        if _cols(c, "mixer", 4) is not None:
            m = [v / MIXER_SCALE for v in _cols(c, "mixer", 4)]
            inputs["controller"] = make_stream(t, [m[0], m[1], m[3], -m[2]], "mixer")
            notes["controller"] = ("mixer[0]/1000->lat, mixer[1]/1000->lon, mixer[3]/1000->col (collective), "
                                   "-mixer[2]/1000->ped (stabilised mixer inputs)")
        else:
            unavailable["controller"] = "no mixer fields in this Rotorflight log"
    elif "axisP[0]" in c and "sticks" in inputs:
        def pid(axis):
            parts = [c.get(f"axis{k}[{axis}]") for k in "PIDF"]
            return sum(p for p in parts if p is not None) / PID_SCALE

        throttle = (rc[3] - 1500.0) / RC_SCALE
        inputs["controller"] = make_stream(t, [pid(0), pid(1), throttle, -pid(2)], "PID sum")
        notes["controller"] = ("(axisP+axisI+axisD+axisF)/1000 per axis -> lat, lon, -yaw -> ped "
                               "(mixer units, limit +-0.5); col = (rcCommand[3]-1500)/500 (throttle)")
    else:
        unavailable["controller"] = "no axisP/I/D fields"
    return inputs, notes, unavailable


def _segment_signals(c: dict, t, hdr: dict, rotorflight: bool) -> SegmentSignals:
    """What the airborne detector reads: power (throttle x collective, or mean motor output), accelerometer,
    barometric height."""
    motors = [c[k] for k in (f"motor[{i}]" for i in range(8)) if k in c]
    power, power_name = None, "throttle"
    throttle, collective = c.get("rcCommand[4]"), c.get("rcCommand[3]")
    if rotorflight:
        if throttle is not None and collective is not None:
            # Lift needs both a spooled rotor (throttle) and positive collective.
            power = make_stream(t, np.clip(throttle / 1000.0, 0, 1) * np.clip(collective / RC_SCALE, 0, 1),
                                "throttle x positive collective")
            power_name = "throttle x positive collective"
    elif motors:
        bounds = hdr.get("motorOutput")
        lo, hi = (float(bounds[0]), float(bounds[1])) if (
            isinstance(bounds, list) and len(bounds) >= 2 and all(isinstance(b, (int, float)) for b in bounds[:2])
        ) else (0.0, 0.0)
        if not hi > lo:
            lo, hi = float(np.min(motors)), float(np.max(motors))
        power = make_stream(t, (np.mean(motors, axis=0) - lo) / max(hi - lo, 1.0), "mean motor output")
        power_name = "mean motor output"
    accel = None
    acc = _cols(c, "accSmooth", 3)
    if acc is not None:
        one_g = _num(hdr, "acc_1G", 2048.0) or 2048.0
        # Betaflight reads +1 g on z when upright; negated to FRD (upright = -g) like PX4 and ArduPilot.
        accel = make_stream(t, 9.80665 / one_g * np.array(acc) * np.array([[1.0], [1.0], [-1.0]]),
                            "accSmooth (z negated)")
    altitude = make_stream(t, c["baroAlt"] / 100.0, "baroAlt") if "baroAlt" in c else None
    return SegmentSignals(power=power, accel=accel, altitude=altitude, power_name=power_name)
