"""What ``heli tune`` needs to know of each firmware: its loop, its parameters, its files, the gains it sweeps.

:data:`FIRMWARES` maps ``"ardupilot"`` and ``"rotorflight"`` to a :class:`FirmwareSpec`. The sweep is the
firmware's own (issue 32):

* ArduPilot, per axis: ``ATC_ANG_*_P`` (its documented range, 3…12; yaw 3…6) × ``ATC_RAT_*_P`` (0…0.35;
  yaw 0.18…0.6), with ``ATC_RAT_*_FF`` set from the model: the output per rate target that holds the
  target rate in steady state, ``FF = k_damp/(s·|k|)`` (k3/k2, k7/k6, k11/k10 over the command scale ``s``:
  a stick ``u`` holds the rate ``(k/k_damp)·u``), limited to FF's documented range;
* Rotorflight: ``{roll,pitch}_p_gain`` × ``angle_level_strength`` (one setting for both axes, so roll and
  pitch are chosen together) with ``*_f_gain`` set from the model the same way
  (``F = (π/180)·k_damp/(s·|k|)/2.5e-5``); yaw ``yaw_p_gain`` × ``yaw_i_gain`` (the tail holds heading by
  its I-term; the stop gains are kept).

The other gains (I, D, filters, limits) stay as the aircraft flew them. The firmware's *default* gains keep
the aircraft's loop rate, gyro filter and cyclic limit (hardware settings, not gains).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from . import ardupilot_params as ap_io
from . import rotorflight_params as rf_io
from .ardupilot import ArduPilotHeli, ArduPilotHeliParams
from .rotorflight import SCALES, Rotorflight, RotorflightParams

DAMPING = ("k3", "k7", "k11")
"""The model's damping per axis [1/s] (eqs. 18, 21)."""


def steady_rate_gain(model_params, axis: int, scale: float) -> float:
    """Body rate per firmware output unit in steady state [(rad/s) per unit]: ``s·|k|/k_damp``; inf without damping."""
    k = abs(float(model_params.control_gains[axis]))
    damp = float(getattr(model_params, DAMPING[axis]))
    return math.inf if damp <= 0 else scale * k / damp


def _sig(value: float, digits: int = 4) -> float:
    """``value`` rounded to ``digits`` significant digits (as a parameter file would hold it)."""
    v = float(value)
    return v if v == 0.0 else float(f"{v:.{digits - 1}e}")


