"""PD gain design: the gains that reach a closed-loop bandwidth with at least a phase margin.

For a crossover frequency ``wc`` the two gains follow in closed form from
``L(wc) = -exp(j*phase_margin)`` on the loop the environment runs (sampled when
``dt > 0``, :mod:`controllers.pd.analysis`); the crossover is then searched so
that the closed loop's bandwidth is the one asked for (:func:`propose_gains`).
The frequency responses of the search are plain numpy (:class:`_Responses`);
the result is checked with :func:`controllers.pd.analysis.loop_analysis`.

The derivative filter
---------------------
A PD whose D term sees the raw gyro rate puts ``kd`` times the gyro noise on the
stick every period: the shipped model's designed PD moved its stick by 0.27 (roll) and
0.42 (pitch) RMS *per 10 ms step*, more than the stick's own RMS (0.18, 0.27). The
design can put a first-order low-pass on the D term
(:func:`controllers.pd.law.filtered_rate`) and design *with* it in the loop, so the
gains still reach the bandwidth and the phase margin asked for. Its cutoff follows the
rule ``f_c = N · ω_c / 2π`` (``N`` = :data:`D_FILTER_RATIO` times the loop's crossover
``ω_c``: far enough above the crossover that the filter's lag there, ``atan(1/N)``, stays a
few degrees, which the design makes up with lead at the cost of a little ``kp``), or is
given in Hz. ``d_filter_hz="auto"`` asks for the rule, the default of
``heli design`` (:data:`DEFAULT_D_FILTER`); the library's default stays None (no filter), so
the gains of existing callers do not change.
"""

from __future__ import annotations

import copy
import math

import numpy as np
from scipy.optimize import brentq

from heli_core.params import ModelParams
from heli_core.terms import AXES

from .analysis import _HALF_POWER, _first_drop, loop_analysis
from .controller import PDGains
from .law import _axis_index, check_cutoff, control_sign, derivative_pole, law_state_space
from .linearisation import _axis_ss, _check_delay, _check_dt, _sampled

D_FILTER_RATIO = 20.0
"""The derivative filter's cutoff as a multiple of the loop's crossover frequency (``d_filter_hz="auto"``).

Measured on the shipped model (``scripts/d_filter_study.py``, docs/controllers.md "The derivative filter"):
with the phase margin held, every filter costs ``kp`` (the design buys back the filter's lag with lead,
which lowers the gain at crossover) and the p90 grows with it. At 20 x crossover (about 22 Hz on roll and
pitch) the p90 grows by 3 % and the stick's RMS increment per period falls by 28 %; at 10 x by 10 % and
50 %. The default keeps the p90 within a few per cent; a lower cutoff is a choice (``--d-filter-hz``)."""
DEFAULT_D_FILTER = "auto"
"""``heli design``'s derivative filter: the :data:`D_FILTER_RATIO` rule."""


def check_d_filter(d_filter_hz):
    """None, ``"auto"`` or a cutoff > 0 [Hz]; ValueError otherwise."""
    if isinstance(d_filter_hz, str) and d_filter_hz == "auto":
        return d_filter_hz
    return check_cutoff(d_filter_hz)


