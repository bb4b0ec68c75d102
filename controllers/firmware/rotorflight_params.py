"""Rotorflight's pid_mode 3 parameters: read from a blackbox header or a CLI file, checked, written back.

Where they come from (:func:`read_rotorflight_values`):

* a Rotorflight blackbox log: its header lines ``H name:value`` — ``rollPID``/``pitchPID``/``yawPID``
  (P, I, D and, where the firmware logs them, F, B, O), ``looptime`` [µs] and ``pid_process_denom`` (the
  PID loop's rate is ``1e6/(looptime·pid_process_denom)``), ``gyro_lpf1_static_hz`` and any profile setting
  the header carries under its CLI name (``angle_level_strength``, ``error_limit``, ``roll_d_cutoff`` ...);
* a CLI file: ``set name = value`` lines as ``diff``/``dump`` print them (arrays as ``a,b,c``), ``#``
  comments; where ``profile N`` lines separate several PID profiles, profile 0's settings are read.

:func:`rotorflight_params` turns them into :class:`~controllers.firmware.rotorflight.RotorflightParams`; a
setting missing from the source takes Rotorflight's default (src/main/pg/pid.c) and a note says so. A CLI
file the user gives is checked: a ``set`` line that is not ``set name = value``, an unknown
``roll_/pitch_/yaw_..._gain`` or ``..._cutoff`` name, or a value outside the range of the CLI's settings
table (src/main/cli/settings.c: gains 0…``PID_GAIN_MAX`` = 1000, cutoffs 0…250, stop gains 25…250,
``angle_level_strength`` 0…200, ``angle_level_limit`` 10…90) is a
:class:`~controllers.firmware.errors.FirmwareParamError`.
"""

from __future__ import annotations

import re
from pathlib import Path

from heli_core.files import write_text

from .errors import FirmwareParamError
from .rotorflight import RotorflightParams

AXES = ("roll", "pitch", "yaw")
TERMS = ("p", "i", "d", "f", "b", "o")
GAIN_NAMES = {f"{a}_{t}_gain" for a in AXES for t in TERMS} | {
    "yaw_cw_stop_gain", "yaw_ccw_stop_gain", "yaw_cyclic_ff_gain", "yaw_collective_ff_gain",
    "yaw_inertia_precomp_gain", "pitch_collective_ff_gain"}
CUTOFF_NAMES = {f"{a}_{k}_cutoff" for a in AXES for k in ("d", "b", "gyro")} | {
    "yaw_precomp_cutoff", "yaw_inertia_precomp_cutoff"}
RANGES = {
    **{n: (0.0, 1000.0) for n in (f"{a}_{t}_gain" for a in AXES for t in TERMS)},
    **{n: (0.0, 250.0) for n in CUTOFF_NAMES},
    "yaw_cw_stop_gain": (25.0, 250.0), "yaw_ccw_stop_gain": (25.0, 250.0),
    "angle_level_strength": (0.0, 200.0), "angle_level_limit": (10.0, 90.0),
    "error_decay_time_cyclic": (0.0, 250.0), "error_decay_limit_cyclic": (0.0, 250.0),
    "error_decay_time_yaw": (0.0, 250.0), "error_decay_limit_yaw": (0.0, 250.0),
    "error_limit": (0.0, 255.0), "iterm_relax_level": (10.0, 250.0), "iterm_relax_cutoff": (1.0, 100.0),
    "pid_process_denom": (1.0, 16.0), "gyro_lpf1_static_hz": (0.0, 4000.0),
}
"""Range of each setting read (settings.c ``minmaxUnsigned``; arrays element by element)."""
GYRO_RATE_HZ = 8000.0
"""Gyro rate assumed when a CLI file gives ``pid_process_denom`` without the gyro's looptime."""


def _number_list(text: str, where: str) -> list:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError as e:
        raise FirmwareParamError(f"{where}: expected a number or numbers separated by ',', got {text.strip()!r}") from e