@dataclass(frozen=True)
class FirmwareSpec:
    """One firmware as ``heli tune`` handles it (module docstring).

    Attributes
    ----------
    name : str
    loop_class : type
    filename : str
        The file ``heli tune`` writes the proposed gains to.
    swept : tuple of 3 tuples of 2 str
        Per axis, the names of the two swept parameters (for reports).
    joint : tuple of tuples of int
        Axes chosen together (Rotorflight's roll and pitch share ``angle_level_strength``).
    """

    name: str
    loop_class: type
    filename: str
    swept: tuple
    joint: tuple

    # ----------------------------------------------------------------------------- files
    def read(self, path):
        return (ap_io.read_ardupilot_values if self.name == "ardupilot" else rf_io.read_rotorflight_values)(path)

    def params_from(self, values: dict, source: str, from_file: bool):
        fn = ap_io.ardupilot_params if self.name == "ardupilot" else rf_io.rotorflight_params
        return fn(values, source, from_file)

    def gains(self, path):
        """``(parameters, notes)`` of the gains in ``path``: the firmware's parameter file, or its log (whose
        parameters are read); refused with :class:`~controllers.firmware.errors.FirmwareParamError` saying why."""
        values, kind = self.read(path)
        return self.params_from(values, str(path), from_file=(kind == "file"))

    def names(self, params) -> dict:
        return (ap_io.ardupilot_names if self.name == "ardupilot" else rf_io.rotorflight_names)(params)

    def clamp(self, values: dict):
        return (ap_io.clamp_to_ranges if self.name == "ardupilot" else rf_io.clamp_to_ranges)(values)

    def write(self, path, values: dict, header=()):
        fn = ap_io.write_ardupilot_param if self.name == "ardupilot" else rf_io.write_rotorflight_cli
        return fn(path, values, header)

    # ----------------------------------------------------------------------------- gains
    def defaults(self, current):
        """The firmware's default gains with the aircraft's hardware settings (loop rate, gyro filter, limits)."""
        if self.name == "ardupilot":
            return replace(ArduPilotHeliParams(), loop_rate_hz=current.loop_rate_hz,
                           gyro_filter_hz=current.gyro_filter_hz, cyc_max=current.cyc_max)
        return replace(RotorflightParams(), loop_rate_hz=current.loop_rate_hz, gyro_lpf1_hz=current.gyro_lpf1_hz,
                       output_limit=current.output_limit)

    def axis_gains(self, params, axis: int) -> dict:
        """The firmware's own names and values of one axis' gains (for tune.json and the report)."""
        names = self.names(params)
        if self.name == "ardupilot":
            a = ap_io.AXES[axis]
            keys = [f"ATC_ANG_{a}_P"] + [f"ATC_RAT_{a}_{s}" for s in ("P", "I", "D", "FF", "IMAX", "ILMI")]
            return {k: names[k] for k in keys}
        a = rf_io.AXES[axis]
        out = {f"{a}_{t}_gain": names[f"{a}_{t}_gain"] for t in ("p", "i", "d", "f", "b")}
        if axis < 2:
            out["angle_level_strength"] = names["angle_level_strength"]
        else:
            out.update({"yaw_cw_stop_gain": names["yaw_cw_stop_gain"], "yaw_ccw_stop_gain": names["yaw_ccw_stop_gain"]})
        return out

    def feed_forward(self, model_params, axis: int, scale: float) -> float:
        """The feed-forward gain that holds a rate target in steady state, in the firmware's units (unclamped)."""
        g = steady_rate_gain(model_params, axis, scale)
        if self.name == "ardupilot":
            return 0.0 if math.isinf(g) else 1.0 / g
        per_deg = 0.0 if math.isinf(g) else (math.pi / 180.0) / g  # mixer units per deg/s
        return per_deg / SCALES["f"][axis]

    def grid(self, axis: int) -> tuple[np.ndarray, np.ndarray]:
        """The two swept gains' values on ``axis`` (firmware units)."""
        if self.name == "ardupilot":
            if axis < 2:
                return np.geomspace(3.0, 12.0, 10), np.geomspace(0.005, 0.35, 12)
            return np.geomspace(3.0, 6.0, 6), np.geomspace(0.18, 0.6, 8)
        if axis < 2:
            return (np.unique(np.round(np.geomspace(10, 1000, 12))), np.unique(np.round(np.geomspace(5, 200, 10))))
        return np.unique(np.round(np.geomspace(10, 1000, 10))), np.unique(np.round(np.geomspace(5, 1000, 8)))

    def candidate(self, base, axis: int, a: float, b: float, ff: float):
        """``base`` with ``axis``' two swept gains set to ``(a, b)`` and its feed-forward to ``ff``."""
        def put(tup, value):
            row = list(tup)
            row[axis] = float(value)
            return tuple(row)

        if self.name == "ardupilot":  # 4 significant digits: the values the file holds are the ones flown
            lo = 0.05 if axis < 2 else 0.0
            return replace(base, ang_p=put(base.ang_p, _sig(a)), rat_p=put(base.rat_p, _sig(b)),
                           rat_ff=put(base.rat_ff, _sig(min(max(ff, lo), 0.5))))
        if axis < 2:
            return replace(base, p=put(base.p, a), level_strength=float(b),
                           f=put(base.f, float(min(max(round(ff), 0), 1000))))
        return replace(base, p=put(base.p, a), i=put(base.i, b))

    def merge(self, base, source, axes) -> object:
        """``base`` with the gains of ``axes`` taken from ``source`` (Rotorflight's level strength with roll)."""
        def mix(name):
            row = list(getattr(base, name))
            for i in axes:
                row[i] = getattr(source, name)[i]
            return tuple(row)

        if self.name == "ardupilot":
            return replace(base, **{n: mix(n) for n in ("ang_p", "rat_p", "rat_ff", "rat_i", "rat_d")})
        kw = {n: mix(n) for n in ("p", "i", "d", "f", "b")}
        if 0 in axes or 1 in axes:
            kw["level_strength"] = source.level_strength
        return replace(base, **kw)


FIRMWARES = {
    "ardupilot": FirmwareSpec("ardupilot", ArduPilotHeli, "ardupilot.param",
                              tuple((f"ATC_ANG_{a}_P", f"ATC_RAT_{a}_P") for a in ap_io.AXES),
                              ((0,), (1,), (2,))),
    "rotorflight": FirmwareSpec("rotorflight", Rotorflight, "rotorflight.txt",
                                (("roll_p_gain", "angle_level_strength"), ("pitch_p_gain", "angle_level_strength"),
                                 ("yaw_p_gain", "yaw_i_gain")), ((0, 1), (2,))),
}
"""The firmwares ``heli tune`` knows (module docstring)."""
