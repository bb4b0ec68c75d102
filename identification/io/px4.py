"""PX4 ULog (``.ulg``) import with :mod:`pyulog`.

Streams used (topic.field; all PX4 topics are in the body FRD / world NED frames)

===============  ==========================================  ==================================================
quantity         topic (fallback)                            units, signs
===============  ==========================================  ==================================================
p, q, r          ``vehicle_angular_velocity.xyz[0..2]``      rad/s, FRD: roll right, nose up, nose right
                 (``sensor_combined.gyro_rad[0..2]``)        positive -- the canonical signs as they come
phi, theta, psi  ``vehicle_attitude.q[0..3]``                quaternion (w, x, y, z) -> ZYX Euler angles, rad
sticks           ``manual_control_setpoint``                 ``y``/``roll`` -> lat; ``-x``/``-pitch`` -> lon
                                                             (stick forward is nose down); ``r``/``yaw`` -> ped;
                                                             throttle ``z`` 0..1 (or ``throttle`` -1..1) -> col
controller       ``actuator_controls_0.control[0..3]``       roll/pitch/yaw torque demand -1..1 -> lat/lon/ped;
                 (``vehicle_torque_setpoint.xyz`` and        thrust 0..1 -> col = 2*thrust - 1
                 ``vehicle_thrust_setpoint.xyz[2]``)
servos           --                                          not provided: PX4 multirotor mixers have no swash
===============  ==========================================  ==================================================

Airborne detection uses the thrust demand (power), ``sensor_combined``
accelerometer (vibration), ``vehicle_local_position.z`` (height) and
``actuator_armed.armed`` (to say so when the vehicle was never armed). Topics are
read from instance 0 and named with it in the metadata and in messages. Time is
the log's own clock (``timestamp``, us since boot) in seconds.

The end of the file is read as PX4 Flight Review does: the message chain is walked;
a last message cut short (logging stopped mid-write) is dropped with a note, and
0xFF/0x00 padding after the last message is skipped. A chain that breaks in the
middle, or data pyulog flags as corrupt, is damage (``allow_damaged``).
"""

from __future__ import annotations

import io
import struct
from pathlib import Path

import numpy as np

from heli_core.errors import require
from heli_core.quaternion import euler_from_quaternion

from .container import PAD, ULOG_MAGIC, locate
from .errors import LogFormatError, MissingStreamError
from .raw_log import RawLog, captured_output, check_damage
from .resample import make_stream
from .segment import SegmentSignals

MAV_TYPE_HELICOPTER = 4
ULOG_HEADER_SIZE = 16
ULOG_MESSAGE_TYPES = frozenset(b"BFIMPQARDLCSO")
"""Message types of the ULog specification (flag bits, format, info, info multiple, parameter, parameter
default, add/remove logged message, data, logging, tagged logging, sync, dropout)."""
TAIL_GARBAGE_MAX = 528
"""bytes: unreadable bytes at the very end (a cut sector) are dropped with a note; more is damage."""


def is_ulog(head: bytes) -> bool:
    """True if the first bytes (after any 0xFF/0x00 padding) are a ULog file header."""
    return head.lstrip(PAD).startswith(ULOG_MAGIC)


def _appended_offsets(data: bytes) -> list[int]:
    """Offsets of appended data from the flag-bits message, if the log declares any (ULog spec)."""
    off = ULOG_HEADER_SIZE
    if len(data) < off + 3 + 40 or data[off + 2] != ord("B"):
        return []
    incompat = data[off + 3 + 8]
    if not incompat & 0x1:
        return []
    return sorted(o for o in struct.unpack_from("<3Q", data, off + 3 + 16) if 0 < o <= len(data))


DATA_SECTION_TYPES = frozenset(b"ALC")
"""pyulog's definitions section ends at the first of these (add logged message, logging, tagged logging)."""
DEFINITION_TYPES = frozenset(b"BFIMPQ")
PYULOG_CORRUPT_SIZE = 10000
"""pyulog calls a message of unknown type corrupt when its size is 0 or above this (or its type 0)."""
RESYNC_CHAIN = 4
"""Consecutive sound message headers that mark where the log resumes after corrupt bytes."""


