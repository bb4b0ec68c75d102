"""The LQG design model of one axis: the identified airframe, its gust model and its sensors, sampled.

Per axis (roll, pitch, yaw) the model the estimator and the regulator are designed on is::

    rate'  = a_rate rate + b_servo servo + b_u u + (w_1 + w_2)         eqs. (18), (21), (31)
    servo' = a_servo servo + b_servo' u                                Padé servo of eq. (31), if identified
    angle' = rate                                                      eq. (25) at level flight
    gust states w: the identified wind model (eqs. 41-42 with the ML estimator's Gauss-Markov wind)
    y = (angle + v_angle,  rate + lines + v_gyro)

* the airframe: the axis' own block of the package's one hover linearisation
  (:func:`heli_core.linear.hover_linearisation`, the PD design's too: the coupling terms are left out,
  a per-axis design on the decoupled part), at the library's mean collective;
* the gust: the wind model the maximum-likelihood identification fitted on this axis
  (``model.json["fit_statistics"]["axes"][axis]["wind"]``, :class:`WindModel`): a slow plus a fast
  first-order Gauss-Markov torque (``"gm2"``) or a slow first-order plus a fast second-order one
  (``"gm_so"``), their states taken from the identification's own definition
  (:func:`identification.likelihood.state_space.wind_block`) and scaled to the fitted torque levels [rad/s²];
* the sensors: the identified white noise of the attitude estimate and the gyro
  (``model.json["sensors"]``) as the measurement noise, and each of the gyro's vibration lines as a
  lightly damped oscillator state at its frequency (the environment draws each line's phase per episode;
  an estimator that knows the frequency removes it rather than passing it to the stick).

The continuous part (airframe and gust) is sampled at the control period: the input by a zero-order hold
(``control.c2d``, the environment holds its action over the period), the gust's white noise by Van Loan's
method. The lines are discrete from the start (a rotation by ``2 pi f dt`` per period, which aliases as
the samples do).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from heli_core.config import is_real
from heli_core.linear import hover_linearisation
from heli_core.terms import AXES

from ..errors import DesignError

WIND_KINDS = ("gm2", "gm_so")
"""Gust models the design takes: those the maximum-likelihood identification fits
(:data:`identification.likelihood.state_space.WIND_MODELS`)."""
LINE_COHERENCE_S = 2.0
"""Time constant [s] over which the estimator lets a gyro line's amplitude and phase wander (its oscillator
decays by ``exp(-dt / LINE_COHERENCE_S)`` per period, driven so that its stationary amplitude is the
identified one). The environment's lines never wander; a finite coherence keeps the filter's Riccati
equation well posed and lets the estimate lock on within a few seconds."""
MIN_NOISE = 1e-5
"""Floor of the measurement noise standard deviations [rad, rad/s]: a model identified without sensors
measures the state exactly, which the Kalman filter's Riccati equation cannot take."""


def _axis_name(axis) -> str:
    if isinstance(axis, str) and axis in AXES:
        return axis
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and 0 <= int(axis) < 3:
        return AXES[int(axis)]
    raise DesignError(f"axis must be one of {', '.join(AXES)} or 0, 1, 2, got {axis!r}")


