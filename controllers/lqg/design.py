"""The LQG (H2) attitude design: an LQR on the design model's states and a Kalman filter on the observations.

Per axis, on the sampled design model of :mod:`controllers.lqg.plant` (the identified airframe with its
Padé servo, its identified gust states and its sensors):

* the **regulator** ``u = -K x`` is python-control's ``control.dlqr`` at the control period on the
  airframe and gust states (the gust states are not controllable but stable, so the gain feeds their
  estimate forward: the stick cancels the torque it expects);
* the **estimator** is the steady-state Kalman filter of ``control.dlqe`` in its current (filtered) form:
  the stick of period ``k`` uses the observation of period ``k`` (the environment applies an action to
  the state it observed), ``x_f = x_p + M (y - C x_p)``, ``x_p[k+1] = A x_f + B u``, with
  ``M = P C' (C P C' + R)^-1`` from the filter's predicted covariance ``P``.

The weights (the rule)
----------------------
**Bryson's rule** on the attitude error, the rate error and the stick: ``Q = diag(1/θ², 1/ω²)`` on
(angle, rate), ``R = 1/u²``, with ``θ`` the allowed attitude error, ``ω`` the allowed rate error and ``u`` the
allowed stick (:class:`LQGWeights`; defaults θ = 0.1°, ω = 0.5°/s and the full stick travel, u = 1: an
attitude error of the size of the best PDs' p90 on the shipped model, or a rate error that would correct
it in 0.2 s, costs as much as the whole stick). With an exact model and the identified noises this is
the H2-optimal controller for that cost.

**One scalar is searched to keep the margins**: the loop-transfer-recovery weight ``q`` (Doyle & Stein
1979, "Robustness with observers", IEEE TAC 24(4)): the filter is designed as if the stick carried white
noise of variance ``q`` [stick²] per period besides the identified gusts, ``Qw + q B B'``. As ``q`` grows
the loop broken at the plant input moves from the LQG's toward the LQR's own. The design takes the
**smallest** ``q`` of :data:`RECOVERY_GRID` whose sampled loop (airframe and compensator built with
python-control, :func:`loop_margins`) is stable and keeps ``gain_margin_db`` (6 dB, up and down) and
``phase_margin_deg`` (45°): the filter closest to the identified noise model that keeps them. The
weight scale ``ρ`` (``R`` times ρ) cannot do this here: on the shipped model at ``q = 0`` and ρ from
10⁻³ to 10³ yaw's phase margin stays at 33-35°, and roll's reaches 43° only at ρ = 10³, where its
predicted p90 has doubled (0.17° against 0.086°): the estimator, not the regulator, eats the margin
(``scripts/lqg_baseline.py --scan`` prints both scans).

Each design also predicts its stationary attitude p90 (``1.645 σ`` of the closed loop's covariance under
the design model's noises: the identified Gauss-Markov gusts and the sensors), which the search table
reports beside the margins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from heli_core.config import is_real
from heli_core.control_period import default_dt
from heli_core.terms import AXES

from ..closed_loop import GAUSS_ABS_FACTOR
from ..errors import DesignError
from .plant import AxisModel, WindModel, axis_model

RECOVERY_GRID = (0.0,) + tuple(float(v) for v in 10.0 ** np.arange(-5.0, 1.01, 0.25))
"""Loop-transfer-recovery weights searched, smallest first [stick² per period]."""
MIN_GAIN_MARGIN_DB = 6.0
MIN_PHASE_MARGIN_DEG = 45.0
"""The margins the loop must keep at the plant input (the robust PD's: 6 dB and 45°)."""
N_FREQ = 1200
"""Frequencies of the loop's response the margins are read from (log-spaced from 0.01 rad/s to Nyquist)."""


@dataclass(frozen=True)
class LQGWeights:
    """Bryson's rule: the errors and the stick that each cost 1 (module docstring).

    Attributes
    ----------
    attitude_deg : float
        Allowed attitude error θ [deg], > 0.
    rate_deg_s : float
        Allowed rate error ω [deg/s], > 0.
    stick : float
        Allowed stick offset u [stick], > 0.
    """

    attitude_deg: float = 0.1
    rate_deg_s: float = 0.5
    stick: float = 1.0

    def __post_init__(self):
        for name in ("attitude_deg", "rate_deg_s", "stick"):
            value = getattr(self, name)
            if not (is_real(value) and value > 0):
                raise DesignError(f"LQGWeights.{name} must be a number > 0, got {value!r}")
            object.__setattr__(self, name, float(value))

    def matrices(self, model: AxisModel) -> tuple[np.ndarray, np.ndarray]:
        """``(Q, R)`` over the model's airframe and gust states (the states the regulator weighs or reads)."""
        k = model.n - 2 * len(model.line_hz)
        Q = np.zeros((k, k))
        Q[model.angle_index, model.angle_index] = 1.0 / math.radians(self.attitude_deg) ** 2
        Q[0, 0] = 1.0 / math.radians(self.rate_deg_s) ** 2
        return Q, np.array([[1.0 / self.stick ** 2]])


@dataclass(frozen=True, eq=False)
class AxisDesign:
    """The LQG of one axis.

    Attributes
    ----------
    model : AxisModel
        The design model (its ``A``, ``B``, ``C`` are the estimator's).
    K : ndarray, shape (1, n)
        Regulator gain, ``u = -K x_f`` [stick per state unit]; zero on the line states.
    M : ndarray, shape (n, 2)
        Current-estimator gain, ``x_f = x_p + M (y - C x_p)``.
    recovery : float
        The loop-transfer-recovery weight chosen [stick²].
    gain_margin_db, phase_margin_deg : float
        The worst margins of the sampled loop at the plant input (inf: no crossing).
    crossover_rad_s : float
        The loop's gain crossover [rad/s] (the lowest).
    predicted_att_p90_deg : float
        Predicted stationary p90 |attitude error| under the design model's noises [deg].
    predicted_stick_rms : float
        Predicted stick RMS [stick].
    search : tuple of dict
        Per recovery weight tried: ``recovery``, ``stable``, ``gain_margin_db``, ``phase_margin_deg``,
        ``crossover_rad_s``, ``predicted_att_p90_deg``, ``predicted_stick_rms``, ``kept``.
    """

    model: AxisModel
    K: np.ndarray
    M: np.ndarray
    recovery: float
    gain_margin_db: float
    phase_margin_deg: float
    crossover_rad_s: float
    predicted_att_p90_deg: float
    predicted_stick_rms: float
    search: tuple = field(repr=False, default=())

    def summary(self) -> dict:
        """The axis' design figures (JSON-ready)."""
        return {"axis": self.model.axis, "states": list(self.model.states), "recovery": self.recovery,
                "gain_margin_db": self.gain_margin_db, "phase_margin_deg": self.phase_margin_deg,
                "crossover_rad_s": self.crossover_rad_s, "predicted_att_p90_deg": self.predicted_att_p90_deg,
                "predicted_stick_rms": self.predicted_stick_rms,
                "wind": None if self.model.wind is None else self.model.wind.to_dict(),
                "gyro_lines_hz": list(self.model.line_hz)}


def regulator_gain(model: AxisModel, weights: LQGWeights) -> np.ndarray:
    """``K`` (1, n) of ``control.dlqr`` on the model's airframe and gust states, zero on its line states."""
    import control

    Q, R = weights.matrices(model)
    k = Q.shape[0]
    K = np.zeros((1, model.n))
    K[:, :k] = np.asarray(control.dlqr(model.A[:k, :k], model.B[:k], Q, R)[0])
    return K


def estimator_gain(model: AxisModel, recovery: float = 0.0) -> np.ndarray:
    """``M`` (n, 2) of the steady-state current estimator (``control.dlqe``), with the recovery weight's
    fictitious stick noise ``recovery * B B'`` added to the process noise."""
    import control

    Qw = model.Qw + recovery * (model.B @ model.B.T)
    P = np.asarray(control.dlqe(model.A, np.eye(model.n), model.C, Qw, model.Rv)[1])
    S = model.C @ P @ model.C.T + model.Rv
    return np.linalg.solve(S.T, (P @ model.C.T).T).T


def compensator(model: AxisModel, K: np.ndarray, M: np.ndarray):
    """The LQG as a discrete system from the measurement ``y`` (angle, rate) to the stick ``u``:
    ``(Ak, Bk, Ck, Dk)`` with ``x_p[k+1] = Ak x_p + Bk y``, ``u = Ck x_p + Dk y`` (the clip left out)."""
    n = model.n
    F = np.eye(n) - M @ model.C
    Acl = model.A - model.B @ K
    return Acl @ F, Acl @ M, -K @ F, -K @ M


def loop_margins(model: AxisModel, K: np.ndarray, M: np.ndarray) -> dict:
    """Margins of the sampled loop broken at the plant input: ``L(z) = -C_lqg(z) P(z)``.

    The airframe ``P`` (stick to angle and rate) and the compensator are python-control systems at the
    control period, joined by ``control.series``; the loop's response on :data:`N_FREQ` log-spaced
    frequencies up to Nyquist is one batched solve, and every crossing is read off it by linear
    interpolation. (python-control's own ``stability_margins`` gives the same figures to 1e-4 dB and
    1e-3° on the shipped model's loops, but evaluates the response one frequency at a time and fits a spline
    through it: over ten times slower, and the design tries a few dozen loops.)

    Returns ``gain_margin_db`` (the smallest distance in dB from 1 at a crossing of the negative real axis,
    up or down: a loop that a lower gain destabilises counts), ``phase_margin_deg`` (the smallest at a gain
    crossing), ``crossover_rad_s`` (the lowest gain crossing, nan if none), and ``stable`` (the closed
    loop's poles inside the unit circle).
    """
    dt = model.dt
    omega = np.geomspace(1e-2, math.pi / dt, N_FREQ)
    L = _response(plant_input_loop(model, K, M), np.exp(1j * omega * dt))
    L[-1] = L[-1].real  # z = -1
    mag = np.abs(L)
    i = np.flatnonzero(np.diff(np.sign(mag - 1.0)) != 0)  # gain crossings between i and i + 1
    f = (1.0 - mag[i]) / (mag[i + 1] - mag[i])
    phase = np.unwrap(np.angle(L))
    pm = np.abs(np.degrees(np.angle(-np.exp(1j * (phase[i] + f * (phase[i + 1] - phase[i]))))))
    wc = omega[i] * (omega[i + 1] / omega[i]) ** f
    j = np.flatnonzero((np.diff(np.sign(L.imag)) != 0) & (L.real[:-1] + L.real[1:] < 0))
    g = L.imag[j] / (L.imag[j] - L.imag[j + 1])
    at = np.abs(L.real[j] + g * (L.real[j + 1] - L.real[j]))
    if L.real[-1] < 0:
        at = np.append(at, abs(L.real[-1]))
    at = at[at > 0]
    closed = _closed_loop(model, K, M)[0]
    return {"stable": bool(np.max(np.abs(np.linalg.eigvals(closed))) < 1.0),
            "gain_margin_db": float(np.min(np.abs(20.0 * np.log10(at)))) if at.size else math.inf,
            "phase_margin_deg": float(np.min(pm)) if pm.size else math.inf,
            "crossover_rad_s": float(np.min(wc)) if wc.size else math.nan}


def plant_input_loop(model: AxisModel, K: np.ndarray, M: np.ndarray):
    """The sampled loop broken at the plant input, ``L(z) = -C_lqg(z) P(z)`` (a python-control system): the
    airframe ``P`` (stick to angle and rate) and the compensator joined by ``control.series``, negative
    feedback folded in (the margins are read against ``L = -1``)."""
    import control

    Ap, Bp, Cp = model.plant()
    plant = control.ss(Ap, Bp, Cp, np.zeros((2, 1)), model.dt)
    comp = control.ss(*compensator(model, K, M), model.dt)
    return -control.series(plant, comp)  # u_in -> y -> u_out


def recovery_response(model: AxisModel, K: np.ndarray, M: np.ndarray, angle0: float, seconds: float):
    """The loop's noise-free recovery from an attitude error ``angle0`` [rad], the filter starting from its
    prior (zero) as at an episode's start: ``(t [s], angle [rad], stick)``, the stick unclipped."""
    Z = _closed_loop(model, K, M)[0]
    n, steps = model.n, int(round(seconds / model.dt)) + 1
    s = np.zeros(2 * n)
    s[model.angle_index] = angle0
    F = np.eye(n) - M @ model.C
    angle, stick = np.empty(steps), np.empty(steps)
    for k in range(steps):
        x, x_p = s[:n], s[n:]
        angle[k] = x[model.angle_index]
        stick[k] = float(-(K @ (F @ x_p + M @ (model.C @ x)))[0])
        s = Z @ s
    return np.arange(steps) * model.dt, angle, stick


def _response(sys, z: np.ndarray) -> np.ndarray:
    """``C (zI - A)^-1 B + D`` of a SISO state-space system at every ``z`` (one batched solve)."""
    A, B, C, D = (np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))
    n = A.shape[0]
    X = np.linalg.solve(z[:, None, None] * np.eye(n) - A, np.broadcast_to(B.astype(complex), (z.size, n, 1)))
    return (C @ X)[:, 0, 0] + D[0, 0]