class _Responses:
    """Fast frequency responses of the signed stick-to-angle and stick-to-(filtered) rate channels (numpy).

    ``d_filter`` is the design's filter request (None, "auto" or Hz); :meth:`at_crossover` gives the
    responses with the filter a design of crossover ``wc`` carries (``cutoff``, Hz or None).
    """

    def __init__(self, params, axis, dt, delay_steps, d_filter=None, ratio: float = D_FILTER_RATIO):
        self.dt = dt
        self.ratio = float(ratio)
        self.sign = control_sign(params, axis)
        A, B, C = _sampled(params, axis, dt, delay_steps)
        self.A, self.b, self.C = A, B[:, 0], C
        self.d_filter = check_d_filter(d_filter)
        self.cutoff = None if self.d_filter == "auto" else self.d_filter

    def at_crossover(self, wc: float) -> "_Responses":
        """These responses with the filter of a design crossing over at ``wc`` [rad/s]."""
        if self.d_filter != "auto":
            return self
        other = copy.copy(self)
        other.cutoff = self.ratio * wc / (2.0 * math.pi)
        return other

    def stable(self, kp, kd) -> bool:
        """Closed-loop stability of the gains with this filter (eigenvalues of the plant and the law closed)."""
        Ak, Bk, Ck, Dk = law_state_space(kp, kd, self.sign, self.cutoff, self.dt)
        b = self.b[:, None]
        Acl = np.block([[self.A - b @ Dk @ self.C, b @ Ck], [-Bk @ self.C, Ak]])
        ev = np.linalg.eigvals(Acl)
        return bool(np.all(np.abs(ev) < 1.0)) if self.dt else bool(np.all(ev.real < 0.0))

    def __call__(self, w):
        w = np.atleast_1d(np.asarray(w, dtype=float))
        z = np.exp(1j * w * self.dt) if self.dt else 1j * w
        n = self.A.shape[0]
        M = z[:, None, None] * np.eye(n) - self.A
        x = np.linalg.solve(M, np.broadcast_to(self.b.astype(complex), (w.size, n))[..., None])[..., 0]
        g = self.sign * (x @ self.C.T)  # (nw, 2): angle, rate
        return g[:, 0], g[:, 1] * self._filter(z)

    def _filter(self, z):
        """The derivative filter's response at ``z`` (``s`` in continuous time); 1 without one."""
        if self.cutoff is None:
            return 1.0
        if self.dt:
            a = derivative_pole(self.cutoff, self.dt)
            return (1.0 - a) * z / (z - a)
        return 1.0 / (1.0 + z / (2.0 * math.pi * self.cutoff))


def _design_at(resp: _Responses, wc: float, pm: float):
    """PD gains putting the loop's crossover at ``wc`` with phase margin ``pm`` [deg], or None.

    Solves ``kp G_angle + kd G_rate = -exp(1j pm)`` at ``wc`` (two real
    equations). If that needs kd < 0 the plant alone already has more margin:
    pure P is returned (margin above ``pm``). kp < 0 means the phase lead a PD
    can give is not enough: None; so is a design whose closed loop is unstable
    (the phase has wrapped past -180° at ``wc``). ``resp`` carries the filter of a
    design at ``wc`` (:meth:`_Responses.at_crossover`, called here).
    """
    resp = resp.at_crossover(wc)
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
    return _bandwidth_of(resp.at_crossover(wc), *g) if g else -1.0


def _max_bandwidth(resp: _Responses, pm: float, w_grid) -> float:
    """Largest closed-loop bandwidth over the designs with crossover on ``w_grid`` and margin ``pm`` (-1: none)."""
    bws = np.array([_bw_at(resp, w, pm) for w in w_grid])
    return float(np.max(np.where(np.isfinite(bws), bws, -1.0)))


