"""The command scale between the firmware's output and the model's sticks, measured from the log where it can be.

The model's sticks are the inputs it was identified on (``flight.metadata["input_source"]``: the
firmware's own output, the pilot's sticks or the swash servos, :mod:`identification.io`). The firmware's
loop outputs its own units (ArduPilot: the rate controller's normalised output, logged as ``RATE.ROut``
…; Rotorflight: the PID sum in mixer units, logged as ``mixer[0..2]``). :func:`measure_scale` reads both from
the same log on the same grid and fits, per axis, ``stick − mean = s·(output − mean)`` by least squares
through the origin, with its R²: the scale [model stick per firmware unit] the loop multiplies its output
by. A model identified on the firmware's output itself has ``s = 1`` exactly — except on an ArduCopter <= 3.3
log, whose roll and pitch outputs the importer scales by ±5000 where the firmware's unit is ±4500
(:data:`LEGACY_FULL_SCALE`): there ``s = 0.9`` on roll and pitch. Where the log has no output
stream (a CSV flight, a log without ``RATE``/``mixer``), the scale is the stated default 1, which the user
overrides with ``heli tune --scale``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from heli_core.terms import AXES

from .errors import FirmwareMappingError

LEGACY_FULL_SCALE = 4500.0
"""ArduCopter <= 3.3's full-scale motor input for roll, pitch and yaw (AP_MotorsHeli ``move_swash``: "roll :
-4500 ~ 4500", the same for pitch and yaw), the unit the ±1 output of later versions replaced: ArduCopter 3.4's
``convert_pid_parameters`` scales the rate gains by 1.27 = (18000/π)/4500. The rate controller clamped its
roll and pitch output at ±5000 (``AC_ATTITUDE_RATE_RP_CONTROLLER_OUT_MAX``), which is what
:mod:`identification.io.ardupilot` divides ``RATE.ROut``/``POut`` by (``LEGACY_RP_SCALE``; yaw by 4500): on
such a log one imported unit is 5000/4500 of the firmware's output unit this loop flies in."""
DEFAULT_SCALE = 1.0
"""The scale used where none can be measured: the model's stick taken as the firmware's output unit."""
MIN_R2 = 0.5
"""Below this R² a measured scale is reported but not trusted: the default is used and a note says why."""


@dataclass(frozen=True)
class CommandScale:
    """The scale per axis and where it came from.

    Attributes
    ----------
    scale : tuple of 3 float
        Model stick per firmware output unit (roll, pitch, yaw), > 0.
    source : str
        ``"measured"``, ``"identity"`` (the model's input is the firmware's output), ``"default"`` or ``"user"``.
    detail : str
        One sentence: which streams, or why the default.
    r2 : tuple of 3 float or None
        R² of the fits (measured only).
    notes : tuple of str
    """

    scale: tuple
    source: str
    detail: str
    r2: tuple | None = None
    notes: tuple = field(default_factory=tuple)

    def __post_init__(self):
        s = np.broadcast_to(np.asarray(self.scale, dtype=float), (3,))
        if not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise FirmwareMappingError(f"the command scale must be 3 finite numbers > 0, got {s.tolist()}")
        object.__setattr__(self, "scale", tuple(float(v) for v in s))

    def to_dict(self) -> dict:
        return {**{a: s for a, s in zip(AXES, self.scale)}, "source": self.source, "detail": self.detail,
                "r2": None if self.r2 is None else dict(zip(AXES, self.r2)), "notes": list(self.notes)}


def user_scale(values) -> CommandScale:
    """The scale a user gave (one number for every axis or three)."""
    return CommandScale(values, "user", "given with --scale")


def default_scale(why: str) -> CommandScale:
    return CommandScale((DEFAULT_SCALE,) * 3, "default",
                        f"{why}; the default {DEFAULT_SCALE:g} (model stick per firmware unit) is used: give "
                        "--scale to override it")