_ARDUPILOT_LINE = re.compile(r"^[A-Z][A-Z0-9_]{0,15}\s*[,\s]\s*[-+0-9.eE]+$")
"""A line of an ArduPilot parameter file (``NAME,VALUE`` or ``NAME VALUE``), refused in a Rotorflight file."""


def parse_cli_text(text: str, name: str) -> dict:
    """``{name: value or list}`` of a CLI file's ``set`` lines (profile 0 where profiles are given).

    Raises
    ------
    FirmwareParamError
        A malformed ``set`` line, or a text without any ``set`` line: an ArduPilot parameter file (its
        ``NAME,VALUE`` lines are named) or no settings at all. Taking every setting at its default would tune
        from gains the aircraft never flew.
    """
    values, profile, sets, foreign = {}, 0, 0, None
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        where = f"{name} line {number}"
        if foreign is None and _ARDUPILOT_LINE.match(line):
            foreign = (number, line)
        m = re.match(r"^profile\s+(\d+)$", line)
        if m:
            profile = int(m.group(1))
            continue
        if not line.startswith("set ") and line != "set":
            continue  # save, diff headers, board_name, other CLI commands: not settings
        m = re.match(r"^set\s+([a-z][a-z0-9_]*)\s*=\s*(\S.*)$", line)
        if not m:
            raise FirmwareParamError(f"{where}: expected 'set name = value', got {raw.strip()!r}")
        sets += 1
        if profile != 0:
            continue
        key, value = m.group(1), m.group(2).strip()
        parts = _number_list(value, where) if re.match(r"^[-0-9.,\s]+$", value) else None
        values[key] = value if parts is None else (parts[0] if len(parts) == 1 else parts)
    if not sets:
        if foreign is not None:
            raise FirmwareParamError(f"{name}: an ArduPilot parameter file (line {foreign[0]}: {foreign[1]!r}), not a "
                                     "Rotorflight CLI file: tune ArduPilot gains with --firmware ardupilot, or give "
                                     "the CLI's 'diff' ('set name = value' lines)")
        raise FirmwareParamError(f"{name}: no 'set name = value' line: expected a Rotorflight CLI 'diff' or 'dump'")
    return values


def _header_values(text: str) -> dict:
    """The header's ``H name:value`` lines as CLI-named settings (module docstring)."""
    raw = {}
    for line in text.splitlines():
        if line.startswith("H ") and ":" in line:
            key, value = line[2:].split(":", 1)
            raw[key.strip()] = value.strip()
    out = {}
    for axis in AXES:
        pid = raw.get(f"{axis}PID")
        if pid:
            for term, v in zip(TERMS, pid.split(",")):
                try:
                    out[f"{axis}_{term}_gain"] = float(v)
                except ValueError:
                    continue
    for key, value in raw.items():
        if re.match(r"^[a-z][a-z0-9_]*$", key) and key not in out:
            try:
                parts = [float(v) for v in value.split(",")]
            except ValueError:
                continue
            out[key] = parts[0] if len(parts) == 1 else parts
    if "looptime" in out and "pid_process_denom" in out and out["looptime"] > 0:
        out["pid_rate_hz"] = 1e6 / (out["looptime"] * out["pid_process_denom"])
    out["_firmware"] = raw.get("Firmware revision", raw.get("Firmware type", ""))
    return out


