"""The aircraft's sensors as identified from its flights: gyro noise, gyro vibration lines, attitude noise.

A :class:`SensorModel` is what ``model.json["sensors"]`` stores and what the environment, the PD sweep and
the flight tests measure through (:mod:`identification.sensors` identifies it). The gyro reads the body
rate plus white noise plus sinusoidal vibration lines (rotor harmonics and their aliases); the attitude
estimate reads the attitude plus white noise. Everything is per axis, in the paper's axes (roll, pitch, yaw).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .terms import AXES


@dataclass(frozen=True)
class GyroLine:
    """One vibration line of a gyro axis.

    Parameters
    ----------
    axis : str
        ``"roll"``, ``"pitch"`` or ``"yaw"``.
    frequency_hz : float
        Frequency as logged [Hz] (an aliased rotor harmonic appears at its alias).
    amplitude : float
        Amplitude of the sinusoid [rad/s].
    """

    axis: str
    frequency_hz: float
    amplitude: float

    def __post_init__(self):
        if self.axis not in AXES:
            raise ValueError(f"GyroLine.axis must be one of {AXES}, got {self.axis!r}")
        if not (math.isfinite(self.frequency_hz) and self.frequency_hz > 0):
            raise ValueError(f"GyroLine.frequency_hz must be a positive frequency in Hz, got {self.frequency_hz!r}")
        if not (math.isfinite(self.amplitude) and self.amplitude >= 0):
            raise ValueError(f"GyroLine.amplitude must be >= 0 rad/s, got {self.amplitude!r}")


@dataclass(frozen=True)
class SensorModel:
    """White noise and vibration lines of the gyros, white noise of the attitude estimate.

    Parameters
    ----------
    gyro_noise : tuple of 3 float
        Standard deviation of the gyros' white noise per axis [rad/s].
    attitude_noise : tuple of 3 float
        Standard deviation of the attitude estimate's white noise per axis [rad].
    gyro_lines : tuple of GyroLine
        Vibration lines on the gyros.
    """

    gyro_noise: tuple = (0.0, 0.0, 0.0)
    attitude_noise: tuple = (0.0, 0.0, 0.0)
    gyro_lines: tuple = ()

    def __post_init__(self):
        for name in ("gyro_noise", "attitude_noise"):
            v = tuple(float(x) for x in np.broadcast_to(np.asarray(getattr(self, name), dtype=float), (3,)))
            if not all(math.isfinite(x) and x >= 0 for x in v):
                raise ValueError(f"SensorModel.{name} must be 3 standard deviations >= 0, got {getattr(self, name)!r}")
            object.__setattr__(self, name, v)
        lines = tuple(line if isinstance(line, GyroLine) else GyroLine(**line) for line in self.gyro_lines)
        object.__setattr__(self, "gyro_lines", lines)

    @property
    def silent(self) -> bool:
        """No noise and no line: the measurement is the state."""
        return not (any(self.gyro_noise) or any(self.attitude_noise) or any(ln.amplitude for ln in self.gyro_lines))

    def line_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The lines as arrays: axis index (int), angular frequency [rad/s], amplitude [rad/s]."""
        return (np.array([AXES.index(ln.axis) for ln in self.gyro_lines], dtype=np.int64),
                np.array([2.0 * math.pi * ln.frequency_hz for ln in self.gyro_lines]),
                np.array([ln.amplitude for ln in self.gyro_lines]))

    def to_dict(self) -> dict:
        """The ``model.json["sensors"]`` entry."""
        return {"gyro_noise_rad_s": dict(zip(AXES, self.gyro_noise)),
                "attitude_noise_rad": dict(zip(AXES, self.attitude_noise)),
                "gyro_lines": [{"axis": ln.axis, "frequency_hz": ln.frequency_hz, "amplitude_rad_s": ln.amplitude}
                               for ln in self.gyro_lines]}

    @classmethod
    def from_dict(cls, doc) -> "SensorModel":
        """Read a ``model.json["sensors"]`` entry (:meth:`to_dict`); ``None`` is a model without sensors.

        Raises
        ------
        ValueError
            A missing axis, a negative or non-numeric level, a malformed line (the message says which).
        """
        if doc is None:
            return cls()
        if not isinstance(doc, dict):
            raise ValueError(f"'sensors' must be an object, got {type(doc).__name__}")

        def per_axis(key):
            value = doc.get(key, {})
            if not isinstance(value, dict) or set(value) - set(AXES):
                raise ValueError(f"'sensors.{key}' must be an object keyed by {', '.join(AXES)}, got {value!r}")
            return tuple(_number(value.get(a, 0.0), f"sensors.{key}.{a}") for a in AXES)

        lines = doc.get("gyro_lines", [])
        if not isinstance(lines, list):
            raise ValueError(f"'sensors.gyro_lines' must be a list, got {type(lines).__name__}")
        parsed = []
        for i, line in enumerate(lines):
            if not isinstance(line, dict) or {"axis", "frequency_hz", "amplitude_rad_s"} - set(line):
                raise ValueError(f"'sensors.gyro_lines[{i}]' must hold axis, frequency_hz, amplitude_rad_s; got {line!r}")
            parsed.append(GyroLine(line["axis"], _number(line["frequency_hz"], f"sensors.gyro_lines[{i}].frequency_hz"),
                                   _number(line["amplitude_rad_s"], f"sensors.gyro_lines[{i}].amplitude_rad_s")))
        return cls(per_axis("gyro_noise_rad_s"), per_axis("attitude_noise_rad"), tuple(parsed))


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"'{where}' must be a number, got {value!r}")
    return float(value)
