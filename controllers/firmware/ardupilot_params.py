"""ArduPilot's heli attitude parameters: read from a log or a parameter file, checked, written back.

Where they come from (:func:`read_ardupilot_values`):

* an ArduPilot DataFlash ``.bin`` log: its ``PARM`` messages (pymavlink ``DFReader``, as
  :mod:`identification.io.ardupilot` reads the log);
* an ArduPilot text DataFlash log (``.log``, lines ``PARM, NAME, VALUE``);
* a parameter file: Mission Planner's ``NAME,VALUE``, pymavlink/MAVProxy's ``NAME VALUE`` or
  QGroundControl's tab-separated ``vehicle component NAME VALUE type`` lines, ``#`` comments.

:func:`ardupilot_params` turns the values into :class:`~controllers.firmware.ardupilot.ArduPilotHeliParams`:
the current names first (``ATC_ANG_*_P``, ``ATC_RAT_*_{P,I,D,FF,D_FF,IMAX,ILMI,FLTT,FLTE,FLTD}``,
``ATC_ACCEL_{R,P,Y}_MAX``, ``ATC_INPUT_TC``, ``SCHED_LOOP_RATE``, ``INS_GYRO_FILTER``, ``H_CYC_MAX``), then
the older ones a log may hold, converted as ArduCopter 3.4 converted them (ArduCopter/Parameters.cpp
``convert_pid_parameters``: ``RATE_*_{P,I,D,FF}`` × 1.27 — the switch from centidegrees and ±4500 to radians
and ±1 —, ``RATE_*_IMAX`` / 4500, ``STB_*_P`` and ``RATE_*_FILT_HZ`` unchanged; ``ATC_RAT_*_VFF`` and
``_FILT`` are the 3.4-4.0 names of ``_FF`` and ``_FLTE``); ``H_ROL_MAX``/``H_PIT_MAX`` stand for
``H_CYC_MAX`` and ``INS_MPU6K_FILTER`` for ``INS_GYRO_FILTER``. A parameter the source lacks takes the
firmware's default and a note says so.

A file the user gives is checked: a line that is not ``NAME,VALUE``, a name that is not ArduPilot's
(upper case, digits and ``_``, at most 16 characters), a name of the families read here with a suffix
ArduPilot does not have (``ATC_RAT_RLL_PP``), or a value outside the documented range
(:data:`RANGES`, from the parameters' ``@Range`` in AC_AttitudeControl_Heli.cpp, AC_AttitudeControl.cpp,
AP_MotorsHeli.cpp, AP_InertialSensor.cpp) is a :class:`~controllers.firmware.errors.FirmwareParamError`.
Values a log holds are what the aircraft flew and are taken as they are.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from heli_core.files import write_text

from .ardupilot import ArduPilotHeliParams
from .errors import FirmwareParamError

AXES = ("RLL", "PIT", "YAW")
RATE_SUFFIXES = {"P": "rat_p", "I": "rat_i", "D": "rat_d", "FF": "rat_ff", "D_FF": "rat_d_ff", "IMAX": "rat_imax",
                 "ILMI": "rat_ilmi", "FLTT": "rat_fltt", "FLTE": "rat_flte", "FLTD": "rat_fltd"}
"""``ATC_RAT_<axis>_<suffix>`` read into the loop's fields."""
OTHER_RATE_SUFFIXES = {"SMAX", "NTF", "NEF", "PDMX", "VFF", "FILT"}
"""Suffixes ArduPilot has (or had) that the loop leaves out or reads through their old meaning."""
ACCEL_NAMES = ("ATC_ACCEL_R_MAX", "ATC_ACCEL_P_MAX", "ATC_ACCEL_Y_MAX")
_NAME = re.compile(r"^[A-Z][A-Z0-9_]{0,15}$")