def _closed_loop(model: AxisModel, K: np.ndarray, M: np.ndarray):
    """``(Z, Gz, W)``: the loop of the model and its LQG, state ``(x, x_p)``, driven by ``(w, v)`` of
    covariance ``W``: ``s[k+1] = Z s[k] + Gz (w, v)``."""
    A, B, C, n = model.A, model.B, model.C, model.n
    F = np.eye(n) - M @ C
    Acl = A - B @ K
    Z = np.block([[A - B @ K @ M @ C, -B @ K @ F], [Acl @ M @ C, Acl @ F]])
    Gz = np.block([[np.eye(n), -B @ K @ M], [np.zeros((n, n)), Acl @ M]])
    W = np.block([[model.Qw, np.zeros((n, 2))], [np.zeros((2, n)), model.Rv]])
    return Z, Gz, W


def predicted_errors(model: AxisModel, K: np.ndarray, M: np.ndarray) -> tuple[float, float]:
    """(p90 |attitude error| [deg], stick RMS [stick]) of the stationary closed loop under the design model's
    noises (discrete Lyapunov equation; Gaussian p90); (inf, inf) for an unstable loop."""
    from scipy.linalg import solve_discrete_lyapunov

    Z, Gz, W = _closed_loop(model, K, M)
    if np.max(np.abs(np.linalg.eigvals(Z))) >= 1.0:
        return math.inf, math.inf
    X = solve_discrete_lyapunov(Z, Gz @ W @ Gz.T)
    n, i = model.n, model.angle_index
    # u = -K x_f = -K (F x_p + M C x + M v)
    F = np.eye(n) - M @ model.C
    Hu = np.hstack([-K @ M @ model.C, -K @ F])
    u_var = float((Hu @ X @ Hu.T + K @ M @ model.Rv @ M.T @ K.T)[0, 0])
    return GAUSS_ABS_FACTOR[90] * math.degrees(math.sqrt(max(X[i, i], 0.0))), math.sqrt(max(u_var, 0.0))


