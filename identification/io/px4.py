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
accelerometer (vibration) and ``vehicle_local_position.z`` (height).
Time is the log's own clock (``timestamp``, us since boot) in seconds.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from ..errors import require
from ..model import euler_from_quaternion
from .errors import LogFormatError, MissingStreamError
from .raw_log import RawLog, captured_output, check_damage
from .resample import make_stream
from .segment import SegmentSignals

ULOG_MAGIC = b"ULog\x01\x12\x35"
MAV_TYPE_HELICOPTER = 4


def is_ulog(head: bytes) -> bool:
    """True if the first bytes are a ULog file header."""
    return head.startswith(ULOG_MAGIC)


def _message_chain_end(path: Path) -> tuple[int, int]:
    """Walk the ULog message headers (uint16 size, uint8 type) and return (end offset, file size).

    A complete log's chain ends exactly at the end of the file; a cut one overshoots it.
    """
    data = path.read_bytes()
    off = 16  # file header
    n = len(data)
    unpack = struct.Struct("<HB").unpack_from
    while off + 3 <= n:
        size, _ = unpack(data, off)
        off += 3 + size
    return off, n


def _topic(ulog, name: str, multi: int = 0):
    try:
        return ulog.get_dataset(name, multi).data
    except (KeyError, IndexError, ValueError):
        return None


def _first(d, *names):
    for n in names:
        if d is not None and n in d:
            return d[n]
    return None