RANGES = {
    **{f"ATC_ANG_{a}_P": ((3.0, 12.0) if a != "YAW" else (3.0, 6.0)) for a in AXES},
    **{f"ATC_RAT_{a}_P": ((0.0, 0.35) if a != "YAW" else (0.18, 0.6)) for a in AXES},
    **{f"ATC_RAT_{a}_I": ((0.0, 0.6) if a != "YAW" else (0.01, 0.2)) for a in AXES},
    **{f"ATC_RAT_{a}_D": ((0.0, 0.03) if a != "YAW" else (0.0, 0.02)) for a in AXES},
    **{f"ATC_RAT_{a}_FF": ((0.05, 0.5) if a != "YAW" else (0.0, 0.5)) for a in AXES},
    **{f"ATC_RAT_{a}_{s}": r for a in AXES for s, r in (("IMAX", (0.0, 1.0)), ("ILMI", (0.0, 1.0)),
                                                       ("D_FF", (0.0, 0.02)), ("FLTT", (0.0, 50.0)),
                                                       ("FLTE", (0.0, 50.0)), ("FLTD", (0.0, 50.0)))},
    "ATC_ACCEL_R_MAX": (0.0, 180000.0), "ATC_ACCEL_P_MAX": (0.0, 180000.0), "ATC_ACCEL_Y_MAX": (0.0, 72000.0),
    "ATC_INPUT_TC": (0.0, 1.0), "SCHED_LOOP_RATE": (50.0, 1000.0), "INS_GYRO_FILTER": (0.0, 256.0),
    "H_CYC_MAX": (0.0, 4500.0),
}
"""Documented range of each parameter read (``@Range``; the filters' 0 = off is allowed, the firmware takes it)."""

LEGACY_PID_SCALE = 1.27
"""ArduCopter 3.4's ``pid_scaler`` for heli rate gains (ArduCopter/Parameters.cpp convert_pid_parameters)."""
LEGACY_IMAX_SCALE = 1.0 / 4500.0


def _parse_float(text: str, where: str) -> float:
    try:
        v = float(text)
    except ValueError as e:
        raise FirmwareParamError(f"{where}: expected a number as the value, got {text.strip()!r}") from e
    if not math.isfinite(v):
        raise FirmwareParamError(f"{where}: expected a finite number as the value, got {text.strip()!r}")
    return v


def parse_param_text(text: str, name: str) -> dict:
    """``{NAME: value}`` of a parameter file's text (module docstring).

    Raises
    ------
    FirmwareParamError
        A malformed line (a Rotorflight/Betaflight CLI ``set`` line is named as such), or no parameter at all:
        taking every gain at its default would tune from gains the aircraft never flew.
    """
    values = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        where = f"{name} line {number}"
        if re.match(r"^set\s+[a-z]", line):
            raise FirmwareParamError(f"{where}: a Rotorflight CLI line ({raw.strip()!r}), not ArduPilot's "
                                     "'NAME,VALUE': tune Rotorflight gains with --firmware rotorflight")
        parts = [p for p in re.split(r"[,\s]+", line) if p]
        if len(parts) == 5 and parts[0].isdigit() and parts[1].isdigit():  # QGroundControl
            parts = parts[2:4]
        if len(parts) != 2:
            raise FirmwareParamError(f"{where}: expected 'NAME,VALUE', got {raw.strip()!r}")
        key = parts[0]
        if not _NAME.match(key):
            raise FirmwareParamError(f"{where}: {key!r} is not an ArduPilot parameter name (expected upper-case "
                                     "letters, digits and '_', at most 16 characters)")
        values[key] = _parse_float(parts[1], where)
    if not values:
        raise FirmwareParamError(f"{name}: no 'NAME,VALUE' line: expected an ArduPilot parameter file (Mission "
                                 "Planner, MAVProxy or QGroundControl)")
    return values


def _dataflash_values(path: Path) -> dict:
    from heli_core.errors import require

    dfreader = require("pymavlink.DFReader", "logs")
    try:
        f = dfreader.DFReader_binary(str(path), zero_time_base=False)
    except Exception as e:  # the parser's own failure on bad bytes: any exception type
        raise FirmwareParamError(f"{path}: pymavlink cannot read this DataFlash log ({type(e).__name__}: {e})") from e
    values = {}
    while True:
        m = f.recv_match(type=["PARM"])
        if m is None:
            break
        values[str(m.Name)] = float(m.Value)
    return values


def _text_log_values(text: str) -> dict:
    values = {}
    for line in text.splitlines():
        if line.startswith("PARM,"):
            parts = [p.strip() for p in line.split(",")]
            if len(parts) >= 3:
                try:
                    values[parts[1]] = float(parts[2])
                except ValueError:
                    continue
    return values


