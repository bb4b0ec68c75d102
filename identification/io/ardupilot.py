"""ArduPilot DataFlash (``.bin``) import with :mod:`pymavlink` (``DFReader``).

Streams used (message.field)

===============  ===============================  =========================================================
quantity         message                          units, signs, mapping
===============  ===============================  =========================================================
p, q, r          ``IMU.GyrX, GyrY, GyrZ``         rad/s, body FRD: roll right, nose up, nose right positive
                                                  (first IMU instance)
phi, theta, psi  ``ATT.Roll, Pitch, Yaw``         deg -> rad; yaw 0..360 wrapped to (-pi, pi]
sticks           ``RCIN.C<n>`` with ``RCMAP_*``   PWM normalised by the RC<n>_MIN/TRIM/MAX/REV parameters:
                                                  roll/pitch/yaw (pwm-trim)/(max-trim) above trim,
                                                  /(trim-min) below -> -1..1 (pitch PWM up = stick back =
                                                  nose up = +lon); throttle 2(pwm-min)/(max-min)-1 -> col.
                                                  PWM 0 (no RC signal yet) lands outside and is clipped.
controller       ``RATE.ROut, POut, YOut, AOut``  rate-controller outputs: ArduCopter <= 3.3 logs them in
                                                  motor-mix units (+-5000 roll/pitch, +-4500 yaw, 0..1000
                                                  throttle), later versions -1..1 / 0..1; scaled to -1..1,
                                                  col = 2*throttle-1. Sign: a positive output drives a
                                                  positive rate.
servos           ``RCOU.C1..C4`` (helicopters)    swash servos 1-3 at -60, 60, 180 deg (ArduPilot's H3-120
                                                  default H_SV1..3_POS) = u_aile, u_aux, u_elev; servo 4 =
                                                  u_rudd; converted with eq. (67). Multirotors: not available.
===============  ===============================  =========================================================

Airborne detection uses ``CTUN.ThrOut`` (``ThO``) as power, the ``IMU``
accelerometer for vibration and ``CTUN.Alt`` as height. Time is the log's own
clock (``TimeMS``/``TimeUS`` since boot) in seconds, continued across a restart of
that clock (:mod:`.clock`; ``metadata["clock"]``).

The file is read as MAVExplorer reads it: a last message cut short (the battery
unplugged while logging) is dropped with a note, 0xFF/0x00 padding before and after
the log is skipped, and a few unreadable bytes at the very end are dropped.
Bytes in the middle of the log that are not DataFlash messages, or an index that
stops early, are damage (``allow_damaged``). The vehicle is named from the
firmware string (ArduCopter, ArduCopter heli frames, ArduPlane, Rover).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np

from heli_core.errors import require

from .ardupilot_vehicle import vehicle_of
from .clock import continue_clock, describe
from .container import DF_HEAD, PAD, locate, span_file
from .errors import LogFormatError, MissingStreamError
from .raw_log import RawLog, captured_output, check_damage
from .resample import make_stream
from .segment import SegmentSignals

TAIL_GARBAGE_MAX = 528
"""bytes: pymavlink's own tolerance for garbage at the end of a log (block-based logs end in a partial page)."""
LEGACY_RP_SCALE = 5000.0
"""ArduCopter <= 3.3: AC_ATTITUDE_RATE_RP_CONTROLLER_OUT_MAX, roll/pitch rate output limit."""
LEGACY_YAW_SCALE = 4500.0
"""ArduCopter <= 3.3: AC_ATTITUDE_RATE_YAW_CONTROLLER_OUT_MAX."""
LEGACY_THROTTLE_SCALE = 1000.0

_WANTED = {
    "IMU": ("GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ"),
    "ATT": ("Roll", "Pitch", "Yaw"),
    "RATE": ("ROut", "POut", "YOut", "AOut"),
    "RCIN": tuple(f"C{i}" for i in range(1, 9)),
    "RCOU": ("C1", "C2", "C3", "C4"),
    "CTUN": ("ThrOut", "ThO", "Alt"),
}


def is_dataflash(head: bytes) -> bool:
    """True if the first bytes (after any 0xFF/0x00 padding) are a DataFlash FMT message."""
    return head.lstrip(PAD).startswith(DF_HEAD)


def _time_of(m) -> float | None:
    us = getattr(m, "TimeUS", None)
    if us is not None:
        return us * 1e-6
    ms = getattr(m, "TimeMS", None)
    return None if ms is None else ms * 1e-3