def fit_scale(stick: np.ndarray, output: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per axis ``(s, R²)`` of ``stick − mean = s·(output − mean)``; inputs (3, n) on one grid."""
    u = stick - stick.mean(axis=1, keepdims=True)
    o = output - output.mean(axis=1, keepdims=True)
    oo = np.sum(o * o, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.sum(u * o, axis=1) / oo
        r2 = 1.0 - np.sum((u - s[:, None] * o) ** 2, axis=1) / np.sum(u * u, axis=1)
    return s, r2


def legacy_output_unit(mapping_note: str) -> tuple:
    """Model stick per firmware output unit of one imported ``controller`` unit, per axis: (0.9, 0.9, 1) where
    the importer read ArduCopter <= 3.3's ``RATE`` outputs (:data:`LEGACY_FULL_SCALE`; its mapping note names
    the divisor), else 1."""
    from identification.io.ardupilot import LEGACY_RP_SCALE, LEGACY_YAW_SCALE

    if f"ROut/{LEGACY_RP_SCALE:g}" not in mapping_note:
        return (1.0, 1.0, 1.0)
    return (LEGACY_FULL_SCALE / LEGACY_RP_SCALE,) * 2 + (LEGACY_FULL_SCALE / LEGACY_YAW_SCALE,)


def measure_scale(log_path, model_source: str | None) -> CommandScale:
    """The scale measured from ``log_path`` against the model's input source (module docstring).

    Parameters
    ----------
    log_path : path
        A flight-controller log (a CSV flight gives the default).
    model_source : str or None
        The input source the model was identified on (``flight.metadata["input_source"]``); None: the log's
        default source, as ``heli identify`` would take it.
    """
    from identification.errors import FlightLogError as LogError
    from identification.io import detect_format, read_log

    if detect_format(log_path) == "csv":
        return default_scale("a CSV flight logs no firmware output to measure the scale against")
    try:
        ctrl = read_log(log_path, inputs="controller")
    except LogError as e:
        return default_scale(f"the log has no firmware output stream to measure the scale against ({e})")
    source = model_source or read_log(log_path).metadata.get("input_source")
    note = ctrl.metadata.get("input_mapping", "")
    unit = legacy_output_unit(note)
    if source == "controller":
        if unit != (1.0, 1.0, 1.0):
            return CommandScale(unit, "identity", f"the model's sticks are the firmware's logged output ({note}); "
                                f"ArduCopter <= 3.3 logged it against a full scale of +-{LEGACY_FULL_SCALE:g}, so one "
                                f"imported unit is {unit[0]:.3g} of the output unit on roll and pitch")
        return CommandScale((1.0,) * 3, "identity", f"the model's sticks are the firmware's logged output ({note})")
    try:
        model = read_log(log_path, inputs=source)
    except LogError as e:
        return default_scale(f"the model's input source {source!r} cannot be read from the log ({e})")
    t0, t1 = max(ctrl.time[0], model.time[0]), min(ctrl.time[-1], model.time[-1])
    t = ctrl.time[(ctrl.time >= t0) & (ctrl.time <= t1)]
    n = t.size
    if n < 100:
        return default_scale(f"the log's {source} and firmware output overlap over {n} samples only")
    stick = np.vstack([np.interp(t, model.time, v) for v in (model.lat, model.lon, model.ped)])
    output = np.vstack([np.interp(t, ctrl.time, v) for v in (ctrl.lat, ctrl.lon, ctrl.ped)])
    s, r2 = fit_scale(stick, output)
    s = s * np.asarray(unit)  # per imported output unit -> per firmware output unit
    notes, scale = [], []
    for a, si, ri in zip(AXES, s, r2):
        if not (np.isfinite(si) and np.isfinite(ri)) or ri < MIN_R2 or si == 0:
            notes.append(f"{a}: the {source} against the firmware's output fit R² {ri:.2f} < {MIN_R2}: "
                         f"default {DEFAULT_SCALE:g} used")
            scale.append(DEFAULT_SCALE)
        else:
            if si < 0:
                notes.append(f"{a}: the {source} move against the firmware's output (s = {si:.3g}); its magnitude "
                             "is used, the sign comes from the model's control gain")
            scale.append(abs(float(si)))
    return CommandScale(tuple(scale), "measured", f"the model's {source} against the firmware's logged output "
                        f"({note}) over {n} samples", tuple(float(v) for v in r2), tuple(notes))