def read_ardupilot_values(path) -> tuple[dict, str]:
    """``({NAME: value}, kind)`` of a log's ``PARM`` messages (``kind`` "log") or a parameter file ("file").

    Raises
    ------
    FirmwareParamError
        A log without parameters, or a malformed parameter file.
    """
    path = Path(path)
    head = path.read_bytes()[:4096]
    if head.lstrip(b"\xff\x00").startswith(b"\xa3\x95"):
        values = _dataflash_values(path)
        kind = "log"
    else:
        text = head.decode("utf-8", errors="replace")
        if text.startswith("FMT,") or "\nFMT," in text[:200]:
            values = _text_log_values(path.read_text(encoding="utf-8", errors="replace"))
            kind = "log"
        else:
            try:
                full = path.read_text(encoding="utf-8")
            except UnicodeDecodeError as e:
                raise FirmwareParamError(f"{path}: not a DataFlash log nor a text parameter file "
                                         f"(undecodable bytes at {e.start})") from e
            return parse_param_text(full, str(path)), "file"
    if not values:
        raise FirmwareParamError(f"{path}: the log holds no parameter (PARM) messages; give the parameters the "
                                 "aircraft flew with --params FILE")
    return values, kind


def check_names(values: dict, source: str) -> None:
    """Refuse names of the families read here with a suffix ArduPilot does not have (module docstring)."""
    for key in values:
        m = re.match(r"^ATC_RAT_(RLL|PIT|YAW)_(.+)$", key)
        if m and m.group(2) not in RATE_SUFFIXES and m.group(2) not in OTHER_RATE_SUFFIXES:
            raise FirmwareParamError(f"{source}: unknown parameter {key!r}: ATC_RAT_{m.group(1)}_ takes "
                                     f"{', '.join(sorted(RATE_SUFFIXES) + sorted(OTHER_RATE_SUFFIXES))}")
        m = re.match(r"^ATC_ANG_(.+)$", key)
        if m and m.group(1) not in {f"{a}_P" for a in AXES} | {"LIM_TC"}:
            raise FirmwareParamError(f"{source}: unknown parameter {key!r}: expected ATC_ANG_RLL_P, ATC_ANG_PIT_P, "
                                     "ATC_ANG_YAW_P or ATC_ANG_LIM_TC")
        m = re.match(r"^ATC_ACCEL_(.+)$", key)
        if m and key not in ACCEL_NAMES and key != "ATC_ACCEL_RP_MAX":
            raise FirmwareParamError(f"{source}: unknown parameter {key!r}: expected one of {', '.join(ACCEL_NAMES)}")


def check_ranges(values: dict, source: str) -> None:
    """Refuse a value outside its documented range (:data:`RANGES`)."""
    for key, v in values.items():
        if key in RANGES:
            lo, hi = RANGES[key]
            if not lo <= v <= hi:
                raise FirmwareParamError(f"{source}: {key} = {v:g} is outside ArduPilot's documented range "
                                         f"[{lo:g}, {hi:g}]")


def _modern(values: dict) -> tuple[dict, list]:
    """Older names rewritten as the current ones (module docstring); the notes of what was converted."""
    v, notes = dict(values), []

    def convert(old, new, factor, why):
        if old in v and new not in v:
            v[new] = v[old] * factor
            notes.append(f"{new} = {v[new]:.6g} from the older {old} = {values[old]:.6g}{why}")

    for a, old_a in zip(AXES, ("RLL", "PIT", "YAW")):
        convert(f"STB_{old_a}_P", f"ATC_ANG_{a}_P", 1.0, "")
        for s in ("P", "I", "D", "FF"):
            convert(f"RATE_{old_a}_{s}", f"ATC_RAT_{a}_{s}", LEGACY_PID_SCALE,
                    " x 1.27 (ArduCopter 3.4's conversion to radians and +-1 outputs)")
        convert(f"RATE_{old_a}_IMAX", f"ATC_RAT_{a}_IMAX", LEGACY_IMAX_SCALE, " / 4500")
        convert(f"RATE_{old_a}_FILT_HZ", f"ATC_RAT_{a}_FLTE", 1.0, " (its one input filter)")
        convert(f"ATC_RAT_{a}_VFF", f"ATC_RAT_{a}_FF", 1.0, "")
        convert(f"ATC_RAT_{a}_FILT", f"ATC_RAT_{a}_FLTE", 1.0, "")
    convert("ATC_ACCEL_RP_MAX", "ATC_ACCEL_R_MAX", 1.0, "")
    convert("ATC_ACCEL_RP_MAX", "ATC_ACCEL_P_MAX", 1.0, "")
    convert("INS_MPU6K_FILTER", "INS_GYRO_FILTER", 1.0, "")
    if "H_CYC_MAX" not in v and ("H_ROL_MAX" in v or "H_PIT_MAX" in v):
        v["H_CYC_MAX"] = max(v.get("H_ROL_MAX", 0.0), v.get("H_PIT_MAX", 0.0))
        notes.append(f"H_CYC_MAX = {v['H_CYC_MAX']:g} from the older H_ROL_MAX/H_PIT_MAX")
    return v, notes