def _definitions_end(data: bytes, name: str) -> int:
    """Walk the definitions section as pyulog does; return the offset of its first logged-data message.

    pyulog's definitions reader advances byte by byte past a corrupt header and loops forever when that
    reaches the end of the file, so a log whose definitions are cut or corrupt is refused here first.
    """
    n, off = len(data), ULOG_HEADER_SIZE
    unpack = struct.Struct("<HB").unpack_from
    while off + 3 <= n:
        size, kind = unpack(data, off)
        if kind in DATA_SECTION_TYPES:
            return off
        if kind not in DEFINITION_TYPES and (kind == 0 or size == 0 or size > PYULOG_CORRUPT_SIZE):
            break
        off += 3 + size
    raise LogFormatError(
        f"{name}: the ULog's definitions section (formats, parameters) is cut or corrupt at byte {min(off, n)} of "
        f"{n}, before any logged data; a log needs it whole (allow_damaged cannot help)")


def _sound(data: bytes, off: int, count: int) -> bool:
    """True if ``count`` consecutive headers of known types, each fitting in the data, start at ``off``."""
    n = len(data)
    for _ in range(count):
        if off + 3 > n or data[off + 2] not in ULOG_MESSAGE_TYPES:
            return False
        off += 3 + (data[off] | data[off + 1] << 8)
        if off > n:
            return False
    return True


def _resync(data: bytes, start: int) -> int | None:
    """The first offset after ``start`` where a sound chain of messages begins, or None."""
    for off in range(start + 1, len(data) - 3):
        if data[off + 2] in ULOG_MESSAGE_TYPES and _sound(data, off, RESYNC_CHAIN):
            return off
    return None


def _walk(data: bytes, off: int, appended: list) -> tuple[int, str]:
    """Walk the data section from ``off``: (end of the last sound message, why the walk ended there).

    ``why`` is ``"end"`` (exactly at the end of the data), ``"cut"`` (the next message runs past the end)
    , ``"unknown"`` (the next header is no ULog message: padding or garbage) or ``"appended"`` (the next
    message runs into the offset of appended data). A message of a type newer than
    :data:`ULOG_MESSAGE_TYPES` is stepped over when a known header follows it, as pyulog steps over it.
    Appended data (ULog flag bits) is followed as pyulog follows it: up to the offset, then from it.
    """
    n = len(data)
    unpack = struct.Struct("<HB").unpack_from
    while off + 3 <= n:
        size, kind = unpack(data, off)
        nxt = off + 3 + size
        if kind not in ULOG_MESSAGE_TYPES and not (
                kind and 0 < size <= PYULOG_CORRUPT_SIZE and nxt <= n
                and (nxt == n or (nxt + 3 <= n and data[nxt + 2] in ULOG_MESSAGE_TYPES))):
            return off, "unknown"
        if appended and nxt > appended[0] >= off:
            return off, "appended"
        if nxt > n:
            return off, "cut"
        off = nxt
    return off, ("end" if off == n else "cut")


def _sound_bytes(data: bytes, name: str, allow_damaged: bool) -> tuple[bytes, list, list, dict]:
    """The log's bytes as pyulog should see them, and what was found: (bytes, notes, damage, metadata).

    A cut last message or trailing padding is dropped with a note. Bytes in the middle that are not ULog
    messages are damage; with ``allow_damaged`` they are cut out (the chain resumes at the next sound
    stretch), so that pyulog never has to scan them byte by byte.
    """
    appended = _appended_offsets(data)
    start = _definitions_end(data, name)
    pieces, notes, damage, meta = [(0, start)], [], [], {}
    off = start
    while True:
        end, why = _walk(data, off, appended)
        pieces.append((off, end))
        if why == "appended":
            off = appended.pop(0)
            continue
        rest = data[end:]
        if why == "end" or not rest:
            break
        if not rest.strip(PAD):
            notes.append(f"skipped {len(rest)} bytes of 0xFF/0x00 padding after the last message")
            meta["padding_after_log"] = len(rest)
            break
        if why == "cut" and len(rest) <= 3 + 0xFFFF:
            size = struct.unpack_from("<H", data, end)[0] + 3 if len(rest) >= 2 else None
            whole = f" of a {size}-byte message" if size else ""
            notes.append(f"the log ends {len(rest)} bytes into its last message{whole} (logging stopped "
                         "mid-write, e.g. power lost): dropped it")
            meta["cut_last_message"] = {"bytes_present": len(rest), "message_bytes": size}
            break
        if len(rest) <= TAIL_GARBAGE_MAX:
            notes.append(f"dropped {len(rest)} unreadable bytes after the last complete message")
            meta["unreadable_tail_bytes"] = len(rest)
            break
        resume = _resync(data, end) if allow_damaged else None
        damage.append(f"bytes {end}..{resume if resume is not None else len(data)} of {len(data)} are not ULog "
                      f"messages{' (skipped)' if resume is not None else ''}")
        if resume is None:
            break
        off = resume
    if len(pieces) == 2 and pieces[1] == (start, len(data)):
        return data, notes, damage, meta
    out = bytearray(b"".join(data[a:b] for a, b in pieces))
    if _appended_offsets(data):  # the pieces are in reading order now: nothing is appended any more
        out[ULOG_HEADER_SIZE + 3 + 8] &= 0xFE
    return bytes(out), notes, damage, meta