def read_rotorflight_values(path) -> tuple[dict, str]:
    """``(settings, kind)`` of a blackbox header (``kind`` "log") or a CLI file ("file").

    Raises
    ------
    FirmwareParamError
        A log whose header is not Rotorflight's or holds no PID gains, or a malformed CLI file.
    """
    path = Path(path)
    data = path.read_bytes()
    head = data[:200000].decode("latin-1")
    if head.lstrip("\xff\x00").startswith("H Product:Blackbox"):
        values = _header_values(head)
        if "Rotorflight" not in values.get("_firmware", "") and "Rotorflight" not in head[:4000]:
            raise FirmwareParamError(f"{path}: a blackbox log, but not Rotorflight's (firmware "
                                     f"{values.get('_firmware') or 'unnamed'}): its gains are not pid_mode 3's")
        if not any(k.endswith("_p_gain") for k in values):
            raise FirmwareParamError(f"{path}: the blackbox header holds no rollPID/pitchPID/yawPID line; give the "
                                     "gains the aircraft flew with --params FILE (a CLI 'diff')")
        return values, "log"
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise FirmwareParamError(f"{path}: not a blackbox log nor a Rotorflight CLI text file (undecodable "
                                 f"bytes at {e.start})") from e
    return parse_cli_text(text, str(path)), "file"


def check_names(values: dict, source: str) -> None:
    """Refuse an unknown ``roll_/pitch_/yaw_..._gain`` or ``..._cutoff`` name."""
    for key in values:
        if re.match(r"^(roll|pitch|yaw)_.*_gain$", key) and key not in GAIN_NAMES:
            raise FirmwareParamError(f"{source}: unknown setting {key!r}: the axis gains are "
                                     "<axis>_{p,i,d,f,b,o}_gain and the yaw stop and precomp gains")
        if re.match(r"^(roll|pitch|yaw)_.*_cutoff$", key) and key not in CUTOFF_NAMES:
            raise FirmwareParamError(f"{source}: unknown setting {key!r}: the axis cutoffs are "
                                     "<axis>_{d,b,gyro}_cutoff and the yaw precomp cutoffs")


def check_ranges(values: dict, source: str) -> None:
    """Refuse a value outside the CLI's range (:data:`RANGES`)."""
    for key, v in values.items():
        if key not in RANGES:
            continue
        lo, hi = RANGES[key]
        for x in (v if isinstance(v, list) else [v]):
            if isinstance(x, str) or not lo <= x <= hi:
                raise FirmwareParamError(f"{source}: {key} = {v} is outside Rotorflight's range [{lo:g}, {hi:g}]")


def _axes(values: dict, name: str, default: tuple, missing: list) -> tuple:
    out = []
    for i, a in enumerate(AXES):
        key = name.format(a)
        if key in values:
            out.append(float(values[key]))
        else:
            out.append(default[i])
            missing.append(key)
    return tuple(out)


def _array(values: dict, name: str, default: tuple, missing: list) -> tuple:
    v = values.get(name)
    if v is None:
        missing.append(name)
        return default
    v = v if isinstance(v, list) else [v]
    return tuple(float(v[i]) if i < len(v) else default[i] for i in range(3))


def rotorflight_params(values: dict, source: str, from_file: bool = False) -> tuple[RotorflightParams, list]:
    """The loop's parameters from Rotorflight's settings, and one note per setting taken from a default.

    ``from_file``: a file the user gave, checked (module docstring).
    """
    check_names(values, source)
    if from_file:
        check_ranges(values, source)
    d = RotorflightParams()
    missing: list = []
    kw = {t: _axes(values, "{}_" + t + "_gain", getattr(d, t), missing) for t in ("p", "i", "d", "f", "b")}
    for field, name in (("d_cutoff", "{}_d_cutoff"), ("b_cutoff", "{}_b_cutoff"), ("gyro_cutoff", "{}_gyro_cutoff")):
        kw[field] = _axes(values, name, getattr(d, field), missing)
    kw["error_limit"] = _array(values, "error_limit", d.error_limit, missing)
    kw["relax_level"] = _array(values, "iterm_relax_level", d.relax_level, missing)
    kw["relax_cutoff"] = _array(values, "iterm_relax_cutoff", d.relax_cutoff, missing)
    for field, name in (("level_strength", "angle_level_strength"), ("level_limit", "angle_level_limit"),
                        ("decay_time_cyclic", "error_decay_time_cyclic"),
                        ("decay_limit_cyclic", "error_decay_limit_cyclic"), ("decay_time_yaw", "error_decay_time_yaw"),
                        ("decay_limit_yaw", "error_decay_limit_yaw"), ("yaw_cw_stop_gain", "yaw_cw_stop_gain"),
                        ("yaw_ccw_stop_gain", "yaw_ccw_stop_gain"), ("gyro_lpf1_hz", "gyro_lpf1_static_hz")):
        if name in values and not isinstance(values[name], (list, str)):
            kw[field] = float(values[name])
        else:
            missing.append(name)
    relax = values.get("iterm_relax_type")
    if isinstance(relax, str):
        kw["relax"] = relax.upper() not in ("OFF", "0")
    notes = []
    if "pid_rate_hz" in values:
        kw["loop_rate_hz"] = float(values["pid_rate_hz"])
    elif "pid_process_denom" in values:
        kw["loop_rate_hz"] = GYRO_RATE_HZ / float(values["pid_process_denom"])
        notes.append(f"PID loop rate {kw['loop_rate_hz']:g} Hz from pid_process_denom and an assumed "
                     f"{GYRO_RATE_HZ:g} Hz gyro")
    else:
        missing.append("pid_process_denom")
    if missing:
        notes.append(f"{len(missing)} setting(s) not in {source}, taken at Rotorflight's defaults: "
                     + ", ".join(missing))
    try:
        return RotorflightParams(**kw), notes
    except ValueError as e:
        raise FirmwareParamError(f"{source}: {e}") from e