@dataclass(frozen=True)
class WindModel:
    """One axis' gust model: Gauss-Markov torque states as the ML identification fitted them.

    Attributes
    ----------
    kind : {"gm2", "gm_so"}
        ``"gm2"``: a slow plus a fast first-order process; ``"gm_so"``: a slow first-order process plus a
        fast second-order one of natural period ``time_constants_s[1]`` and damping ``damping_ratio``.
    time_constants_s : tuple of 2 float
        Slow and fast time constants [s], > 0.
    torque_std : tuple of 2 float
        Stationary standard deviation of each component's torque per inertia [rad/s²], >= 0.
    damping_ratio : float
        Damping ratio of the fast second-order process (``"gm_so"`` only) [-], > 0.
    """

    kind: str = "gm2"
    time_constants_s: tuple = (1.0, 0.1)
    torque_std: tuple = (0.0, 0.0)
    damping_ratio: float = 1.0

    def __post_init__(self):
        if self.kind not in WIND_KINDS:
            raise DesignError(f"WindModel.kind must be one of {WIND_KINDS}, got {self.kind!r}")
        for name, positive in (("time_constants_s", True), ("torque_std", False)):
            raw = getattr(self, name)
            try:
                values = tuple(raw)
            except TypeError:
                values = ()
            ok = len(values) == 2 and all(is_real(v) and (v > 0 if positive else v >= 0) for v in values)
            if not ok:
                raise DesignError(f"WindModel.{name} must be 2 numbers {'> 0' if positive else '>= 0'} "
                                  f"(slow, fast), got {raw!r}")
            object.__setattr__(self, name, tuple(float(v) for v in values))
        if not (is_real(self.damping_ratio) and self.damping_ratio > 0):
            raise DesignError(f"WindModel.damping_ratio must be a number > 0, got {self.damping_ratio!r}")
        object.__setattr__(self, "damping_ratio", float(self.damping_ratio))

    @classmethod
    def from_document(cls, document, axis) -> "WindModel":
        """The wind model the ML identification stored for ``axis`` in a model file's document
        (:meth:`model_store.model_file.ModelDocument.wind`).

        Raises
        ------
        DesignError
            The document holds no wind model for the axis (a model identified with ``--method integral``,
            or written before the wind was stored), or a malformed one; the message says which entry.
        """
        name = _axis_name(axis)
        where = f"model.json fit_statistics.axes.{name}.wind"
        wind = document.wind(name)
        if wind is None:
            raise DesignError(f"{where} is missing: the LQG design needs the gust model the maximum-likelihood "
                              "identification fits ('heli identify --method ml', the default); pass "
                              "wind=WindModel(...) to design on a model identified otherwise")
        try:
            return cls(wind["model"], tuple(wind["time_constants_s"]), tuple(wind["torque_std"]),
                       wind.get("damping_ratio") or 1.0)
        except (KeyError, TypeError) as e:
            raise DesignError(f"{where} must hold model, time_constants_s and torque_std; got {wind!r}") from e

    def states(self):
        """``(Aw, cw, G)``: the gust states' matrix (m, m), the row summing them into the torque (m,), and the
        noise input (m, 2) that gives each component its torque level (unit-intensity white noise in)."""
        from identification.likelihood.state_space import wind_block

        Aw, cw, cols = wind_block(self.kind, *self.time_constants_s, self.damping_ratio)
        G = np.column_stack([c * s for c, s in zip(cols, self.torque_std)])
        return Aw, cw, G

    def to_dict(self) -> dict:
        return {"model": self.kind, "time_constants_s": list(self.time_constants_s),
                "torque_std": list(self.torque_std),
                "damping_ratio": self.damping_ratio if self.kind == "gm_so" else None}


@dataclass(frozen=True, eq=False)
class AxisModel:
    """One axis' sampled design model (module docstring).

    ``x[k+1] = A x[k] + B u[k] + w[k]``, ``cov(w) = Qw``; ``y[k] = C x[k] + v[k]``, ``cov(v) = Rv``.

    Attributes
    ----------
    axis : str
    dt : float
        Control period [s].
    A : ndarray, shape (n, n)
    B : ndarray, shape (n, 1)
        Per unit stick offset [stick].
    C : ndarray, shape (2, n)
        Rows: the angle [rad] and the gyro's rate [rad/s] (in the airframe's signs; the observation's
        attitude and rate *errors* are their negatives in an attitude hold).
    Qw : ndarray, shape (n, n)
        Covariance of the process noise over one period (gust and line states only).
    Rv : ndarray, shape (2, 2)
        Covariance of the measurement noise [rad², (rad/s)²].
    states : tuple of str
        ``rate``, ``servo`` (a delayed axis), ``angle``, ``wind_slow``, ``wind_fast`` (and ``wind_fast_rate``
        for ``"gm_so"``), then ``line<i>_c``, ``line<i>_s`` per gyro line.
    n_plant : int
        Airframe states (rate, [servo], angle): the only ones the stick reaches.
    wind : WindModel or None
        The gust model, None for a design without gust states.
    line_hz : tuple of float
        Frequencies of the modelled gyro lines [Hz].
    """

    axis: str
    dt: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    Qw: np.ndarray
    Rv: np.ndarray
    states: tuple
    n_plant: int
    wind: WindModel | None
    line_hz: tuple

    @property
    def n(self) -> int:
        return int(self.A.shape[0])

    @property
    def angle_index(self) -> int:
        return self.n_plant - 1

    def plant(self):
        """``(A, B, C)`` of the airframe alone (what the stick reaches), for the loop's margins."""
        k = self.n_plant
        return self.A[:k, :k], self.B[:k], self.C[:, :k]


