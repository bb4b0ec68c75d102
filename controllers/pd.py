"""Per-axis PD attitude controllers designed on the identified model with python-control.

Design model
------------
Each axis is designed on the decoupled linearisation of the identified model at
rest (zero rates, servo settled, collective 0). For roll, eq. (18) gives::

    p' = -k3 p + k2 c + d          c: stick after the servo, d: gust torque per inertia
    c  = exp(-s tau) u  ~  (n1 - n2 s) / (1 + d1 s) u      first-order Padé servo, eq. (31)
    phi' = p

and pitch and yaw the same with (k6, k7, tau_pitch) and (k10, k11, tau_yaw) of
eq. (21). The matrices come from :func:`heli_core.discrete.linear_structure`,
the package's one statement of the physics, and keep only the axis' own block:
the flybar cross-coupling (k4, k8) and the gyroscopic products (k1, k5, k9) are
left out (per-axis design on the decoupled part; the paper finds the coupling
"swamped by wind disturbance", Section 3), and so are the collective-scheduled
gains (``gs1``-``gs3``, zero at collective 0). Products like ``p|p|`` have zero
slope at rest and drop out of a linearisation anyway.

Control law
-----------
On the environment's observation (:class:`heli_env.env.HeliAttitudeEnv`) the
policy sets, per axis ``i`` (roll, pitch, yaw)::

    action_i = clip(s_i * (kp_i * obs[i] + kd_i * obs[6 + i]), -1, 1)

where ``obs[0:3]`` is the attitude error (reference - attitude) [rad],
``obs[6:9]`` the rate error (reference rate - rate) [rad/s], ``kp`` is in
stick/rad, ``kd`` in stick/(rad/s) and ``s_i`` = sign of the axis' control gain
(k2, k6, k10) so that positive gains stabilise (the paper's pitch gain k6 is
negative, eq. 69). The derivative is the *measured* rate error, not a finite
difference: on the continuous model the controller is exactly ``C(s) = s_i
(kp + kd s)`` acting on the attitude error, with no derivative filter.

Sampling
--------
The environment samples the observation every ``dt`` and holds the action over
the period (zero-order hold), then integrates the linear part exactly
(:func:`heli_core.discrete.discrete_step`, matrix exponential). The analysis
here therefore discretises the plant with :func:`control.c2d` (``'zoh'``) and
closes the loop in discrete time: ``L(z) = s (kp G_phi(z) + kd G_p(z))``, where
``G_phi`` and ``G_p`` are the sampled stick-to-angle and stick-to-rate responses.
For the decoupled linear model this is the environment's own closed loop, so
the predicted stability is exact (``tests/test_pd.py`` checks gain pairs on both
sides of the boundary in the environment). The hold costs about ``omega*dt/2``
of phase, which the Bode figure shows against the continuous loop. ``dt=0``
gives the ideal continuous-time analysis.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import control
import numpy as np
from scipy.optimize import brentq

from heli_core.discrete import linear_structure
from heli_core.files import jsonable, save_figure, write_text
from heli_core.params import ModelParams
from heli_core.terms import AXES, STICK_ROW

from .closed_loop import pd_command

SCHEMA = "heli-env/pd-controller"
SCHEMA_VERSION = 1
OBS_DIM = 12
_HALF_POWER = 10.0 ** (-3.0 / 20.0)


def _axis_index(axis) -> int:
    """0, 1, 2 for "roll", "pitch", "yaw" (or the index itself)."""
    if isinstance(axis, str) and axis in AXES:
        return AXES.index(axis)
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and 0 <= axis < 3:
        return int(axis)
    raise ValueError(f"axis must be one of {AXES} or 0, 1, 2, got {axis!r}")


def _check_dt(dt) -> float:
    if not (isinstance(dt, (int, float, np.floating, np.integer)) and math.isfinite(dt) and dt >= 0):
        raise ValueError(f"dt must be a control period >= 0 s (0 for continuous time), got {dt!r}")
    return float(dt)


def _check_delay(delay_steps, dt) -> int:
    if int(delay_steps) != delay_steps or delay_steps < 0:
        raise ValueError(f"delay_steps must be a whole number of control periods >= 0, got {delay_steps!r}")
    if delay_steps and dt == 0:
        raise ValueError("delay_steps needs a control period dt > 0")
    return int(delay_steps)


def control_sign(params: ModelParams, axis) -> float:
    """Sign of the axis' control gain (k2, k6, k10): +1 or -1.

    Raises
    ------
    ValueError
        The control gain is zero: the stick does not move that axis.
    """
    i = _axis_index(axis)
    k = float(params.control_gains[i])
    if k == 0.0:
        raise ValueError(f"the model's {AXES[i]} control gain {('k2', 'k6', 'k10')[i]} is 0: the axis cannot be controlled")
    return 1.0 if k > 0 else -1.0


def _axis_ss(params: ModelParams, axis: int):
    """Continuous state space of one decoupled axis, eqs. (18), (21), (31).

    States ``(rate, [servo z], angle)``, inputs ``(stick u, torque d)``, outputs
    ``(angle, rate)``. The servo state appears only when the axis has a delay.
    """
    A6, B6, _, _ = linear_structure(params)
    i, j = axis, STICK_ROW[axis]
    servo = A6[3 + i, 3 + i] != 0.0
    if servo:
        A = np.array([[A6[i, i], A6[i, 3 + i], 0.0],
                      [0.0, A6[3 + i, 3 + i], 0.0],
                      [1.0, 0.0, 0.0]])
        B = np.array([[B6[i, j], B6[i, 5 + i]],
                      [B6[3 + i, j], 0.0],
                      [0.0, 0.0]])
        C = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    else:
        A = np.array([[A6[i, i], 0.0], [1.0, 0.0]])
        B = np.array([[B6[i, j], B6[i, 5 + i]], [0.0, 0.0]])
        C = np.array([[0.0, 1.0], [1.0, 0.0]])
    return A, B, C


def _sampled(params: ModelParams, axis: int, dt: float, delay_steps: int = 0):
    """(A, B, C) of the axis as the environment runs it: ZOH at ``dt`` and ``delay_steps`` periods of action delay.

    ``dt == 0`` returns the continuous matrices. The delay is a shift register
    in front of the stick input (the environment's ``action_delay`` queue).
    """
    A, B, C = _axis_ss(params, axis)
    if dt == 0:
        return A, B, C
    d = control.c2d(control.ss(A, B, C, np.zeros((2, 2))), dt, "zoh")
    A, B, C = np.asarray(d.A), np.asarray(d.B), np.asarray(d.C)
    if delay_steps:
        n, m = A.shape[0], delay_steps
        Aa = np.zeros((n + m, n + m))
        Aa[:n, :n] = A
        Aa[:n, n + m - 1] = B[:, 0]  # the oldest queued action reaches the aircraft
        for k in range(1, m):
            Aa[n + k, n + k - 1] = 1.0
        Ba = np.zeros((n + m, 2))
        Ba[n, 0] = 1.0
        Ba[:n, 1] = B[:, 1]
        A, B, C = Aa, Ba, np.hstack([C, np.zeros((2, m))])
    return A, B, C


def _tf(sys) -> control.TransferFunction:
    """:func:`control.ss2tf` of a SISO system, leading numerator coefficients that are rounding noise removed."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy's BadCoefficients for those same near-zero coefficients
        tf = control.ss2tf(sys)
    num = np.atleast_1d(np.squeeze(tf.num[0][0])).astype(float)
    den = np.atleast_1d(np.squeeze(tf.den[0][0])).astype(float)
    scale = max(np.max(np.abs(num)), 1e-300)
    first = np.nonzero(np.abs(num) > 1e-12 * scale)[0]
    num = num[first[0]:] if first.size else np.zeros(1)
    return control.tf(num, den, sys.dt)


def plant(params: ModelParams, axis, output: str = "angle") -> control.TransferFunction:
    """Continuous transfer function from the axis' stick offset to its angle (or rate).

    The decoupled linearisation at rest of eqs. (18), (21) with the Padé servo of
    eq. (31) when the model has a delay for the axis. For roll::

        P(s) = k2 (n1 - n2 s) / ((1 + d1 s) (s + k3) s)       (without delay: k2 / (s (s + k3)))

    Parameters
    ----------
    params : ModelParams
        Identified model.
    axis : {"roll", "pitch", "yaw"} or int
        Axis; its stick is lat, lon or ped.
    output : {"angle", "rate"}
        Roll/pitch/yaw angle [rad] or body rate p/q/r [rad/s].

    Returns
    -------
    control.TransferFunction
        Continuous time, from stick [stick units] to angle [rad] or rate [rad/s].
        The model's sign is kept (pitch is negative for the paper's k6 < 0).
    """
    i = _axis_index(axis)
    if output not in ("angle", "rate"):
        raise ValueError(f"output must be 'angle' or 'rate', got {output!r}")
    A, B, C = _axis_ss(params, i)
    if output == "angle":
        return _tf(control.ss(A, B[:, :1], C[:1], 0.0))
    # the angle (last state) does not feed back into the rate: leave it out for a minimal realisation
    return _tf(control.ss(A[:-1, :-1], B[:-1, :1], C[1:, :-1], 0.0))


# ------------------------------------------------------------------------ gains
@dataclass(frozen=True)
class PDGains:
    """Per-axis PD gains (roll, pitch, yaw).

    A scalar is broadcast to the three axes.

    Attributes
    ----------
    kp : tuple of 3 float
        Proportional gains on the attitude error [stick/rad], >= 0.
    kd : tuple of 3 float
        Derivative gains on the rate error [stick/(rad/s)], >= 0.
    """

    kp: tuple = (0.0, 0.0, 0.0)
    kd: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        for name in ("kp", "kd"):
            raw = getattr(self, name)
            try:
                v = np.broadcast_to(np.asarray(raw, dtype=float), (3,))
            except (TypeError, ValueError) as e:
                raise ValueError(f"{name} must be a number or 3 numbers (roll, pitch, yaw), got {raw!r}") from e
            if not np.all(np.isfinite(v)):
                raise ValueError(f"{name} must be finite, got {raw!r}")
            if np.any(v < 0):
                raise ValueError(f"{name} must be >= 0 (the control-gain sign is applied by the law), got {raw!r}")
            object.__setattr__(self, name, tuple(float(x) for x in v))

    def axis(self, axis) -> tuple[float, float]:
        """(kp, kd) of one axis."""
        i = _axis_index(axis)
        return self.kp[i], self.kd[i]


# --------------------------------------------------------------------- analysis
@dataclass(frozen=True, eq=False)
class LoopAnalysis:
    """Loop and closed-loop properties of one axis under PD control.

    Frequencies in rad/s; discrete systems (``dt > 0``) have time base ``dt``.

    Attributes
    ----------
    axis : str
    kp, kd : float
        Gains [stick/rad], [stick/(rad/s)].
    dt : float
        Control period [s]; 0 for the continuous-time analysis.
    delay_steps : int
        Whole periods of action delay.
    sign : float
        Control-gain sign s applied by the law.
    plant : control.TransferFunction
        Continuous stick-to-angle plant (:func:`plant`).
    loop : control.TransferFunction
        Loop transfer broken at the stick, ``L = s (kp G_angle + kd G_rate)``;
        discrete (ZOH) when ``dt > 0``, else ``s (kp + kd s) P(s)``.
    loop_continuous : control.TransferFunction
        ``s (kp + kd s) P(s)``, the loop without sampling (for comparison).
    gain_margin : float
        Gain margin as a factor [-] (inf if the phase never crosses -180°).
    phase_margin : float
        Phase margin [deg] at the gain crossover.
    stability_margin : float
        Smallest distance of the Nyquist curve to -1 [-].
    phase_crossover : float
        Frequency of the gain margin [rad/s] (nan if none).
    gain_crossover : float
        Crossover frequency |L| = 1 [rad/s] (nan if none).
    bandwidth : float
        -3 dB frequency of the complementary sensitivity ``T = L / (1 + L)`` [rad/s];
        nan for an unstable loop or kp = 0 (no finite DC gain of T).
    poles : ndarray of complex
        Closed-loop poles (z-plane for dt > 0, s-plane for dt = 0).
    stable : bool
        All closed-loop poles strictly inside the unit circle (left half plane).
    complementary : control.TransferFunction
        ``T = L / (1 + L)``: reference to angle when the reference rate is fed
        as well (smooth references of the "track" task).
    reference_to_angle : control.TransferFunction
        Reference angle to angle with the derivative on the measured rate only
        (reference steps, whose rate reference is zero).
    torque_to_angle : control.TransferFunction
        Gust torque per inertia d [rad/s^2] to angle [rad], closed loop; ``d``
        enters the rate equation like ``k*u`` (eq. 41) and is held over each period.
    ud_to_angle : control.TransferFunction
        Equivalent cyclic disturbance u_d [stick] to angle [rad], closed loop:
        ``k * torque_to_angle`` with ``k`` the control gain (eq. 42).
    disturbance_system : control.StateSpace
        Closed loop from u_d [stick] to (angle [rad], rate [rad/s], action
        [stick, before clipping]).
    """

    axis: str
    kp: float
    kd: float
    dt: float
    delay_steps: int
    sign: float
    plant: control.TransferFunction
    loop: control.TransferFunction
    loop_continuous: control.TransferFunction
    gain_margin: float
    phase_margin: float
    stability_margin: float
    phase_crossover: float
    gain_crossover: float
    bandwidth: float
    poles: np.ndarray
    stable: bool
    complementary: control.TransferFunction
    reference_to_angle: control.TransferFunction
    torque_to_angle: control.TransferFunction
    ud_to_angle: control.TransferFunction
    disturbance_system: control.StateSpace = field(repr=False)

    @property
    def gain_margin_db(self) -> float:
        """Gain margin [dB]."""
        return 20.0 * math.log10(self.gain_margin) if self.gain_margin > 0 else -math.inf

    @property
    def poles_s(self) -> np.ndarray:
        """Closed-loop poles as continuous-time equivalents ``log(z)/dt`` [1/s]."""
        p = np.asarray(self.poles, dtype=complex)
        return p if self.dt == 0 else np.log(p) / self.dt

    def summary(self) -> dict:
        """Scalars of the analysis (JSON-ready; non-finite values become None)."""
        worst = float(np.max(np.abs(self.poles))) if self.dt else float(np.max(self.poles.real))
        return jsonable({"axis": self.axis, "kp": self.kp, "kd": self.kd, "dt": self.dt,
                         "delay_steps": self.delay_steps, "gain_margin_db": self.gain_margin_db,
                         "phase_margin_deg": self.phase_margin, "gain_crossover_rad_s": self.gain_crossover,
                         "phase_crossover_rad_s": self.phase_crossover, "bandwidth_rad_s": self.bandwidth,
                         "stable": self.stable,
                         ("max_pole_radius" if self.dt else "max_pole_real_part"): worst})


def closed_loop_bandwidth(sys) -> float:
    """-3 dB bandwidth of a SISO closed loop [rad/s]: :func:`control.bandwidth`, also for discrete time.

    python-control 0.10 evaluates ``sys(1j*w)`` for discrete systems as well
    (fixed upstream in python-control PR #1212); here a discrete system is
    evaluated on the unit circle ``z = exp(1j*w*dt)`` up to the Nyquist
    frequency. Returns inf if the gain never drops by 3 dB, nan for an
    infinite DC gain (as :func:`control.bandwidth`).
    """
    if sys.isctime():
        return float(control.bandwidth(sys))
    dt = float(sys.dt)
    dc = abs(complex(np.squeeze(sys(1.0))))
    if not math.isfinite(dc):
        return math.nan

    def mag(w):
        return np.abs(np.squeeze(sys(np.exp(1j * np.asarray(w) * dt))))

    return _first_drop(mag, dc * _HALF_POWER, math.pi / dt)


def _first_drop(mag, level, w_max) -> float:
    """First frequency in (0, w_max] where ``mag(w) < level``; inf if none."""
    w = np.geomspace(w_max * 1e-5, w_max, 600)
    below = np.nonzero(mag(w) < level)[0]
    if below.size == 0:
        return math.inf
    k = int(below[0])
    if k == 0:
        return float(w[0])
    return float(brentq(lambda x: float(np.ravel(mag(x))[0]) - level, w[k - 1], w[k], xtol=1e-12, rtol=1e-10))


def _margins(loop):
    """(gm, pm, sm, wpc, wgc) of a SISO loop, as :func:`control.stability_margins` picks them.

    Two corrections for sampled loops with an integrator: the static "crossing"
    at w = 0 (where |L| is infinite) is dropped, and the Nyquist frequency
    ``pi/dt`` counts as a phase crossover when ``L(-1) < 0``: the ZOH'd loop of
    a PD on eq. (18) reaches -180° exactly there, and python-control 0.10's
    polynomial and FRD searches miss that end point.
    """
    with warnings.catch_warnings():
        # python-control falls back from 'poly' to 'frd' for discrete loops and says so
        warnings.simplefilter("ignore")
        gms, pms, sms, w180, wcs, _ = control.stability_margins(loop, returnall=True)
    gms, w180 = np.atleast_1d(np.asarray(gms, float)), np.atleast_1d(np.asarray(w180, float))
    keep = (w180 > 1e-9) & (gms > 0)
    gms, w180 = list(gms[keep]), list(w180[keep])
    if loop.isdtime(strict=True):
        at_nyquist = complex(np.squeeze(loop(-1.0)))
        w_nyq = math.pi / float(loop.dt)
        if at_nyquist.real < 0 and not any(abs(w - w_nyq) < 1e-6 * w_nyq for w in w180):
            gms.append(1.0 / abs(at_nyquist))
            w180.append(w_nyq)
    gms, w180 = np.array(gms), np.array(w180)
    pms, wcs, sms = np.atleast_1d(pms), np.atleast_1d(wcs), np.atleast_1d(sms)
    if gms.size and np.any(np.isfinite(gms)):
        j = int(np.argmin(np.abs(np.log(gms))))
        gm, wpc = float(gms[j]), float(w180[j])
    else:
        gm, wpc = math.inf, math.nan
    if pms.size:
        j = int(np.argmin(np.abs(pms)))
        pm, wgc = float(pms[j]), float(wcs[j])
    else:
        pm, wgc = math.inf, math.nan
    sm = float(np.min(sms)) if sms.size else math.inf
    return gm, pm, sm, wpc, wgc


def loop_analysis(params: ModelParams, axis, kp: float, kd: float, dt: float = 0.01,
                  delay_steps: int = 0) -> LoopAnalysis:
    """Margins, bandwidth, poles and disturbance responses of one axis under the PD law.

    The controller acts as ``C = s (kp + kd s)`` on the attitude error (the
    derivative is the measured rate error); the loop is broken at the stick.
    With ``dt > 0`` everything is computed for the sampled loop the environment
    runs (ZOH plant via :func:`control.c2d`, see the module docstring); margins
    from :func:`control.stability_margins`, bandwidth from
    :func:`closed_loop_bandwidth`, poles from :func:`control.poles` of the
    closed loop.

    Parameters
    ----------
    params : ModelParams
    axis : {"roll", "pitch", "yaw"} or int
    kp : float
        Proportional gain [stick/rad], >= 0.
    kd : float
        Derivative gain [stick/(rad/s)], >= 0.
    dt : float
        Control period [s]; 0 for the continuous-time analysis.
    delay_steps : int
        Periods of action delay (the environment's ``action_delay``).

    Returns
    -------
    LoopAnalysis
    """
    i = _axis_index(axis)
    if np.ndim(kp) or np.ndim(kd):
        raise ValueError(f"kp and kd must be numbers for one axis, got kp={kp!r}, kd={kd!r}")
    gains = PDGains(kp, kd)  # checks
    kp, kd = gains.kp[0], gains.kd[0]
    dt = _check_dt(dt)
    nd = _check_delay(delay_steps, dt)
    s = control_sign(params, i)
    k = float(params.control_gains[i])
    A, B, C = _sampled(params, i, dt, nd)
    bu, bd = B[:, :1], B[:, 1:]
    K = s * np.array([[kp, kd]])
    KC = K @ C
    loop = _tf(control.ss(A, bu, KC, 0.0, dt))
    Acl = A - bu @ KC
    n = A.shape[0]
    angle = C[:1]
    cl_d = control.ss(Acl, bd, angle, 0.0, dt)
    outputs = np.vstack([C, -KC])
    dist = control.ss(Acl, k * bd, outputs, np.zeros((3, 1)), dt)
    ref = control.ss(Acl, bu * (s * kp), angle, 0.0, dt)
    poles = np.asarray(control.poles(control.ss(Acl, np.zeros((n, 1)), np.zeros((1, n)), 0.0, dt)), dtype=complex)
    stable = bool(np.all(np.abs(poles) < 1.0)) if dt else bool(np.all(poles.real < 0.0))
    P = plant(params, i)
    loop_c = control.tf([s * kd, s * kp], [1.0]) * P
    T = control.feedback(loop, 1)
    gm, pm, sm, wpc, wgc = _margins(loop)
    bw = closed_loop_bandwidth(T) if kp > 0 and stable else math.nan
    torque = _tf(cl_d)
    return LoopAnalysis(
        axis=AXES[i], kp=kp, kd=kd, dt=dt, delay_steps=nd, sign=s, plant=P, loop=loop, loop_continuous=loop_c,
        gain_margin=gm, phase_margin=pm, stability_margin=sm, phase_crossover=wpc, gain_crossover=wgc,
        bandwidth=bw, poles=poles, stable=stable, complementary=T, reference_to_angle=_tf(ref),
        torque_to_angle=torque, ud_to_angle=k * torque, disturbance_system=dist,
    )


# ----------------------------------------------------------------------- design
class _Responses:
    """Fast frequency responses of the signed stick-to-angle and stick-to-rate channels (numpy)."""

    def __init__(self, params, axis, dt, delay_steps):
        self.dt = dt
        self.sign = control_sign(params, axis)
        A, B, C = _sampled(params, axis, dt, delay_steps)
        self.A, self.b, self.C = A, B[:, 0], C

    def stable(self, kp, kd) -> bool:
        """Closed-loop stability of the gains (eigenvalues of A - b s [kp, kd] C)."""
        ev = np.linalg.eigvals(self.A - self.sign * np.outer(self.b, kp * self.C[0] + kd * self.C[1]))
        return bool(np.all(np.abs(ev) < 1.0)) if self.dt else bool(np.all(ev.real < 0.0))

    def __call__(self, w):
        w = np.atleast_1d(np.asarray(w, dtype=float))
        z = np.exp(1j * w * self.dt) if self.dt else 1j * w
        n = self.A.shape[0]
        M = z[:, None, None] * np.eye(n) - self.A
        x = np.linalg.solve(M, np.broadcast_to(self.b.astype(complex), (w.size, n))[..., None])[..., 0]
        g = self.sign * (x @ self.C.T)  # (nw, 2): angle, rate
        return g[:, 0], g[:, 1]


def _design_at(resp: _Responses, wc: float, pm: float):
    """PD gains putting the loop's crossover at ``wc`` with phase margin ``pm`` [deg], or None.

    Solves ``kp G_angle + kd G_rate = -exp(1j pm)`` at ``wc`` (two real
    equations). If that needs kd < 0 the plant alone already has more margin:
    pure P is returned (margin above ``pm``). kp < 0 means the phase lead a PD
    can give is not enough: None; so is a design whose closed loop is unstable
    (the phase has wrapped past -180° at ``wc``).
    """
    ga, gr = resp(wc)
    ga, gr = complex(ga[0]), complex(gr[0])
    target = -np.exp(1j * math.radians(pm))
    M = np.array([[ga.real, gr.real], [ga.imag, gr.imag]])
    try:
        kp, kd = np.linalg.solve(M, [target.real, target.imag])
    except np.linalg.LinAlgError:
        return None
    if not (kp >= 0 and kd >= 0):
        p_only = 180.0 + math.degrees(np.angle(ga))  # in (0, 360]; above 180 the lag has wrapped past -180
        if not (kd < 0 and abs(ga) > 0 and pm <= p_only <= 180.0):
            return None
        kp, kd = 1.0 / abs(ga), 0.0
    return (float(kp), float(kd)) if resp.stable(kp, kd) else None


def _bandwidth_of(resp: _Responses, kp: float, kd: float) -> float:
    def mag(w):
        ga, gr = resp(w)
        L = kp * ga + kd * gr
        return np.abs(L / (1.0 + L))

    w_max = math.pi / resp.dt if resp.dt else 1e4
    return _first_drop(mag, _HALF_POWER, w_max)


def _bw_at(resp: _Responses, wc: float, pm: float) -> float:
    """Bandwidth of the design at crossover ``wc`` and margin ``pm``; -1 where there is none."""
    g = _design_at(resp, wc, pm)
    return _bandwidth_of(resp, *g) if g else -1.0


def _max_bandwidth(resp: _Responses, pm: float, w_grid) -> float:
    """Largest closed-loop bandwidth over the designs with crossover on ``w_grid`` and margin ``pm`` (-1: none)."""
    bws = np.array([_bw_at(resp, w, pm) for w in w_grid])
    return float(np.max(np.where(np.isfinite(bws), bws, -1.0)))


def propose_gains(params: ModelParams, axis, bandwidth: float | None = None, phase_margin: float = 45.0,
                  dt: float = 0.01, delay_steps: int = 0):
    """PD gains reaching a closed-loop bandwidth with at least a phase margin.

    For a crossover frequency ``wc`` the two gains follow in closed form from
    ``L(wc) = -exp(j*phase_margin)`` (a complex equation in kp, kd, on the
    sampled loop when ``dt > 0``); ``wc`` is then found with
    :func:`scipy.optimize.brentq` so that the bandwidth of ``T = L/(1+L)``
    equals the request. Where the plant alone has more phase than asked, a
    pure P controller is used and the margin is larger than requested. The
    result is checked with :func:`loop_analysis`.

    Parameters
    ----------
    params : ModelParams
    axis : {"roll", "pitch", "yaw"} or int
    bandwidth : float, optional
        Requested -3 dB bandwidth of ``T`` [rad/s]. Default: five times the bare
        airframe's rate pole (k3, k7, k11; at least 1 rad/s), i.e. a loop five
        times faster than the open-loop rate response, or half the largest
        bandwidth the phase margin allows if that is lower.
    phase_margin : float
        Least phase margin [deg], in (0, 180).
    dt : float
        Control period [s] (0: continuous time).
    delay_steps : int
        Periods of action delay.

    Returns
    -------
    kp : float
        [stick/rad]
    kd : float
        [stick/(rad/s)]
    analysis : LoopAnalysis

    Raises
    ------
    ValueError
        The request is infeasible; the message gives the best phase margin a PD
        reaches at the requested bandwidth and the largest bandwidth at the
        requested margin.
    """
    i = _axis_index(axis)
    dt = _check_dt(dt)
    nd = _check_delay(delay_steps, dt)
    if not (isinstance(phase_margin, (int, float, np.floating)) and 0 < phase_margin < 180):
        raise ValueError(f"phase_margin must be in (0, 180) degrees, got {phase_margin!r}")
    resp = _Responses(params, i, dt, nd)
    w_top = 0.98 * math.pi / dt if dt else 1e3
    w_grid = np.geomspace(1e-2, w_top, 160)
    bw_max = _max_bandwidth(resp, phase_margin, w_grid)
    if bandwidth is None:
        A, _, _ = _axis_ss(params, i)
        bandwidth = min(5.0 * max(abs(A[0, 0]), 1.0), 0.5 * bw_max)
        if not bandwidth > 0:
            raise ValueError(f"{AXES[i]}: no PD gains give a phase margin of {phase_margin:g} deg")
    if not (isinstance(bandwidth, (int, float, np.floating)) and math.isfinite(bandwidth) and bandwidth > 0):
        raise ValueError(f"bandwidth must be a positive frequency in rad/s, got {bandwidth!r}")
    bandwidth = float(bandwidth)
    if bandwidth > bw_max:
        best = _best_margin(resp, bandwidth, w_grid, phase_margin)
        at = ("no phase margin at all" if best is None else f"at most {best:.1f} deg of phase margin")
        raise ValueError(
            f"{AXES[i]}: a PD controller cannot reach a bandwidth of {bandwidth:g} rad/s with a phase margin of "
            f"{phase_margin:g} deg (dt={dt:g} s): at that bandwidth it has {at}; with {phase_margin:g} deg "
            f"the largest bandwidth is {max(bw_max, 0.0):.3g} rad/s"
        )
    # the first crossover frequency whose design reaches the bandwidth, refined by brentq
    grid = np.geomspace(min(1e-3 * bandwidth, w_grid[0]), w_top, 240)
    bws = np.array([_bw_at(resp, w, phase_margin) for w in grid])
    k = int(np.argmax(bws >= bandwidth))
    wc = grid[0] if k == 0 else brentq(lambda x: _bw_at(resp, x, phase_margin) - bandwidth, grid[k - 1], grid[k],
                                       xtol=1e-12, rtol=1e-12)
    design = _design_at(resp, wc, phase_margin)
    if design is None:  # the bandwidth is only reached where the designs stop existing
        raise ValueError(f"{AXES[i]}: no PD design reaches {bandwidth:g} rad/s with a phase margin of "
                         f"{phase_margin:g} deg; ask for a lower bandwidth or margin")
    kp, kd = design
    an = loop_analysis(params, i, kp, kd, dt, nd)
    if not (an.stable and an.phase_margin >= phase_margin - 1e-6):
        raise ValueError(
            f"{AXES[i]}: the design for {bandwidth:g} rad/s (kp={kp:.4g}, kd={kd:.4g}) has a phase margin of only "
            f"{an.phase_margin:.1f} deg at another crossover ({an.gain_crossover:.3g} rad/s); ask for a lower "
            "bandwidth"
        )
    return kp, kd, an


def _best_margin(resp, bandwidth, w_grid, upper):
    """Largest phase margin (deg, below ``upper``) whose designs still reach ``bandwidth``; None if none."""
    lo, hi = 0.0, float(upper)
    if _max_bandwidth(resp, 1e-3, w_grid) < bandwidth:
        return None
    while hi - lo > 0.01:
        mid = 0.5 * (lo + hi)
        if _max_bandwidth(resp, mid, w_grid) >= bandwidth:
            lo = mid
        else:
            hi = mid
    return lo


def design_gains(params: ModelParams, bandwidth=None, phase_margin: float = 45.0, dt: float = 0.01,
                 delay_steps: int = 0) -> PDGains:
    """:func:`propose_gains` on roll, pitch and yaw; ``bandwidth`` is one value, three, or None.

    Returns
    -------
    PDGains
    """
    bws = [bandwidth] * 3 if bandwidth is None or np.ndim(bandwidth) == 0 else list(bandwidth)
    if len(bws) != 3:
        raise ValueError(f"bandwidth must be None, a number or 3 numbers (roll, pitch, yaw), got {bandwidth!r}")
    out = [propose_gains(params, a, b, phase_margin, dt, delay_steps)[:2] for a, b in zip(AXES, bws)]
    return PDGains(kp=[g[0] for g in out], kd=[g[1] for g in out])


# ---------------------------------------------------------------------- figures
def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_step_responses(params: ModelParams, gains: PDGains, path, dt: float = 0.01, delay_steps: int = 0,
                        t_final: float | None = None) -> Path:
    """Closed-loop attitude step responses of the three axes (:func:`control.step_response`).

    Solid: a step of the reference angle with zero reference rate (derivative on
    the measured rate, the "track" task's steps). Dashed: ``T = L/(1+L)``, where
    the reference rate is fed too. Saved atomically.

    Parameters
    ----------
    params : ModelParams
    gains : PDGains
    path : str or Path
        PNG file.
    dt, delay_steps
        As :func:`loop_analysis`.
    t_final : float, optional
        Duration [s]; default 40/bandwidth of the slowest axis (0.5 s to 30 s).
    """
    plt = _pyplot()
    analyses = [loop_analysis(params, a, *gains.axis(a), dt, delay_steps) for a in AXES]
    if t_final is None:
        bws = [a.bandwidth for a in analyses if a.bandwidth and math.isfinite(a.bandwidth) and a.bandwidth > 0]
        t_final = min(max(40.0 / min(bws), 0.5), 30.0) if bws else 5.0
    fig, axs = plt.subplots(1, 3, figsize=(13, 3.8), sharey=False)
    for ax, an in zip(axs, analyses):
        t = np.arange(0.0, t_final + 0.5 * max(dt, 1e-9), dt) if dt else np.linspace(0, t_final, 1000)
        for sys, style, label in ((an.reference_to_angle, "-", "reference step (rate ref 0)"),
                                  (an.complementary, "--", "T = L/(1+L)")):
            r = control.step_response(sys, T=t)
            y = np.squeeze(r.outputs)
            if not an.stable:
                y = np.clip(y, -5, 5)
            ax.plot(r.time, y, style, drawstyle="steps-post" if dt else "default", label=label)
        ax.axhline(1.0, color="0.6", lw=0.8)
        state = "stable" if an.stable else "UNSTABLE"
        ax.set_title(f"{an.axis}: kp={an.kp:.3g}, kd={an.kd:.3g} ({state})\n"
                     f"PM {an.phase_margin:.1f}°, GM {an.gain_margin_db:.1f} dB, bw {an.bandwidth:.3g} rad/s",
                     fontsize=9)
        ax.set_xlabel("time [s]")
        ax.grid(True, alpha=0.3)
    axs[0].set_ylabel("angle / reference [-]")
    axs[0].legend(fontsize=8)
    fig.suptitle(f"PD closed-loop step responses (dt = {dt:g} s, ZOH{'' if not delay_steps else f', delay {delay_steps}'})",
                 fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def plot_bode(params: ModelParams, axis, kp: float, kd: float, path, dt: float = 0.01, delay_steps: int = 0) -> Path:
    """Bode plot of the loop ``L`` with its gain and phase margins marked; saved atomically.

    The sampled loop (the environment's) is drawn with its margins; the
    continuous loop ``s (kp + kd s) P(s)`` is overlaid dashed to show what the
    zero-order hold and any delay cost in phase.
    """
    plt = _pyplot()
    an = loop_analysis(params, axis, kp, kd, dt, delay_steps)
    w_hi = math.pi / dt if dt else 1e3
    omega = np.geomspace(1e-2, w_hi * (0.999 if dt else 1.0), 800)
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    for sys, style, label in ((an.loop, "-", f"L (sampled, dt={dt:g} s)" if dt else "L"),
                              (an.loop_continuous, "--", "L without sampling")):
        if sys is an.loop_continuous and not dt:
            continue
        resp = control.frequency_response(sys, omega)
        mag = np.squeeze(resp.magnitude)
        ph = np.degrees(np.unwrap(np.squeeze(resp.phase)))
        ph -= 360.0 * np.round(ph[0] / 360.0 + 0.25)  # start near -90 deg (integrator)
        ax_m.semilogx(omega, 20 * np.log10(mag), style, label=label)
        ax_p.semilogx(omega, ph, style)
    ax_m.axhline(0.0, color="k", lw=0.7)
    ax_p.axhline(-180.0, color="k", lw=0.7)
    if math.isfinite(an.gain_crossover):
        ax_m.axvline(an.gain_crossover, color="C2", ls=":", lw=1)
        ax_p.axvline(an.gain_crossover, color="C2", ls=":", lw=1)
        ax_p.annotate("", xy=(an.gain_crossover, -180.0 + an.phase_margin), xytext=(an.gain_crossover, -180.0),
                      arrowprops=dict(arrowstyle="<->", color="C2"))
        ax_p.text(an.gain_crossover * 1.1, -180.0 + 0.5 * an.phase_margin, f"PM {an.phase_margin:.1f}°", color="C2")
    if math.isfinite(an.phase_crossover) and math.isfinite(an.gain_margin):
        ax_m.axvline(an.phase_crossover, color="C3", ls=":", lw=1)
        ax_p.axvline(an.phase_crossover, color="C3", ls=":", lw=1)
        ax_m.annotate("", xy=(an.phase_crossover, 0.0), xytext=(an.phase_crossover, -an.gain_margin_db),
                      arrowprops=dict(arrowstyle="<->", color="C3"))
        ax_m.text(an.phase_crossover / 1.1, -0.5 * an.gain_margin_db, f"GM {an.gain_margin_db:.1f} dB ", color="C3",
                  ha="right", va="center")
    if dt:
        for ax in (ax_m, ax_p):
            ax.axvline(math.pi / dt, color="0.5", lw=0.8)
        # placed in axes height (not data), so the final limits cannot push it out of the frame
        ax_m.text(math.pi / dt, 0.97, "Nyquist ", transform=ax_m.get_xaxis_transform(), ha="right", va="top",
                  fontsize=8, color="0.4")
    ax_m.set_ylabel("|L| [dB]")
    ax_p.set_ylabel("phase L [deg]")
    ax_p.set_xlabel("frequency [rad/s]")
    ax_m.legend(fontsize=8, loc="lower left")
    for ax in (ax_m, ax_p):
        ax.grid(True, which="both", alpha=0.3)
    ax_m.set_title(f"{an.axis} loop: kp={an.kp:.3g} stick/rad, kd={an.kd:.3g} stick/(rad/s); "
                   f"crossover {an.gain_crossover:.3g} rad/s, closed-loop bw {an.bandwidth:.3g} rad/s, "
                   f"{'stable' if an.stable else 'UNSTABLE'}", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


# ------------------------------------------------------------------------ policy
class PDController:
    """Discrete PD attitude policy with stable-baselines3's ``predict`` interface.

    Per step and axis ``action = clip(s * (kp * obs[0:3] + kd * obs[6:9]), -1, 1)``
    (see the module docstring): memoryless, so ``state`` is passed through and
    ``episode_start`` and ``deterministic`` are ignored. PD and RL agents go
    through one evaluator (``stable_baselines3.common.evaluation.evaluate_policy``).

    Parameters
    ----------
    gains : PDGains
    signs : sequence of 3 float
        Control-gain signs (+1 or -1) of roll, pitch, yaw; :meth:`from_model`
        takes them from the model's k2, k6, k10.
    """

    def __init__(self, gains: PDGains, signs=(1.0, 1.0, 1.0)):
        if not isinstance(gains, PDGains):
            raise ValueError(f"gains must be a PDGains, got {type(gains).__name__}")
        sg = np.asarray(signs, dtype=float)
        if sg.shape != (3,) or not np.all(np.abs(sg) == 1.0):
            raise ValueError(f"signs must be three values of +1 or -1 (roll, pitch, yaw), got {signs!r}")
        self.gains = gains
        self.signs = tuple(float(v) for v in sg)
        self._kp, self._kd, self._sign = np.array(gains.kp, dtype=float), np.array(gains.kd, dtype=float), sg

    @classmethod
    def from_model(cls, params: ModelParams, gains: PDGains) -> "PDController":
        """The controller for a model: signs of its control gains (k2, k6, k10)."""
        return cls(gains, [control_sign(params, a) for a in AXES])

    def __repr__(self):
        return f"PDController(kp={self.gains.kp}, kd={self.gains.kd}, signs={self.signs})"

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = False):
        """Actions for one observation ``(12,)`` or a batch ``(n, 12)``.

        Parameters
        ----------
        observation : array_like, shape (12,) or (n, 12)
            Observations of ``HeliAttitude-v0`` (attitude error [rad], rates
            [rad/s], rate error [rad/s], previous action).
        state, episode_start, deterministic
            SB3's interface; unused (the law has no memory).

        Returns
        -------
        action : ndarray of float32, shape (3,) or (n, 3)
            lat, lon, ped offsets from trim in [-1, 1].
        state
            ``state`` unchanged.
        """
        return np.clip(self.command(observation), -1.0, 1.0).astype(np.float32), state

    def command(self, observation) -> np.ndarray:
        """The unclipped command ``sign * (kp * attitude_error + kd * rate_error)`` [stick], float64,
        shape (3,) or (n, 3); :meth:`predict` clips it (a residual agent adds to it first)."""
        obs = np.asarray(observation, dtype=np.float64)
        if obs.ndim not in (1, 2) or obs.shape[-1] != OBS_DIM:
            raise ValueError(f"observation must have shape ({OBS_DIM},) or (n, {OBS_DIM}), got {obs.shape}")
        return pd_command(self._kp, self._kd, self._sign, obs[..., 0:3], obs[..., 6:9])  # the one PD law

    def document(self, metadata=None) -> dict:
        """The JSON document :meth:`save` writes."""
        return jsonable({
            "schema": SCHEMA, "schema_version": SCHEMA_VERSION,
            "law": "action = clip(sign * (kp * attitude_error + kd * rate_error), -1, 1) per axis",
            "axes": list(AXES), "kp": self.gains.kp, "kd": self.gains.kd, "signs": self.signs,
            "units": {"kp": "stick/rad", "kd": "stick/(rad/s)", "signs": "-"},
            "metadata": dict(metadata or {}),
        })

    def save(self, path, metadata=None) -> Path:
        """Write the controller as JSON, atomically. Returns the path.

        Parameters
        ----------
        path : str or Path
        metadata : dict, optional
            Stored as is (e.g. the model directory and the design margins).
        """
        return write_text(path, json.dumps(self.document(metadata), indent=2, allow_nan=False) + "\n")

    @classmethod
    def load(cls, path) -> "PDController":
        """Read a controller written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            No such file.
        ValueError
            Not a PD controller file, another schema version, or bad gains.
        """
        path = Path(path)
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: not a JSON PD controller file ({e})") from e
        if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
            got = doc.get("schema") if isinstance(doc, dict) else type(doc).__name__
            raise ValueError(f"{path}: expected schema {SCHEMA!r}, got {got!r}")
        if doc.get("schema_version") != SCHEMA_VERSION:
            raise ValueError(f"{path}: expected schema_version {SCHEMA_VERSION}, got {doc.get('schema_version')!r}")
        missing = [k for k in ("kp", "kd", "signs") if k not in doc]
        if missing:
            raise ValueError(f"{path}: missing {', '.join(missing)}")
        try:
            return cls(PDGains(doc["kp"], doc["kd"]), doc["signs"])
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from e