def rotorflight_names(params: RotorflightParams) -> dict:
    """``{name: value}`` of every setting the loop models, in the CLI's names (arrays as lists)."""
    out = {}
    for t in ("p", "i", "d", "f", "b"):
        for i, a in enumerate(AXES):
            out[f"{a}_{t}_gain"] = getattr(params, t)[i]
    for field, name in (("d_cutoff", "{}_d_cutoff"), ("b_cutoff", "{}_b_cutoff"), ("gyro_cutoff", "{}_gyro_cutoff")):
        for i, a in enumerate(AXES):
            out[name.format(a)] = getattr(params, field)[i]
    out.update({"angle_level_strength": params.level_strength, "angle_level_limit": params.level_limit,
                "error_limit": list(params.error_limit), "error_decay_time_cyclic": params.decay_time_cyclic,
                "error_decay_limit_cyclic": params.decay_limit_cyclic, "error_decay_time_yaw": params.decay_time_yaw,
                "error_decay_limit_yaw": params.decay_limit_yaw, "yaw_cw_stop_gain": params.yaw_cw_stop_gain,
                "yaw_ccw_stop_gain": params.yaw_ccw_stop_gain, "iterm_relax_level": list(params.relax_level),
                "iterm_relax_cutoff": list(params.relax_cutoff)})
    return out


def clamp_to_ranges(values: dict) -> tuple[dict, list]:
    """Values rounded to the firmware's integers and limited to the CLI's ranges; a note per value changed."""
    out, notes = {}, []
    for key, v in values.items():
        lo, hi = RANGES.get(key, (float("-inf"), float("inf")))
        items = v if isinstance(v, list) else [v]
        done = [int(round(min(max(x, lo), hi))) for x in items]
        if any(min(max(x, lo), hi) != x for x in items):
            notes.append(f"{key} {v} is outside Rotorflight's range [{lo:g}, {hi:g}]: set to "
                         f"{done if isinstance(v, list) else done[0]}")
        out[key] = done if isinstance(v, list) else done[0]
    return out, notes


def write_rotorflight_cli(path, values: dict, header: list = ()) -> Path:
    """Write CLI ``set name = value`` lines and ``save``, atomically (paste them into the CLI tab).

    ``header`` lines are written first as ``#`` comments.
    """
    lines = [f"# {h}" for h in header]
    for key, v in values.items():
        text = ",".join(str(int(x)) for x in v) if isinstance(v, list) else str(int(v))
        lines.append(f"set {key} = {text}")
    lines.append("save")
    return write_text(path, "\n".join(lines) + "\n")