def _topic(ulog, name: str, multi: int = 0):
    """(data dict, a function naming one of its fields with the instance) of a topic, or (None, ...)."""
    label = lambda field: f"{name}.{field} (instance {multi})"  # noqa: E731
    try:
        return ulog.get_dataset(name, multi).data, label
    except (KeyError, IndexError, ValueError):
        return None, label


def _has(d, *fields) -> bool:
    """True if a topic was logged with a timestamp and all ``fields`` (a corrupt format may lack some)."""
    return d is not None and "timestamp" in d and all(f in d for f in fields)


def _t(d) -> np.ndarray:
    """A topic's timestamps [s] (PX4 logs microseconds since boot)."""
    return np.asarray(d["timestamp"], dtype=float) * 1e-6


def load_px4(path, allow_damaged: bool = False) -> RawLog:
    """Decode a PX4 ULog into a :class:`~identification.io.raw_log.RawLog` (streams in the module docstring).

    Raises
    ------
    LogFormatError
        Not a ULog, its definitions section is cut or corrupt, or pyulog cannot decode it.
    DamagedLogError
        Bytes in the middle are not ULog messages, or pyulog reports corrupt data (unless ``allow_damaged``).
    MissingStreamError
        No body-rate topic or no input topic.
    """
    path = Path(path)
    pyulog = require("pyulog", "logs")
    ulog, damage, tolerated, meta_end = _parse(path, pyulog, allow_damaged)
    rates, attitude = _rates_and_attitude(ulog, path)
    inputs, notes, unavailable, power = _inputs(ulog, path)
    status, _ = _topic(ulog, "vehicle_status")
    mav_type = int(status["system_type"][0]) if _has(status, "system_type") else None
    vehicle = {MAV_TYPE_HELICOPTER: "helicopter", 1: "fixed-wing"}.get(mav_type, "multirotor")
    unavailable["servos"] = (f"PX4 {vehicle} log: PX4's mixer outputs are not swash-plate servos of eqs. 65-67; "
                             "use inputs='controller' (the rate controller's torque demand)")
    meta = {
        "firmware": f"PX4 {ulog.msg_info_dict.get('ver_sw', '?')}",
        "mav_type": mav_type,
        "parser": f"pyulog {getattr(pyulog, '__version__', '?')}",
        **meta_end,
    }
    ratemax = ulog.initial_parameters.get("IMU_GYRO_RATEMAX", 0)
    if isinstance(ratemax, (int, float)) and ratemax > 0 and vehicle != "fixed-wing":
        # the multicopter (and helicopter) rate controller runs on each vehicle_angular_velocity sample, published at
        # most this fast (PX4's imu_gyro_parameters.c: "the loop rate for the rate controller and outputs"; 0: the
        # sensor's own rate, which the log does not state); a fixed-wing's rate loop is not read as it
        meta["loop_rate_hz"] = float(ratemax)
    cutoff = ulog.initial_parameters.get("IMU_GYRO_CUTOFF", 0.0)
    if isinstance(cutoff, (int, float)) and cutoff > 0:  # the gyro's 2-pole low-pass before the controller and log
        meta["gyro_filter_hz"] = float(cutoff)
    return RawLog(path=path, format="px4-ulog", vehicle=vehicle, rates=rates, attitude=attitude, inputs=inputs,
                  input_notes=notes, unavailable=unavailable,
                  default_input="controller" if "controller" in inputs else "sticks",
                  segment_signals=_segment_signals(ulog, power), metadata=meta, damage=damage, notes=tolerated)


