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
(Rotorflight) as power, ``accSmooth`` (Betaflight) or the gyro for vibration,
and ``baroAlt`` when logged. Time is the log's clock (us since boot) in seconds.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from ..errors import require
from .errors import LogFormatError, MissingStreamError
from .raw_log import RawLog, captured_output, check_damage
from .resample import make_stream
from .segment import SegmentSignals

BLACKBOX_MAGIC = b"H Product:Blackbox flight data recorder"
CORRUPT_FRAME_SHARE = 1e-3
"""A log with more than this share of its frames invalid (orangebox's own count) is called corrupt."""
QUAT_SCALE = 32767.0
RC_SCALE = 500.0
PID_SCALE = 1000.0
MIXER_SCALE = 1000.0


def is_blackbox(head: bytes) -> bool:
    """True if the first bytes are a blackbox header."""
    return head.startswith(BLACKBOX_MAGIC)


def _float_bits(value) -> float:
    return struct.unpack("<f", struct.pack("<I", int(value) & 0xFFFFFFFF))[0]


def _decode(path: Path, allow_damaged: bool):
    orangebox = require("orangebox", "logs")
    from orangebox.types import FrameType

    damage = []
    try:
        with captured_output():
            parser = orangebox.Parser.load(str(path))
            names = [f.name for f in parser.reader.field_defs[FrameType.INTRA]]
    except Exception as e:  # the parser's own failure on bad bytes: any exception type
        raise LogFormatError(f"{path}: orangebox cannot read the blackbox header ({type(e).__name__}: {e})") from e
    n = len(names)
    rows = []
    try:
        with captured_output():
            for frame in parser.frames():
                rows.append(frame.data[:n])
    except Exception as e:  # a cut or garbled frame stream ends in an arbitrary exception inside orangebox
        damage.append(f"decoding stopped after {len(rows)} frames ({type(e).__name__}: {e}); "
                      "the file is truncated or corrupt there")
    events = [ev.type.name for ev in parser.events]
    stats = parser._ctx.stats if getattr(parser, "_ctx", None) is not None else {}
    if not damage and "LOG_END" not in events:
        damage.append(f"truncated: no end-of-log event after {len(rows)} frames")
    total = max(int(stats.get("total", 0)), 1)
    invalid = int(stats.get("invalid", 0))
    if invalid > CORRUPT_FRAME_SHARE * total:
        damage.append(f"corrupt: {invalid} of {total} frames invalid (orangebox), more than "
                      f"{CORRUPT_FRAME_SHARE:.1%}")
    check_damage(damage, path, allow_damaged, "blackbox")
    if len(rows) < 2:
        raise LogFormatError(f"{path}: the blackbox log holds {len(rows)} decodable frames; expected a flight")
    data = np.array(rows, dtype=float).T
    cols = {name: data[i] for i, name in enumerate(names)}
    return parser.headers, cols, damage, parser.reader.log_count, events