def axis_model(params, sensors, wind: WindModel | None, axis, dt: float, collective: float = 0.0,
               lines: bool = True) -> AxisModel:
    """The sampled design model of one axis (module docstring).

    Parameters
    ----------
    params : heli_core.params.ModelParams
        The identified model.
    sensors : heli_core.sensors.SensorModel
        Its sensors; a silent one measures with :data:`MIN_NOISE`.
    wind : WindModel or None
        The axis' gust model; None leaves the gust states out (the airframe alone).
    axis : {"roll", "pitch", "yaw"} or 0, 1, 2
    dt : float
        Control period [s], in (0, 1).
    collective : float
        Collective stick of the hover point [-1, 1].
    lines : bool
        Model the gyro's vibration lines as oscillator states (default True); False leaves them to the
        estimator as white noise of the same variance.

    Raises
    ------
    DesignError
        A bad axis or control period, or an axis whose stick does not move it.
    """
    import control

    name = _axis_name(axis)
    ax = AXES.index(name)
    if not (is_real(dt) and 0 < dt < 1):
        raise DesignError(f"dt must be a control period in (0, 1) s, got {dt!r}")
    if float(params.control_gains[ax]) == 0.0:
        raise DesignError(f"the model's {name} control gain is 0: the stick does not move that axis")
    lin = hover_linearisation(params, float(collective))
    Ap, Bp, _ = lin.axis_block(ax)
    n_p = Ap.shape[0]
    Aw, cw, G = wind.states() if wind is not None else (np.zeros((0, 0)), np.zeros(0), np.zeros((0, 2)))
    n_w = Aw.shape[0]
    n_c = n_p + n_w
    Ac = np.zeros((n_c, n_c))
    Ac[:n_p, :n_p] = Ap
    Ac[:n_p, n_p:] = np.outer(Bp[:, 1], cw)  # the gust torque enters where the linearisation's d does
    Ac[n_p:, n_p:] = Aw
    Bc = np.zeros((n_c, 1))
    Bc[:n_p, 0] = Bp[:, 0]
    Gc = np.zeros((n_c, G.shape[1]))
    Gc[n_p:] = G
    sampled = control.c2d(control.ss(Ac, Bc, np.eye(n_c), np.zeros((n_c, 1))), float(dt), "zoh")
    Ad, Bd = np.asarray(sampled.A), np.asarray(sampled.B)
    Qd = _van_loan(Ac, Gc, float(dt))

    rate_noise = float(sensors.gyro_noise[ax])
    angle_noise = float(sensors.attitude_noise[ax])
    axis_lines = [ln for ln in sensors.gyro_lines if ln.axis == name and ln.amplitude > 0]
    white_rate_var = rate_noise ** 2 + (0.0 if lines else sum(ln.amplitude ** 2 / 2 for ln in axis_lines))
    modelled = axis_lines if lines else []
    n = n_c + 2 * len(modelled)
    A = np.zeros((n, n))
    A[:n_c, :n_c] = Ad
    B = np.zeros((n, 1))
    B[:n_c] = Bd
    Qw = np.zeros((n, n))
    Qw[:n_c, :n_c] = Qd
    C = np.zeros((2, n))
    C[0, n_p - 1] = 1.0  # angle
    C[1, 0] = 1.0  # gyro: rate ...
    r = math.exp(-dt / LINE_COHERENCE_S)
    for i, line in enumerate(modelled):
        j = n_c + 2 * i
        theta = 2.0 * math.pi * line.frequency_hz * dt
        A[j:j + 2, j:j + 2] = r * np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
        Qw[j:j + 2, j:j + 2] = (1.0 - r * r) * line.amplitude ** 2 / 2.0 * np.eye(2)
        C[1, j] = 1.0  # ... plus each line
    Rv = np.diag([max(angle_noise, MIN_NOISE) ** 2, max(white_rate_var, MIN_NOISE ** 2)])
    wind_states = ("wind_slow", "wind_fast") + (("wind_fast_rate",) if n_w == 3 else ()) if n_w else ()
    states = ("rate",) + (("servo",) if n_p == 3 else ()) + ("angle",) + wind_states + tuple(
        s for i in range(len(modelled)) for s in (f"line{i}_c", f"line{i}_s"))
    return AxisModel(name, float(dt), A, B, C, 0.5 * (Qw + Qw.T), Rv, states, n_p, wind,
                     tuple(float(ln.frequency_hz) for ln in modelled))


def _van_loan(A: np.ndarray, G: np.ndarray, dt: float) -> np.ndarray:
    """Covariance over one period of ``x' = A x + G n`` driven by unit-intensity white noise ``n``
    (Van Loan 1978, "Computing integrals involving the matrix exponential")."""
    from scipy.linalg import expm

    n = A.shape[0]
    if n == 0:
        return np.zeros((0, 0))
    V = np.zeros((2 * n, 2 * n))
    V[:n, :n] = -A * dt
    V[:n, n:] = G @ G.T * dt
    V[n:, n:] = A.T * dt
    F = expm(V)
    Ad = F[n:, n:].T
    Q = Ad @ F[:n, n:]
    return 0.5 * (Q + Q.T)