def design_axis(model: AxisModel, weights: LQGWeights | None = None, recovery=RECOVERY_GRID,
                gain_margin_db: float = MIN_GAIN_MARGIN_DB,
                phase_margin_deg: float = MIN_PHASE_MARGIN_DEG) -> AxisDesign:
    """The LQG of one axis: Bryson's weights, and the smallest recovery weight that keeps the margins.

    Parameters
    ----------
    model : AxisModel
    weights : LQGWeights, optional
    recovery : float or sequence of float
        Recovery weights to try, in order (default :data:`RECOVERY_GRID`); one number takes it as is
        (margins reported, not required).
    gain_margin_db, phase_margin_deg : float
        Margins required [dB], [deg].

    Raises
    ------
    DesignError
        No weight of the grid keeps the margins; the message gives the best each reached.
    """
    weights = LQGWeights() if weights is None else weights
    if not isinstance(weights, LQGWeights):
        raise DesignError(f"weights must be an LQGWeights, got {type(weights).__name__}")
    fixed = np.ndim(recovery) == 0
    grid = [recovery] if fixed else list(recovery)
    if not grid or not all(is_real(q) and q >= 0 for q in grid):
        raise DesignError(f"recovery must be a weight >= 0 or a non-empty sequence of them, got {recovery!r}")
    from threadpoolctl import threadpool_limits

    rows, chosen = [], None
    # 10-20 states: BLAS threads only wait on each other (a model's three axes: 1.7 s, not 4.7 s, on 2 busy cores)
    with threadpool_limits(limits=1, user_api="blas"):
        K = regulator_gain(model, weights)
        for q in grid:
            M = estimator_gain(model, float(q))
            m = loop_margins(model, K, M)
            p90, u_rms = predicted_errors(model, K, M)
            kept = m["stable"] and m["gain_margin_db"] >= gain_margin_db and m["phase_margin_deg"] >= phase_margin_deg
            rows.append({"recovery": float(q), **m, "predicted_att_p90_deg": p90, "predicted_stick_rms": u_rms,
                         "kept": bool(kept)})
            if fixed or kept:
                chosen = (float(q), M, rows[-1])
                break
    if chosen is None:
        best_gm = max(r["gain_margin_db"] for r in rows if r["stable"]) if any(r["stable"] for r in rows) else None
        best_pm = max(r["phase_margin_deg"] for r in rows if r["stable"]) if any(r["stable"] for r in rows) else None
        raise DesignError(f"{model.axis}: no recovery weight of {grid[0]:g}..{grid[-1]:g} keeps {gain_margin_db:g} dB "
                          f"and {phase_margin_deg:g} deg at the plant input (best reached: "
                          f"{best_gm if best_gm is None else round(best_gm, 1)} dB, "
                          f"{best_pm if best_pm is None else round(best_pm, 1)} deg); weigh the rate more (a smaller "
                          "LQGWeights.rate_deg_s), allow a larger attitude error, or ask for smaller margins")
    q, M, row = chosen
    return AxisDesign(model, K, M, q, row["gain_margin_db"], row["phase_margin_deg"], row["crossover_rad_s"],
                      row["predicted_att_p90_deg"], row["predicted_stick_rms"], tuple(rows))


