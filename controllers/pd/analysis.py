"""Loop analysis of one axis under PD control: margins, bandwidth, poles, disturbance responses.

The environment samples the observation every ``dt`` and holds the action over
the period (zero-order hold), then integrates the linear part exactly
(:func:`heli_core.discrete.discrete_step`, matrix exponential). The analysis
here therefore discretises the plant with :func:`control.c2d` (``'zoh'``) and
closes the loop in discrete time: ``L(z) = s (kp G_phi(z) + kd F(z) G_p(z))``, where
``G_phi`` and ``G_p`` are the sampled stick-to-angle and stick-to-rate responses and
``F(z) = (1 - a) z / (z - a)`` the derivative filter the controller runs (1 without one;
:func:`controllers.pd.law.law_state_space`), so margins, poles and disturbance responses
are those of the filtered PD the controller's ``predict`` and the sweep's replay fly.
For the decoupled linear model this is the environment's own closed loop, so
the predicted stability is exact (``tests/test_pd.py`` checks gain pairs on both
sides of the boundary in the environment). The hold costs about ``omega*dt/2``
of phase, which the Bode figure shows against the continuous loop. ``dt=0``
gives the ideal continuous-time analysis.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import control
import numpy as np
from scipy.optimize import brentq

from heli_core.files import jsonable
from heli_core.params import ModelParams
from heli_core.terms import AXES

from .controller import PDGains
from .law import _axis_index, check_cutoff, control_sign, law_state_space
from .linearisation import _check_delay, _check_dt, _sampled, _tf, plant

_HALF_POWER = 10.0 ** (-3.0 / 20.0)


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
    d_filter_hz : float or None
        Cutoff of the derivative filter in the loop [Hz]; None: no filter.
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
    d_filter_hz: float | None = None

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
        return jsonable({"axis": self.axis, "kp": self.kp, "kd": self.kd, "d_filter_hz": self.d_filter_hz,
                         "dt": self.dt,
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
                  delay_steps: int = 0, d_filter_hz: float | None = None) -> LoopAnalysis:
    """Margins, bandwidth, poles and disturbance responses of one axis under the PD law.

    The controller acts as ``C = s (kp + kd F s)`` on the attitude error (the
    derivative is the measured rate error, ``F`` its low-pass when ``d_filter_hz`` is
    given); the loop is broken at the stick. With ``dt > 0`` everything is computed
    for the sampled loop the environment runs (ZOH plant via :func:`control.c2d`, the
    filter as the controller samples it, see the module docstring); margins from
    :func:`control.stability_margins`, bandwidth from :func:`closed_loop_bandwidth`,
    poles from :func:`control.poles` of the closed loop.

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
    d_filter_hz : float, optional
        Cutoff of the derivative's first-order low-pass [Hz]; None: no filter.

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
    cutoff = check_cutoff(d_filter_hz)
    s = control_sign(params, i)
    k = float(params.control_gains[i])
    A, B, C = _sampled(params, i, dt, nd)
    cl = _closed_loop(A, B, C, law_state_space(kp, kd, s, cutoff, dt))
    loop = _tf(control.series(control.ss(A, B[:, :1], C, np.zeros((2, 1)), dt), control.ss(*cl.law, dt)))
    n = cl.A.shape[0]
    poles = np.asarray(control.poles(control.ss(cl.A, np.zeros((n, 1)), np.zeros((1, n)), 0.0, dt)), dtype=complex)
    stable = bool(np.all(np.abs(poles) < 1.0)) if dt else bool(np.all(poles.real < 0.0))
    P = plant(params, i)
    loop_c = control.tf([s * kd, s * kp], [1.0]) * P
    if cutoff is not None:
        w_f = 2.0 * math.pi * cutoff
        loop_c = control.tf([s * kp / w_f, s * (kp + kd * w_f) / w_f], [1.0 / w_f, 1.0]) * P
    T = control.feedback(loop, 1)
    gm, pm, sm, wpc, wgc = _margins(loop)
    bw = closed_loop_bandwidth(T) if kp > 0 and stable else math.nan
    torque = _tf(control.ss(cl.A, cl.bd, cl.angle, 0.0, dt))
    dist = control.ss(cl.A, k * cl.bd, cl.outputs, np.zeros((3, 1)), dt)
    ref = control.ss(cl.A, cl.bu_ref * (s * kp), cl.angle, 0.0, dt)
    return LoopAnalysis(
        axis=AXES[i], kp=kp, kd=kd, dt=dt, delay_steps=nd, sign=s, plant=P, loop=loop, loop_continuous=loop_c,
        gain_margin=gm, phase_margin=pm, stability_margin=sm, phase_crossover=wpc, gain_crossover=wgc,
        bandwidth=bw, poles=poles, stable=stable, complementary=T, reference_to_angle=_tf(ref),
        torque_to_angle=torque, ud_to_angle=k * torque, disturbance_system=dist, d_filter_hz=cutoff,
    )


@dataclass(frozen=True, eq=False)
class _Closed:
    """The closed loop of plant ``(A, B, C)`` and the law ``(Ak, Bk, Ck, Dk)``: state ``(x, w)``."""

    A: np.ndarray
    bd: np.ndarray
    bu_ref: np.ndarray
    angle: np.ndarray
    outputs: np.ndarray
    law: tuple


def _closed_loop(A, B, C, law) -> _Closed:
    """``x' = A x + b_u u + b_d d``, ``w' = Ak w + Bk e``, ``u = Ck w + Dk e``, ``e = -C x`` (reference 0).

    Outputs of :attr:`_Closed.outputs`: angle [rad], rate [rad/s], stick [stick, before clipping];
    ``bu_ref`` is the stick's column, through which a reference angle enters as ``s kp r``.
    """
    Ak, Bk, Ck, Dk = law
    n, m = A.shape[0], Ak.shape[0]
    bu, bd = B[:, :1], B[:, 1:]
    Acl = np.block([[A - bu @ Dk @ C, bu @ Ck], [-Bk @ C, Ak]])
    pad = np.zeros((m, 1))
    angle = np.hstack([C[:1], np.zeros((1, m))])
    outputs = np.vstack([np.hstack([C, np.zeros((2, m))]), np.hstack([-Dk @ C, Ck])])
    return _Closed(Acl, np.vstack([bd, pad]), np.vstack([bu, pad]), angle, outputs, law)