def _parse(path: Path, pyulog, allow_damaged: bool):
    """The log's sound bytes parsed by pyulog: (ULog, damage, notes, metadata of how the file ends)."""
    where = locate(path)
    if where.format != "px4-ulog":
        head = path.read_bytes()[:16]
        raise LogFormatError(f"{path}: not a PX4 ULog: expected the header bytes {ULOG_MAGIC!r}, got {head[:7]!r}")
    span = where.logs[0]
    with open(path, "rb") as fh:
        fh.seek(span.start)
        data = fh.read(span.size)
    data, tolerated, damage, meta_end = _sound_bytes(data, str(path), allow_damaged)
    check_damage(damage, path, allow_damaged, "PX4 ULog")
    if span.padding_note():
        tolerated.insert(0, span.padding_note())
        meta_end["padding"] = {"before": span.lead, "after": span.trail}
    try:
        with captured_output() as printed:
            ulog = pyulog.ULog(io.BytesIO(data))
    except Exception as e:  # the parser's own failure on bad bytes: any exception type
        raise LogFormatError(f"{path}: pyulog cannot decode this ULog ({type(e).__name__}: {e})") from e
    if ulog.file_corruption:
        damage.append("pyulog reports corrupt data inside the log ("
                      + ("; ".join(p for p in printed[:2] if p) or "messages it could not decode") + ")")
    check_damage(damage, path, allow_damaged, "PX4 ULog")
    return ulog, damage, tolerated, meta_end


def _rates_and_attitude(ulog, path: Path):
    """The body rates (``vehicle_angular_velocity``, else ``sensor_combined``) and the attitude, or None."""
    rates = None
    d, src = _topic(ulog, "vehicle_angular_velocity")
    if _has(d, "xyz[0]", "xyz[1]", "xyz[2]"):
        rates = make_stream(_t(d), [d[f"xyz[{i}]"] for i in range(3)], src("xyz"))
    if rates is None:
        d, src = _topic(ulog, "sensor_combined")
        if _has(d, "gyro_rad[0]", "gyro_rad[1]", "gyro_rad[2]"):
            rates = make_stream(_t(d), [d[f"gyro_rad[{i}]"] for i in range(3)], src("gyro_rad"))
    if rates is None:
        raise MissingStreamError(f"{path}: no body rates: expected topic vehicle_angular_velocity (xyz) or "
                                 "sensor_combined (gyro_rad) with at least 2 samples")
    d, src = _topic(ulog, "vehicle_attitude")
    attitude = None
    if _has(d, "q[0]", "q[1]", "q[2]", "q[3]"):
        q = np.array([d[f"q[{i}]"] for i in range(4)], dtype=float)
        attitude = make_stream(_t(d), euler_from_quaternion(q), src("q"), angles=True)
    return rates, attitude


def _inputs(ulog, path: Path):
    """The input streams, their notes, why a source is unavailable, and the thrust demand (power) or None."""
    inputs, notes, unavailable = {}, {}, {}
    sticks = _sticks(ulog, notes)
    if sticks is not None:
        inputs["sticks"] = sticks
    else:
        unavailable["sticks"] = "no manual_control_setpoint topic with at least 2 samples"
    controller, power = _controller(ulog, notes)
    if controller is not None:
        inputs["controller"] = controller
    else:
        unavailable["controller"] = ("neither actuator_controls_0 nor vehicle_torque_setpoint + "
                                     "vehicle_thrust_setpoint is logged with at least 2 samples")
    if power is None and "sticks" in inputs:
        power = make_stream(inputs["sticks"].time, (inputs["sticks"].values[2] + 1.0) / 2.0,
                            "manual_control_setpoint throttle")
    if not inputs:
        raise MissingStreamError(f"{path}: no input stream: expected actuator_controls_0, vehicle_torque_setpoint "
                                 "+ vehicle_thrust_setpoint (controller) or manual_control_setpoint (sticks)")
    return inputs, notes, unavailable, power


