"""The parameters of the attitude model, eqs. (18) and (21), as one frozen dataclass.

:class:`ModelParams` holds the paper's parameters ``k1`` … ``k12``, the torque
offsets ``kd1`` … ``kd3``, the servo delay of each axis (eq. 31) and any
catalogue terms of :data:`heli_core.terms.EXTRA_PARAMS`. It is hashable, so the
physics core (:mod:`heli_core.physics`, :mod:`heli_core.discrete`) compiles
each parameter set once and caches it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from .terms import BASE_PARAMS, EXTRA_PARAMS, TERMS

SERVO_FIELDS = ("tau_roll", "tau_pitch", "tau_yaw", "lag_roll", "lag_pitch", "lag_yaw")
"""The servo's parameters per axis: transport delay and first-order lag [s] (eq. 31)."""


@dataclass(frozen=True)
class ModelParams:
    """Parameters of the coupled attitude model, eqs. (18) and (21).

    All fields default to 0, so a decoupled model simply leaves the coupling
    terms at zero. Names and signs follow the paper.

    Attributes
    ----------
    k1, k5, k9 : float
        Gyroscopic inertia ratios [-] (eqs. 19, 22, 23).
    k2, k6, k10 : float
        Control effectiveness of lateral cyclic, longitudinal cyclic and pedal
        [rad/s^2 per unit stick].
    k3, k7, k11 : float
        Damping of roll, pitch and yaw [1/s].
    k4, k8 : float
        Flybar cross-coupling (``+k4*q`` in roll, ``-k8*p`` in pitch) [1/s].
    k12 : float
        Main-rotor reaction torque per unit collective, entering as ``-k12*col``
        [rad/s^2].
    kd1, kd2, kd3 : float
        Constant torque offsets [rad/s^2].
    tau_roll, tau_pitch, tau_yaw : float
        Servo transport delay per axis [s], modelled by the first-order Padé
        approximation of eq. (31); 0 means no delay.
    lag_roll, lag_pitch, lag_yaw : float
        Servo first-order lag per axis [s] (the servo's time constant), added to
        the denominator of eq. (31): ``(1 - s tau/2) / (1 + s (tau/2 + lag))``
        (:func:`heli_core.servo.servo_coefficients`); 0 means none.
    extra : tuple of (str, float)
        Added catalogue terms (:data:`heli_core.terms.EXTRA_PARAMS`) and
        their values, e.g. ``(("nld1", 0.2),)``.

    Raises
    ------
    ValueError
        A parameter that is not a finite number, a delay outside [0, 2] s, a lag
        outside [0, 1] s, or an unknown or repeated extra term.
    """

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    kd1: float = 0.0
    k5: float = 0.0
    k6: float = 0.0
    k7: float = 0.0
    k8: float = 0.0
    kd2: float = 0.0
    k9: float = 0.0
    k10: float = 0.0
    k11: float = 0.0
    k12: float = 0.0
    kd3: float = 0.0
    tau_roll: float = 0.0
    tau_pitch: float = 0.0
    tau_yaw: float = 0.0
    extra: tuple = field(default=())
    lag_roll: float = 0.0
    lag_pitch: float = 0.0
    lag_yaw: float = 0.0

    def __post_init__(self):
        for name in BASE_PARAMS + SERVO_FIELDS:
            v = getattr(self, name)
            if (isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.floating, np.integer))
                    or not math.isfinite(float(v))):
                raise ValueError(f"parameter {name} must be a finite number, got {v!r}")
            object.__setattr__(self, name, float(v))
        for name in ("tau_roll", "tau_pitch", "tau_yaw"):
            if not 0.0 <= getattr(self, name) <= 2.0:
                raise ValueError(f"{name} must be a delay in [0, 2] s, got {getattr(self, name)}")
        for name in ("lag_roll", "lag_pitch", "lag_yaw"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be a servo time constant in [0, 1] s, got {getattr(self, name)}")
        extra = tuple((str(k), float(v)) for k, v in dict(self.extra).items())
        if len(extra) != len(self.extra):
            raise ValueError(f"extra terms must have unique names, got {[k for k, _ in self.extra]}")
        for k, v in extra:
            if k not in EXTRA_PARAMS:
                raise ValueError(f"unknown extra term {k!r}; known: {', '.join(EXTRA_PARAMS)}")
            if not math.isfinite(v):
                raise ValueError(f"extra term {k} must be finite, got {v}")
        object.__setattr__(self, "extra", tuple(sorted(extra)))

    # ------------------------------------------------------------------ access
    @property
    def taus(self) -> tuple[float, float, float]:
        """Servo delays (roll, pitch, yaw) [s]."""
        return (self.tau_roll, self.tau_pitch, self.tau_yaw)

    @property
    def lags(self) -> tuple[float, float, float]:
        """Servo first-order lags (roll, pitch, yaw) [s]."""
        return (self.lag_roll, self.lag_pitch, self.lag_yaw)

    @property
    def control_gains(self) -> np.ndarray:
        """(k2, k6, k10): torque per unit stick on each axis [rad/s^2]."""
        return np.array([self.k2, self.k6, self.k10])

    def values(self) -> dict[str, float]:
        """All term parameters (base and extra) by name."""
        out = {name: getattr(self, name) for name in BASE_PARAMS}
        out.update(dict(self.extra))
        return out

    def get(self, name: str) -> float:
        """Value of a base or extra parameter; 0 for an extra term not in the model."""
        if name in BASE_PARAMS or name in SERVO_FIELDS:
            return getattr(self, name)
        if name not in TERMS:
            raise KeyError(f"unknown parameter {name!r}")
        return dict(self.extra).get(name, 0.0)

    def with_values(self, **values) -> "ModelParams":
        """A copy with some parameters replaced; extra-term names add or replace terms."""
        base = {k: v for k, v in values.items() if k in BASE_PARAMS or k in SERVO_FIELDS}
        extra = dict(self.extra)
        for k, v in values.items():
            if k not in base:
                if k not in EXTRA_PARAMS:
                    raise KeyError(f"unknown parameter {k!r}")
                extra[k] = v
        return dataclasses.replace(self, **base, extra=tuple(extra.items()))