def _read_messages(f) -> tuple[dict, dict, list, list]:
    """Columns of the wanted messages (first instance) on a continued clock, the parameters, the texts, and
    the clock events (:func:`~identification.io.clock.continue_clock` over all messages in file order)."""
    rows: dict = defaultdict(lambda: defaultdict(list))
    order: dict = defaultdict(list)
    times: list = []
    params: dict = {}
    texts: list = []
    while True:
        m = f.recv_match(type=list(_WANTED) + ["PARM", "MSG", "RCOU"])
        if m is None:
            break
        kind = m.get_type()
        if kind == "PARM":
            params[str(m.Name)] = float(m.Value)
            continue
        if kind == "MSG":
            texts.append(str(m.Message))
            continue
        if getattr(m, "I", 0) not in (0, None) or getattr(m, "Instance", 0) not in (0, None):
            continue
        t = _time_of(m)
        if t is None:
            continue
        c = rows[kind]
        order[kind].append(len(times))
        times.append(float(t))
        for name in _WANTED[kind]:
            v = getattr(m, name, None)
            if v is None and kind == "RCOU":
                v = getattr(m, "Ch" + name[1:], None)  # ArduCopter 3.3 names RCOU fields Ch1..
            c[name].append(np.nan if v is None else float(v))
    clock, keep, events = continue_clock(times)
    fixed = np.full(len(times), np.nan)
    fixed[keep] = clock
    cols = {}
    for kind, c in rows.items():
        idx = np.asarray(order[kind], dtype=int)
        cols[kind] = {"t": fixed[idx], **{n: np.asarray(v, dtype=float) for n, v in c.items()}}
    return cols, params, texts, events


def _end_of_log(f) -> tuple[list, list, dict]:
    """How the log ends and whether its middle is sound, from pymavlink's index: (notes, damage, metadata).

    A last message running past the end of the data is a cut last message (pymavlink drops it); bytes
    between indexed messages are garbage inside the log; an index that stops well before the end
    (pymavlink stops at an unknown message type) loses the rest of the log.
    """
    notes, damage, meta = [], [], {}
    lengths = {t: f.formats[t].len for t in range(len(f.offsets)) if len(f.offsets[t]) and t in f.formats}
    if not lengths:
        return notes, ["no DataFlash message could be indexed"], meta
    last_type = max(lengths, key=lambda t: int(f.offsets[t][-1]))
    last = int(f.offsets[last_type][-1])
    end = last + lengths[last_type]
    used = sum(int(f.counts[t]) * n for t, n in lengths.items())
    if end > f.data_len:
        name = getattr(f.formats[last_type], "name", "?")
        notes.append(f"the log ends {f.data_len - last} bytes into its last message ({name}, {lengths[last_type]} "
                     "bytes; logging stopped mid-write, e.g. power lost): dropped it")
        meta["cut_last_message"] = {"message": name, "bytes_present": f.data_len - last,
                                    "message_bytes": lengths[last_type]}
    elif f.data_len - end > TAIL_GARBAGE_MAX:
        damage.append(f"decoding stops at byte {end} of {f.data_len}: the {f.data_len - end} bytes after it are not "
                      "DataFlash messages pymavlink can index")
    elif f.data_len > end:
        notes.append(f"dropped {f.data_len - end} unreadable bytes after the last complete message")
        meta["unreadable_tail_bytes"] = f.data_len - end
    skipped = min(end, f.data_len) - used + (lengths[last_type] - (f.data_len - last) if end > f.data_len else 0)
    if skipped > 0:
        damage.append(f"corrupt: {skipped} bytes inside the log are not DataFlash messages (pymavlink skips them)")
    return notes, damage, meta


def _channel(value, default: int) -> int:
    """An RCMAP_* parameter as a channel number 1..16 (the default for a missing or garbled value)."""
    return int(value) if value is not None and np.isfinite(value) and 1 <= value <= 16 else default


def _rc_norm(pwm, lo, trim, hi, rev) -> np.ndarray:
    """Centred RC channel -> -1..1 (ArduPilot's own scaling about the trim)."""
    x = np.where(pwm >= trim, (pwm - trim) / max(hi - trim, 1.0), (pwm - trim) / max(trim - lo, 1.0))
    return x * (-1.0 if rev < 0 else 1.0)