@dataclass(frozen=True, eq=False)
class LQGDesign:
    """The three axes' LQG designs of one model.

    Attributes
    ----------
    axes : tuple of 3 AxisDesign
        Roll, pitch, yaw.
    weights : LQGWeights
    dt : float
        Control period [s].
    settings : dict
        Model path, collective, margins asked, lines modelled, where each wind model came from.
    """

    axes: tuple
    weights: LQGWeights
    dt: float
    settings: dict = field(default_factory=dict)

    def controller(self):
        """The policy (:class:`controllers.lqg.controller.LQGController`) of this design."""
        from .controller import LQGController

        return LQGController.from_design(self)

    def summary(self) -> dict:
        return {"dt": self.dt, "weights": {"attitude_deg": self.weights.attitude_deg,
                                           "rate_deg_s": self.weights.rate_deg_s, "stick": self.weights.stick},
                **self.settings, "axes": [a.summary() for a in self.axes]}

    def markdown(self) -> str:
        """A table of each axis' design: recovery weight, margins, crossover, predicted p90 and stick RMS."""
        rows = ["| axis | states | recovery q [stick²] | gain margin [dB] | phase margin [deg] | crossover [rad/s] "
                "| predicted p90 [deg] | predicted stick RMS |", "|---|---|---|---|---|---|---|---|"]
        for a in self.axes:
            rows.append(f"| {a.model.axis} | {a.model.n} | {a.recovery:.3g} | {a.gain_margin_db:.1f} | "
                        f"{a.phase_margin_deg:.1f} | {a.crossover_rad_s:.3g} | {a.predicted_att_p90_deg:.3f} | "
                        f"{a.predicted_stick_rms:.3f} |")
        return "\n".join(rows)