def _sticks(ulog, notes: dict):
    """The pilot's sticks from ``manual_control_setpoint`` (either generation of its fields), or None."""
    m, src = _topic(ulog, "manual_control_setpoint")
    if _has(m, "roll", "pitch", "yaw", "throttle"):  # PX4 >= 1.14: roll, pitch, yaw, throttle all -1..1
        lat, lon, ped, col = m["roll"], -np.asarray(m["pitch"], float), m["yaw"], m["throttle"]
        notes["sticks"] = ("manual_control_setpoint: lat=roll, lon=-pitch (stick forward = nose down), "
                           "col=throttle (-1..1), ped=yaw")
    elif _has(m, "x", "y", "z", "r"):
        lat, lon, ped = m["y"], -np.asarray(m["x"], float), m["r"]
        col = 2.0 * np.asarray(m["z"], float) - 1.0
        notes["sticks"] = "manual_control_setpoint: lat=y, lon=-x (stick forward = nose down), col=2z-1, ped=r"
    else:
        return None
    return make_stream(_t(m), [lat, lon, col, ped], src("*"))


def _controller(ulog, notes: dict):
    """The rate controller's demand (``actuator_controls_0``, else the torque and thrust setpoints) and its
    thrust as power: (stream or None, power or None)."""
    c, src = _topic(ulog, "actuator_controls_0")
    ts, src_ts = _topic(ulog, "vehicle_torque_setpoint")
    th, src_th = _topic(ulog, "vehicle_thrust_setpoint")
    if _has(c, "control[0]", "control[1]", "control[2]", "control[3]"):
        thrust = np.asarray(c["control[3]"], float)
        s = make_stream(_t(c), [c["control[0]"], c["control[1]"], 2.0 * thrust - 1.0, c["control[2]"]],
                        src("control[0..3]"))
        notes["controller"] = ("actuator_controls_0: lat=control[0] (roll torque), lon=control[1] (pitch torque), "
                               "col=2*control[3]-1 (thrust), ped=control[2] (yaw torque); all -1..1")
        if s is not None:
            return s, make_stream(_t(c), thrust, src("control[3]"))
    elif _has(ts, "xyz[0]", "xyz[1]", "xyz[2]") and _has(th, "xyz[2]"):
        tt, tth = _t(ts), _t(th)
        up = -np.asarray(th["xyz[2]"], float)
        thrust_stream = make_stream(tth, up, src_th("-xyz[2]"))
        if thrust_stream is not None:
            thrust = np.interp(tt, thrust_stream.time, thrust_stream.values[0])
            s = make_stream(tt, [ts["xyz[0]"], ts["xyz[1]"], 2.0 * thrust - 1.0, ts["xyz[2]"]], src_ts("xyz"))
            notes["controller"] = ("vehicle_torque_setpoint.xyz -> lat, lon, ped (-1..1); "
                                   "col = 2*(-vehicle_thrust_setpoint.xyz[2]) - 1")
            if s is not None:
                return s, thrust_stream
    return None, None


def _segment_signals(ulog, power) -> SegmentSignals:
    """What the airborne detector reads: thrust demand, accelerometer, height, armed state."""
    sc, src = _topic(ulog, "sensor_combined")
    accel = None
    if _has(sc, "accelerometer_m_s2[0]", "accelerometer_m_s2[1]", "accelerometer_m_s2[2]"):
        accel = make_stream(_t(sc), [sc[f"accelerometer_m_s2[{i}]"] for i in range(3)], src("accelerometer_m_s2"))
    lp, src = _topic(ulog, "vehicle_local_position")
    altitude = None
    if _has(lp, "z"):
        altitude = make_stream(_t(lp), -np.asarray(lp["z"], float), src("-z"))
    armed, src = _topic(ulog, "actuator_armed")
    armed = make_stream(_t(armed), armed["armed"], src("armed")) if _has(armed, "armed") else None
    return SegmentSignals(power=power, accel=accel, altitude=altitude, armed=armed,
                          power_name=f"thrust demand ({power.name})" if power else "thrust demand")