def load_ardupilot(path, allow_damaged: bool = False) -> RawLog:
    """Decode an ArduPilot DataFlash log into a :class:`~identification.io.raw_log.RawLog`.

    Raises
    ------
    LogFormatError
        Not a DataFlash log or pymavlink cannot decode it.
    DamagedLogError
        Truncated or with corrupt bytes (unless ``allow_damaged``).
    MissingStreamError
        No IMU gyro or ATT messages.
    """
    path = Path(path)
    cols, params, texts, tolerated, damage, meta_end = _parse(path, allow_damaged)
    imu, att = cols.get("IMU"), cols.get("ATT")
    if imu is None or "GyrX" not in imu:
        raise MissingStreamError(f"{path}: no body rates: expected IMU messages with GyrX/GyrY/GyrZ")
    rates = make_stream(imu["t"], [imu["GyrX"], imu["GyrY"], imu["GyrZ"]], "IMU.Gyr")
    if rates is None:
        raise MissingStreamError(f"{path}: fewer than 2 usable IMU samples")
    attitude = None
    if att is not None:
        attitude = make_stream(att["t"], np.radians([att["Roll"], att["Pitch"], att["Yaw"]]), "ATT", angles=True)
    accel = make_stream(imu["t"], [imu["AccX"], imu["AccY"], imu["AccZ"]], "IMU.Acc")

    firmware, vehicle, heli = vehicle_of(texts, params)
    if vehicle in ("fixed-wing", "ground vehicle"):
        tolerated.append(f"{firmware}: a {vehicle}, not a rotorcraft; the attitude models of this package describe "
                         "hovering helicopters, so read identification results of this log with care")
    inputs, notes, unavailable = {}, {}, {}
    _sticks(cols.get("RCIN"), params, inputs, notes, unavailable)
    _controller(cols.get("RATE"), inputs, notes, unavailable)
    power, altitude = _power_and_altitude(cols.get("CTUN"))
    servos = _servos(cols.get("RCOU"), heli, firmware, vehicle, unavailable)
    inputs = {k: v for k, v in inputs.items() if v is not None}
    if not inputs and servos is None:
        raise MissingStreamError(f"{path}: no input stream: expected RATE (controller), RCIN (sticks) or, on a "
                                 "helicopter, RCOU (servos) messages with at least 2 samples")
    default = "servos" if servos is not None else ("controller" if "controller" in inputs else "sticks")
    meta = {"firmware": firmware, "frame": params.get("FRAME"), "parser": "pymavlink DFReader", **meta_end}
    if params.get("SCHED_LOOP_RATE", 0.0) > 0:  # the main loop's rate, the rate controller's (ArduCopter >= 3.4)
        meta["loop_rate_hz"] = float(params["SCHED_LOOP_RATE"])
    if params.get("INS_GYRO_FILTER", 0.0) > 0:  # the gyro's 2-pole low-pass, before the loop reads it and the log
        meta["gyro_filter_hz"] = float(params["INS_GYRO_FILTER"])
    return RawLog(path=path, format="ardupilot-dataflash", vehicle=vehicle, rates=rates, attitude=attitude,
                  inputs=inputs, input_notes=notes, unavailable=unavailable, default_input=default, servos=servos,
                  segment_signals=SegmentSignals(power=power, accel=accel, altitude=altitude,
                                                 power_name=f"throttle output ({power.name})" if power else
                                                 "throttle output"),
                  metadata=meta, damage=damage, notes=tolerated)


def _parse(path: Path, allow_damaged: bool):
    """The log read by pymavlink: (columns, parameters, texts, notes, damage, metadata of how it ends)."""
    mavlink = require("pymavlink.DFReader", "logs")
    where = locate(path)
    if where.format != "ardupilot-dataflash":
        with open(path, "rb") as fh:
            head = fh.read(3)
        raise LogFormatError(f"{path}: not an ArduPilot DataFlash log: expected it to start with bytes "
                             f"{DF_HEAD.hex(' ')}, got {head.hex(' ') or 'an empty file'}")
    span = where.logs[0]
    try:
        with span_file(path, span, where.size) as src, captured_output():
            f = mavlink.DFReader_binary(str(src), zero_time_base=False)
            cols, params, texts, clock = _read_messages(f)
            tolerated, damage, meta_end = _end_of_log(f)
            f.filehandle.close()
    except Exception as e:  # the parser's own failure on bad bytes: any exception type
        raise LogFormatError(f"{path}: pymavlink cannot decode this DataFlash log ({type(e).__name__}: {e})") from e
    check_damage(damage, path, allow_damaged, "ArduPilot DataFlash")
    if span.padding_note():
        tolerated.insert(0, span.padding_note())
        meta_end["padding"] = {"before": span.lead, "after": span.trail}
    if clock:
        tolerated.append(describe(clock))
        meta_end["clock"] = clock
    return cols, params, texts, tolerated, damage, meta_end