def ardupilot_params(values: dict, source: str, from_file: bool = False) -> tuple[ArduPilotHeliParams, list]:
    """The loop's parameters from ArduPilot's names, and one note per value taken from a default or converted.

    Parameters
    ----------
    values : dict
        ``{NAME: value}`` (:func:`read_ardupilot_values`).
    source : str
        Where they came from, for the messages.
    from_file : bool
        A file the user gave: unknown names of the families read here and values outside the documented
        ranges are refused (:class:`FirmwareParamError`).
    """
    check_names(values, source)
    if from_file:
        check_ranges(values, source)
    v, notes = _modern(values)
    default = ArduPilotHeliParams()
    kw = {}
    missing = []
    for suffix, field in RATE_SUFFIXES.items():
        row = []
        for i, a in enumerate(AXES):
            name = f"ATC_RAT_{a}_{suffix}"
            row.append(v.get(name, getattr(default, field)[i]))
            if name not in v:
                missing.append(name)
        kw[field] = tuple(row)
    kw["ang_p"] = tuple(v.get(f"ATC_ANG_{a}_P", default.ang_p[i]) for i, a in enumerate(AXES))
    missing += [f"ATC_ANG_{a}_P" for a in AXES if f"ATC_ANG_{a}_P" not in v]
    kw["accel_max"] = tuple(v.get(n, default.accel_max[i]) for i, n in enumerate(ACCEL_NAMES))
    missing += [n for n in ACCEL_NAMES if n not in v]
    for name, field in (("ATC_INPUT_TC", "input_tc"), ("SCHED_LOOP_RATE", "loop_rate_hz"),
                        ("INS_GYRO_FILTER", "gyro_filter_hz"), ("H_CYC_MAX", "cyc_max")):
        kw[field] = v.get(name, getattr(default, field))
        if name not in v:
            missing.append(name)
    if missing:
        notes.append(f"{len(missing)} parameter(s) not in {source}, taken at ArduPilot's heli defaults: "
                     + ", ".join(missing))
    try:
        return ArduPilotHeliParams(**kw), notes
    except ValueError as e:
        raise FirmwareParamError(f"{source}: {e}") from e


def ardupilot_names(params: ArduPilotHeliParams) -> dict:
    """``{NAME: value}`` of every parameter the loop models, in ArduPilot's names and units."""
    out = {}
    for i, a in enumerate(AXES):
        out[f"ATC_ANG_{a}_P"] = params.ang_p[i]
    for i, a in enumerate(AXES):
        for suffix, field in RATE_SUFFIXES.items():
            out[f"ATC_RAT_{a}_{suffix}"] = getattr(params, field)[i]
    for i, n in enumerate(ACCEL_NAMES):
        out[n] = params.accel_max[i]
    out.update({"ATC_INPUT_TC": params.input_tc, "SCHED_LOOP_RATE": params.loop_rate_hz,
                "INS_GYRO_FILTER": params.gyro_filter_hz, "H_CYC_MAX": params.cyc_max})
    return out


def clamp_to_ranges(values: dict) -> tuple[dict, list]:
    """Values limited to their documented ranges, and a note per value changed."""
    out, notes = dict(values), []
    for key, v in values.items():
        if key in RANGES:
            lo, hi = RANGES[key]
            c = min(max(v, lo), hi)
            if c != v:
                out[key] = c
                notes.append(f"{key} {v:.4g} is outside ArduPilot's documented range [{lo:g}, {hi:g}]: "
                             f"clamped to {c:.4g}")
    return out, notes


def write_ardupilot_param(path, values: dict, header: list = ()) -> Path:
    """Write ``NAME,VALUE`` lines (Mission Planner; MAVProxy's ``param load`` reads them too), atomically.

    ``header`` lines are written first as ``#`` comments.
    """
    lines = [f"# {h}" for h in header]
    lines += [f"{name},{_format(value)}" for name, value in values.items()]
    return write_text(path, "\n".join(lines) + "\n")


def _format(value: float) -> str:
    """A value as ArduPilot's tools show it: up to 6 significant digits, no exponent for ordinary numbers."""
    v = float(value)
    if v == int(v) and abs(v) < 1e7:
        return str(int(v))
    return f"{v:.6g}"