def load_blackbox(path, allow_damaged: bool = False) -> RawLog:
    """Decode a Betaflight or Rotorflight blackbox log (the first log in the file) into a ``RawLog``.

    Raises
    ------
    LogFormatError
        Not a blackbox log, or orangebox cannot decode its header.
    DamagedLogError
        Truncated (no end-of-log event, decoding stopped) or with more than 0.1% invalid frames.
    MissingStreamError
        No gyro, no attitude, or no time field.
    """
    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.read(len(BLACKBOX_MAGIC))
    if not is_blackbox(head):
        raise LogFormatError(f"{path}: not a blackbox log: expected it to start with {BLACKBOX_MAGIC.decode()!r}, "
                             f"got {head[:40]!r}")
    hdr, c, damage, log_count, events = _decode(path, allow_damaged)
    firmware = str(hdr.get("Firmware type", "Betaflight"))
    rotorflight = "rotorflight" in firmware.lower()
    if "time" not in c or "gyroADC[0]" not in c:
        raise MissingStreamError(f"{path}: the blackbox log lacks the time or gyroADC fields")
    t = c["time"] * 1e-6
    scale = _float_bits(hdr.get("gyro_scale", 1065353216))
    to_rad = np.radians(1.0) if abs(scale - 1.0) < 1e-6 else scale * 1e6  # deg/s, or Cleanflight rad/us units
    # Yaw: the blackbox logs yaw rate positive nose-left; canonical r is positive nose-right.
    sign = np.array([1.0, 1.0, -1.0])
    rates = make_stream(t, sign[:, None] * to_rad * np.array([c[f"gyroADC[{i}]"] for i in range(3)]), "gyroADC")
    if rates is None:
        raise MissingStreamError(f"{path}: fewer than 2 frames with increasing time")

    if "attitude[0]" in c:
        ang = np.radians(np.array([c["attitude[0]"], c["attitude[1]"], c["attitude[2]"]]) / 10.0)
        attitude = make_stream(t, ang, "attitude (decidegrees)", angles=True)
    elif "imuQuaternion[0]" in c:
        x, y, z = (c[f"imuQuaternion[{i}]"] / QUAT_SCALE for i in range(3))
        w = np.sqrt(np.clip(1.0 - x * x - y * y - z * z, 0.0, 1.0))
        roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
        pitch = np.arcsin(np.clip(2.0 * (w * y - x * z), -1.0, 1.0))
        yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        attitude = make_stream(t, [roll, pitch, -yaw], "imuQuaternion", angles=True)
    else:
        attitude = None

    inputs, notes, unavailable = {}, {}, {}
    rc = [c.get(f"rcCommand[{i}]") for i in range(5)]
    if all(r is not None for r in rc[:4]):
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
        if all(f"mixer[{i}]" in c for i in range(4)):
            m = [c[f"mixer[{i}]"] / MIXER_SCALE for i in range(4)]
            inputs["controller"] = make_stream(t, [m[0], m[1], m[3], -m[2]], "mixer")
            notes["controller"] = ("mixer[0]/1000->lat, mixer[1]/1000->lon, mixer[3]/1000->col (collective), "
                                   "-mixer[2]/1000->ped (stabilised mixer inputs)")
        else:
            unavailable["controller"] = "no mixer fields in this Rotorflight log"
    else:
        def pid(axis):
            parts = [c.get(f"axis{k}[{axis}]") for k in "PIDF"]
            return sum(p for p in parts if p is not None) / PID_SCALE

        if "axisP[0]" in c and "sticks" in inputs:
            throttle = (rc[3] - 1500.0) / RC_SCALE
            inputs["controller"] = make_stream(t, [pid(0), pid(1), throttle, -pid(2)], "PID sum")
            notes["controller"] = ("(axisP+axisI+axisD+axisF)/1000 per axis -> lat, lon, -yaw -> ped "
                                   "(mixer units, limit +-0.5); col = (rcCommand[3]-1500)/500 (throttle)")
        else:
            unavailable["controller"] = "no axisP/I/D fields"

    servos = None
    if rotorflight:
        if all(f"servo[{i}]" in c for i in range(4)):
            servos = make_stream(t, [c[f"servo[{i}]"] for i in range(4)], "servo[0..3]")
        else:
            unavailable["servos"] = ("this Rotorflight log has no servo[0..3] fields (enable servos in the "
                                     "blackbox field mask); use inputs='controller' (mixer inputs)")
    else:
        unavailable["servos"] = (f"{firmware} multirotor log: motor outputs are not swash-plate servos of "
                                 "eqs. 65-67; use inputs='controller' (the PID sum)")

    motors = [c[k] for k in (f"motor[{i}]" for i in range(8)) if k in c]
    power, power_name = None, "throttle"
    if rotorflight:
        if rc[4] is not None and rc[3] is not None:
            # Lift needs both a spooled rotor (throttle) and positive collective.
            power = make_stream(t, np.clip(rc[4] / 1000.0, 0, 1) * np.clip(rc[3] / RC_SCALE, 0, 1),
                                "throttle x positive collective")
            power_name = "throttle x positive collective"
    elif motors:
        lo, hi = (hdr.get("motorOutput") or [0, 0])[:2]
        if not hi > lo:
            lo, hi = float(np.min(motors)), float(np.max(motors))
        power = make_stream(t, (np.mean(motors, axis=0) - lo) / max(hi - lo, 1.0), "mean motor output")
        power_name = "mean motor output"
    accel = None
    if "accSmooth[0]" in c:
        one_g = float(hdr.get("acc_1G", 2048) or 2048)
        accel = make_stream(t, 9.80665 / one_g * np.array([c[f"accSmooth[{i}]"] for i in range(3)]), "accSmooth")
    altitude = make_stream(t, c["baroAlt"] / 100.0, "baroAlt") if "baroAlt" in c else None

    default = "servos" if servos is not None else ("controller" if "controller" in inputs else "sticks")
    meta = {"firmware": str(hdr.get("Firmware revision", firmware)), "craft": hdr.get("Craft name"),
            "logs_in_file": int(log_count), "log_index": 1, "events": sorted(set(events)),
            "parser": "orangebox"}
    return RawLog(path=path, format="rotorflight-blackbox" if rotorflight else "betaflight-blackbox",
                  vehicle="helicopter" if rotorflight else "multirotor", rates=rates, attitude=attitude,
                  inputs={k: v for k, v in inputs.items() if v is not None}, input_notes=notes,
                  unavailable=unavailable, default_input=default, servos=servos,
                  segment_signals=SegmentSignals(power=power, accel=accel, altitude=altitude, power_name=power_name),
                  metadata=meta, damage=damage)