def _sticks(rcin, params: dict, inputs: dict, notes: dict, unavailable: dict) -> None:
    """The sticks from ``RCIN`` mapped by ``RCMAP_*`` and normalised by ``RC<n>_*`` (into ``inputs``)."""
    if rcin is None:
        unavailable["sticks"] = "no RCIN messages"
        return
    chan = {a: _channel(params.get(f"RCMAP_{a}"), d) for a, d in
            (("ROLL", 1), ("PITCH", 2), ("THROTTLE", 3), ("YAW", 4))}

    def rc(axis):
        n = chan[axis]
        p = lambda k, d: params.get(f"RC{n}_{k}", d)  # noqa: E731
        return n, rcin.get(f"C{n}"), p("MIN", 1100.0), p("TRIM", 1500.0), p("MAX", 1900.0), p("REV", 1.0)

    parts = {a: rc(a) for a in chan}
    if not all(v[1] is not None for v in parts.values()):
        unavailable["sticks"] = "RCIN lacks the channels RCMAP_* names"
        return
    lat = _rc_norm(*parts["ROLL"][1:])
    lon = _rc_norm(*parts["PITCH"][1:])
    ped = _rc_norm(*parts["YAW"][1:])
    n, pwm, lo, _, hi, rev = parts["THROTTLE"]
    col = 2.0 * (pwm - lo) / max(hi - lo, 1.0) - 1.0
    inputs["sticks"] = make_stream(rcin["t"], [lat, lon, col, ped], "RCIN")
    notes["sticks"] = (f"RCIN C{chan['ROLL']}->lat, C{chan['PITCH']}->lon, C{chan['THROTTLE']}->col, "
                       f"C{chan['YAW']}->ped (RCMAP_*), normalised by RC<n>_MIN/TRIM/MAX/REV to -1..1")


def _controller(rate, inputs: dict, notes: dict, unavailable: dict) -> None:
    """The rate controller's outputs from ``RATE``, in either generation's units (into ``inputs``)."""
    if rate is None or "ROut" not in rate:
        unavailable["controller"] = "no RATE messages (LOG_BITMASK without the rate-controller bit)"
        return
    legacy = np.nanmax(np.abs(np.concatenate([rate["ROut"], rate["POut"]]))) > 1.5
    s_rp, s_y, s_t = (LEGACY_RP_SCALE, LEGACY_YAW_SCALE, LEGACY_THROTTLE_SCALE) if legacy else (1.0, 1.0, 1.0)
    thr = rate["AOut"] / s_t
    inputs["controller"] = make_stream(
        rate["t"], [rate["ROut"] / s_rp, rate["POut"] / s_rp, 2.0 * thr - 1.0, rate["YOut"] / s_y], "RATE")
    notes["controller"] = (f"RATE ROut/{s_rp:g}->lat, POut/{s_rp:g}->lon, 2*AOut/{s_t:g}-1->col, "
                           f"YOut/{s_y:g}->ped (rate-controller outputs"
                           f"{', ArduCopter <= 3.3 motor-mix units' if legacy else ''})")


def _power_and_altitude(ctun):
    """The throttle output (power) and the height from ``CTUN``, each a stream or None."""
    if ctun is None:
        return None, None
    power = None
    thr = ctun.get("ThO") if "ThO" in ctun and np.isfinite(ctun["ThO"]).any() else ctun.get("ThrOut")
    if thr is not None and np.isfinite(thr).any():
        thr = thr / (LEGACY_THROTTLE_SCALE if np.nanmax(thr) > 1.5 else 1.0)
        power = make_stream(ctun["t"], thr, "CTUN.ThrOut")
    altitude = make_stream(ctun["t"], ctun["Alt"], "CTUN.Alt") if "Alt" in ctun else None
    return power, altitude


def _servos(rcou, heli: bool, firmware: str, vehicle: str, unavailable: dict):
    """A helicopter's swash servos from ``RCOU``, or None (with the reason in ``unavailable``)."""
    if heli and rcou is not None:
        return make_stream(rcou["t"], [rcou["C1"], rcou["C2"], rcou["C3"], rcou["C4"]], "RCOU.C1-C4")
    if not heli:
        outputs = "control-surface servos" if vehicle == "fixed-wing" else "motor outputs"
        unavailable["servos"] = (f"{firmware} {vehicle} log: RCOU holds {outputs}, not swash-plate servos of "
                                 "eqs. 65-67; use inputs='controller' (the rate controller's outputs) or 'sticks'")
    else:
        unavailable["servos"] = "no RCOU messages"
    return None