def propose_gains(params: ModelParams, axis, bandwidth: float | None = None, phase_margin: float = 45.0,
                  dt: float = 0.01, delay_steps: int = 0, d_filter_hz=None,
                  d_filter_ratio: float = D_FILTER_RATIO):
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
    d_filter_hz : None, "auto" or float
        The derivative filter designed with (module docstring): None none, "auto" the cutoff
        ``d_filter_ratio`` times the crossover, a number the cutoff [Hz]. A pure P design
        carries none.
    d_filter_ratio : float
        The rule's multiple of the crossover (default :data:`D_FILTER_RATIO`), > 0.

    Returns
    -------
    kp : float
        [stick/rad]
    kd : float
        [stick/(rad/s)]
    analysis : LoopAnalysis
        With the filter chosen (``analysis.d_filter_hz``, Hz or None).

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
    if not (isinstance(d_filter_ratio, (int, float, np.floating)) and math.isfinite(d_filter_ratio)
            and d_filter_ratio > 0):
        raise ValueError(f"d_filter_ratio must be a positive multiple of the crossover, got {d_filter_ratio!r}")
    resp = _Responses(params, i, dt, nd, d_filter_hz, d_filter_ratio)
    w_top = 0.98 * math.pi / dt if dt else 1e3
    w_grid = np.geomspace(1e-2, w_top, 160)
    bandwidth = _feasible_bandwidth(params, resp, i, bandwidth, phase_margin, w_grid)
    wc = _crossover_for(resp, bandwidth, phase_margin, np.geomspace(min(1e-3 * bandwidth, w_grid[0]), w_top, 240))
    design = _design_at(resp, wc, phase_margin)
    if design is None:  # the bandwidth is only reached where the designs stop existing
        raise ValueError(f"{AXES[i]}: no PD design reaches {bandwidth:g} rad/s with a phase margin of "
                         f"{phase_margin:g} deg; ask for a lower bandwidth or margin")
    kp, kd = design
    cutoff = resp.at_crossover(wc).cutoff if kd > 0 else None
    an = loop_analysis(params, i, kp, kd, dt, nd, cutoff)
    if not (an.stable and an.phase_margin >= phase_margin - 1e-6):
        raise ValueError(
            f"{AXES[i]}: the design for {bandwidth:g} rad/s (kp={kp:.4g}, kd={kd:.4g}) has a phase margin of only "
            f"{an.phase_margin:.1f} deg at another crossover ({an.gain_crossover:.3g} rad/s); ask for a lower "
            "bandwidth"
        )
    return kp, kd, an


def _feasible_bandwidth(params, resp: _Responses, i: int, bandwidth, phase_margin: float, w_grid) -> float:
    """The bandwidth asked for (or the default of :func:`propose_gains`), checked to be reachable with
    ``phase_margin``; ValueError saying what is reachable otherwise."""
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
            f"{phase_margin:g} deg (dt={resp.dt:g} s): at that bandwidth it has {at}; with {phase_margin:g} deg "
            f"the largest bandwidth is {max(bw_max, 0.0):.3g} rad/s"
        )
    return bandwidth


def _crossover_for(resp: _Responses, bandwidth: float, phase_margin: float, grid) -> float:
    """The first crossover frequency on ``grid`` whose design reaches ``bandwidth``, refined by brentq [rad/s]."""
    bws = np.array([_bw_at(resp, w, phase_margin) for w in grid])
    k = int(np.argmax(bws >= bandwidth))
    return grid[0] if k == 0 else brentq(lambda x: _bw_at(resp, x, phase_margin) - bandwidth, grid[k - 1], grid[k],
                                         xtol=1e-12, rtol=1e-12)


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
                 delay_steps: int = 0, d_filter_hz=None, d_filter_ratio: float = D_FILTER_RATIO) -> PDGains:
    """:func:`propose_gains` on roll, pitch and yaw; ``bandwidth`` is one value, three, or None;
    ``d_filter_hz`` one request (None, "auto", Hz) or three, ``d_filter_ratio`` the rule's multiple.

    Returns
    -------
    PDGains
        With each axis' derivative filter (``d_filter_hz``).
    """
    bws = [bandwidth] * 3 if bandwidth is None or np.ndim(bandwidth) == 0 else list(bandwidth)
    if len(bws) != 3:
        raise ValueError(f"bandwidth must be None, a number or 3 numbers (roll, pitch, yaw), got {bandwidth!r}")
    cuts = [d_filter_hz] * 3 if d_filter_hz is None or isinstance(d_filter_hz, str) or np.ndim(d_filter_hz) == 0 \
        else list(d_filter_hz)
    if len(cuts) != 3:
        raise ValueError(f"d_filter_hz must be None, 'auto', a cutoff in Hz or 3 of them, got {d_filter_hz!r}")
    out = [propose_gains(params, a, b, phase_margin, dt, delay_steps, c, d_filter_ratio)
           for a, b, c in zip(AXES, bws, cuts)]
    return PDGains(kp=[g[0] for g in out], kd=[g[1] for g in out], d_filter_hz=[g[2].d_filter_hz for g in out])