def load_px4(path, allow_damaged: bool = False) -> RawLog:
    """Decode a PX4 ULog into a :class:`~identification.io.raw_log.RawLog` (streams in the module docstring).

    Raises
    ------
    LogFormatError
        Not a ULog, or pyulog cannot decode it.
    DamagedLogError
        The message chain is cut short or pyulog reports corruption (unless ``allow_damaged``).
    MissingStreamError
        No body-rate or attitude topic.
    """
    path = Path(path)
    pyulog = require("pyulog", "logs")
    with open(path, "rb") as fh:
        head = fh.read(16)
    if not is_ulog(head):
        raise LogFormatError(f"{path}: not a PX4 ULog: expected the header bytes {ULOG_MAGIC!r}, got {head[:7]!r}")
    try:
        with captured_output() as printed:
            ulog = pyulog.ULog(str(path))
    except Exception as e:  # the parser's own failure on bad bytes: any exception type
        raise LogFormatError(f"{path}: pyulog cannot decode this ULog ({type(e).__name__}: {e})") from e
    damage = []
    if ulog.file_corruption:
        damage.append("pyulog reports corrupt data (" + "; ".join(p for p in printed[:2] if p) + ")")
    end, size = _message_chain_end(path)
    if end != size:
        damage.append(f"truncated: its last message runs {end - size} bytes past the end of the {size}-byte file")
    check_damage(damage, path, allow_damaged, "PX4 ULog")

    t_of = lambda d: np.asarray(d["timestamp"], dtype=float) * 1e-6  # noqa: E731

    rates = None
    d = _topic(ulog, "vehicle_angular_velocity")
    if d is not None:
        rates = make_stream(t_of(d), [d[f"xyz[{i}]"] for i in range(3)], "vehicle_angular_velocity.xyz")
    if rates is None:
        d = _topic(ulog, "sensor_combined")
        if d is not None:
            rates = make_stream(t_of(d), [d[f"gyro_rad[{i}]"] for i in range(3)], "sensor_combined.gyro_rad")
    if rates is None:
        raise MissingStreamError(f"{path}: no body rates: expected topic vehicle_angular_velocity or sensor_combined")
    d = _topic(ulog, "vehicle_attitude")
    attitude = None
    if d is not None:
        q = np.array([d[f"q[{i}]"] for i in range(4)], dtype=float)
        attitude = make_stream(t_of(d), euler_from_quaternion(q), "vehicle_attitude.q", angles=True)

    inputs, notes, unavailable = {}, {}, {}
    power = None
    m = _topic(ulog, "manual_control_setpoint")
    if m is not None:
        if "roll" in m:  # PX4 >= 1.14: roll, pitch, yaw, throttle all -1..1
            lat, lon, ped, col = m["roll"], -np.asarray(m["pitch"], float), m["yaw"], m["throttle"]
            notes["sticks"] = ("manual_control_setpoint: lat=roll, lon=-pitch (stick forward = nose down), "
                               "col=throttle (-1..1), ped=yaw")
        else:
            lat, lon, ped = m["y"], -np.asarray(m["x"], float), m["r"]
            col = 2.0 * np.asarray(m["z"], float) - 1.0
            notes["sticks"] = "manual_control_setpoint: lat=y, lon=-x (stick forward = nose down), col=2z-1, ped=r"
        s = make_stream(t_of(m), [lat, lon, col, ped], "manual_control_setpoint")
        if s is not None:
            inputs["sticks"] = s
    else:
        unavailable["sticks"] = "no manual_control_setpoint topic"
    c = _topic(ulog, "actuator_controls_0")
    if c is not None:
        thrust = np.asarray(c["control[3]"], float)
        s = make_stream(t_of(c), [c["control[0]"], c["control[1]"], 2.0 * thrust - 1.0, c["control[2]"]],
                        "actuator_controls_0")
        notes["controller"] = ("actuator_controls_0: lat=control[0] (roll torque), lon=control[1] (pitch torque), "
                               "col=2*control[3]-1 (thrust), ped=control[2] (yaw torque); all -1..1")
        if s is not None:
            inputs["controller"] = s
            power = make_stream(t_of(c), thrust, "actuator_controls_0.control[3]")
    else:
        ts, th = _topic(ulog, "vehicle_torque_setpoint"), _topic(ulog, "vehicle_thrust_setpoint")
        if ts is not None and th is not None:
            tt, tth = t_of(ts), t_of(th)
            thrust = np.interp(tt, tth, -np.asarray(th["xyz[2]"], float))
            s = make_stream(tt, [ts["xyz[0]"], ts["xyz[1]"], 2.0 * thrust - 1.0, ts["xyz[2]"]],
                            "vehicle_torque_setpoint")
            notes["controller"] = ("vehicle_torque_setpoint.xyz -> lat, lon, ped (-1..1); "
                                   "col = 2*(-vehicle_thrust_setpoint.xyz[2]) - 1")
            if s is not None:
                inputs["controller"] = s
                power = make_stream(tth, -np.asarray(th["xyz[2]"], float), "vehicle_thrust_setpoint")
        else:
            unavailable["controller"] = "neither actuator_controls_0 nor vehicle_torque_setpoint is logged"
    if power is None and "sticks" in inputs:
        power = make_stream(inputs["sticks"].time, (inputs["sticks"].values[2] + 1.0) / 2.0, "sticks throttle")

    status = _topic(ulog, "vehicle_status")
    mav_type = int(status["system_type"][0]) if status is not None and "system_type" in status else None
    vehicle = "helicopter" if mav_type == MAV_TYPE_HELICOPTER else "multirotor"
    unavailable["servos"] = (f"PX4 {vehicle} log: PX4's mixer outputs are not swash-plate servos of eqs. 65-67; "
                             "use inputs='controller' (the rate controller's torque demand)")
    sc = _topic(ulog, "sensor_combined")
    accel = None
    if sc is not None:
        accel = make_stream(t_of(sc), [sc[f"accelerometer_m_s2[{i}]"] for i in range(3)],
                            "sensor_combined.accelerometer_m_s2")
    lp = _topic(ulog, "vehicle_local_position")
    altitude = None
    if lp is not None:
        altitude = make_stream(t_of(lp), -np.asarray(lp["z"], float), "vehicle_local_position.z")
    default = "controller" if "controller" in inputs else "sticks"
    meta = {
        "firmware": f"PX4 {ulog.msg_info_dict.get('ver_sw', '?')}",
        "mav_type": mav_type,
        "parser": f"pyulog {getattr(pyulog, '__version__', '?')}",
    }
    return RawLog(path=path, format="px4-ulog", vehicle=vehicle, rates=rates, attitude=attitude, inputs=inputs,
                  input_notes=notes, unavailable=unavailable, default_input=default,
                  segment_signals=SegmentSignals(power=power, accel=accel, altitude=altitude,
                                                 power_name="thrust demand"),
                  metadata=meta, damage=damage)