def design_lqg(model=None, dt: float | None = None, weights: LQGWeights | None = None, recovery=RECOVERY_GRID,
               gain_margin_db: float = MIN_GAIN_MARGIN_DB, phase_margin_deg: float = MIN_PHASE_MARGIN_DEG,
               lines: bool = True, wind=None, collective: float | None = None) -> LQGDesign:
    """Design the per-axis LQG of an identified model (module docstring).

    Parameters
    ----------
    model : str, Path, EnvModel or None
        Model directory (None: the shipped model).
    dt : float or None
        Control period [s], in (0, 1); None (default): the environment's for the model
        (:func:`heli_core.control_period.default_dt`: 0.01 s, or 0.02 s for a 50 Hz log's model).
    weights : LQGWeights, optional
        Bryson's allowed errors and stick (default :class:`LQGWeights`).
    recovery : float or sequence of float
        Loop-transfer-recovery weights searched (:func:`design_axis`).
    gain_margin_db, phase_margin_deg : float
        Margins the loop keeps at the plant input [dB], [deg].
    lines : bool
        Model the gyros' vibration lines as estimator states (default True).
    wind : None, WindModel, or dict of axis to WindModel or None
        None: each axis' identified wind model (``model.json``); a WindModel for every axis; per axis in a dict
        (an axis left out keeps its identified one), where None leaves that axis' gust states out.
    collective : float, optional
        Collective of the hover point (default: the library's mean, as the sweep's plant).

    Raises
    ------
    DesignError
        No identified wind model, a bad setting, or margins no recovery weight keeps.
    heli_env.errors.EnvModelError
        Missing or corrupt model directory.
    """
    from heli_env.env_model import as_env_model

    env_model = as_env_model(model)
    if dt is None:
        dt = default_dt(env_model.sample_rate)
    for name, value in (("gain_margin_db", gain_margin_db), ("phase_margin_deg", phase_margin_deg)):
        if not (is_real(value) and value >= 0):
            raise DesignError(f"{name} must be a number >= 0, got {value!r}")
    if not isinstance(lines, (bool, np.bool_)):
        raise DesignError(f"lines must be True or False, got {lines!r}")
    col = float(np.mean(env_model.collective)) if collective is None else collective
    if not (is_real(col) and -1.0 <= col <= 1.0):
        raise DesignError(f"collective must be a stick value in [-1, 1], got {collective!r}")
    def identified(axis):
        try:
            return WindModel.from_document(env_model.document, axis)
        except DesignError as e:
            raise DesignError(f"{env_model.path}: {e}") from e

    winds, sources = {}, {}
    for axis in AXES:
        if wind is None:
            winds[axis], sources[axis] = identified(axis), "model.json"
        elif isinstance(wind, WindModel):
            winds[axis], sources[axis] = wind, "given"
        elif isinstance(wind, dict) and set(wind) <= set(AXES):
            w = wind.get(axis, "identified")
            if w == "identified":
                winds[axis], sources[axis] = identified(axis), "model.json"
            elif w is None or isinstance(w, WindModel):
                winds[axis], sources[axis] = w, "none" if w is None else "given"
            else:
                raise DesignError(f"wind[{axis!r}] must be a WindModel or None, got {w!r}")
        else:
            raise DesignError(f"wind must be None, a WindModel or a dict of roll/pitch/yaw to WindModel or None, "
                              f"got {wind!r}")
    axes = tuple(design_axis(axis_model(env_model.params, env_model.sensors, winds[a], a, dt, col, lines),
                             weights, recovery, gain_margin_db, phase_margin_deg) for a in AXES)
    settings = {"model": str(env_model.path), "collective": col, "min_gain_margin_db": float(gain_margin_db),
                "min_phase_margin_deg": float(phase_margin_deg), "gyro_lines_modelled": bool(lines),
                "wind_source": sources}
    return LQGDesign(axes, LQGWeights() if weights is None else weights, float(dt), settings)
