"""The hover plant under per-axis PD attitude hold, linearised and sampled: stability and error spectra.

The gain sweep (:mod:`controllers.sweep`) needs two things from linear control
theory for every gain pair (paper Section 4 proposal):

* **stability** — the discrete closed-loop poles (python-control), so unstable
  pairs are reported as such and never simulated into NaN;
* **a frequency-domain prediction** of the error distribution — the
  disturbance spectrum of the library (Welch) passed through the closed-loop
  transfer function from the equivalent stick ``u_d`` (eq. 42) to the attitude
  error, the rate error and the stick.

The plant is the package's one linearisation of the physics core
(:func:`heli_core.linear.hover_linearisation`: about hover at the trim for the
given collective, every term of the model — the decoupled eqs. (18), (21),
coupling, the Padé servo of eq. (31), collective-scheduled gains — and the
attitude of eq. (25) at level flight). For the decoupled model each axis is
``k·Padé(servo)/(s(s+k_damp))`` from stick to angle. It is sampled by a zero-order hold at the control
period (``control.c2d``, the digital autopilot holds its stick over the period,
as the environments do). The physics core's discrete step integrates the
attitude with the mean of the start and end rates instead of exactly; the
difference is of order ``dt²`` and shows in the tests as < 1 % on the error
standard deviations.

The PD law is the one of :mod:`controllers.pd` (:func:`controllers.pd.law.pd_command`); for a
decoupled model the stability verdicts and spectral radii equal those of
:func:`controllers.pd.loop_analysis` (tested), while the plant here keeps all
three axes so that coupling terms are included.

A PD with a derivative filter (``hover_plant(..., d_filter_hz=)``) keeps the static
state feedback: each filtered axis adds a state ``w`` to the sampled plant, its filtered
rate ``w[k+1] = a w[k] + (1 - a) rate[k]`` (:func:`controllers.pd.law.filtered_rate`, pole
``a``), and the law reads ``a w + (1 - a) rate`` where it read the rate. Poles, margins,
the error spectra and the sensors' share then hold for the filtered PD the replay flies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from heli_core.linear import hover_linearisation
from heli_core.terms import AXES

from .errors import SweepError
from .pd.law import pd_command
STABILITY_MARGIN = 1e-9
"""A gain pair is stable when every discrete closed-loop pole has ``|z| < 1 - STABILITY_MARGIN``
(a pole on the unit circle, e.g. ``kp = 0``, lets the attitude drift and counts as unstable)."""
GAUSS_ABS_FACTOR = {50: 0.6744897501960817, 90: 1.6448536269514722, 99: 2.5758293035489004}
"""Percentiles of ``|e|`` for a zero-mean normal ``e`` of unit standard deviation (``norm.ppf((1 + q)/2)``)."""


def axis_index(axis) -> int:
    """0, 1, 2 for "roll", "pitch", "yaw" (or the index itself)."""
    if isinstance(axis, (int, np.integer)) and 0 <= int(axis) < 3:
        return int(axis)
    if axis in AXES:
        return AXES.index(axis)
    raise SweepError(f"axis must be one of {', '.join(AXES)}, got {axis!r}")


@dataclass(frozen=True, eq=False)
class HoverPlant:
    """The linearised hover plant, continuous and sampled (zero-order hold).

    State ``x``: body rates p, q, r [rad/s], the Padé servo states of delayed axes
    [stick], Euler angles roll, pitch, yaw [rad]. Inputs: stick offsets from trim
    ``u`` (lat, lon, ped) and the wind as equivalent sticks ``u_d`` (roll, pitch, yaw),
    entering as the torque ``k·u_d`` (eq. 42).

    Attributes
    ----------
    params : ModelParams
    dt : float
        Control period [s].
    collective : float
        Collective stick the model was linearised at.
    A, Bu, Bw : ndarray, shapes (n, n), (n, 3), (n, 3)
        Discrete-time ``x[k+1] = A x[k] + Bu u[k] + Bw u_d[k]``.
    Ac, Buc, Bwc : ndarray
        The continuous-time matrices.
    states : tuple of str
    rate_idx, angle_idx : ndarray of int, shape (3,)
        Where the rates and the angles sit in the state.
    signs : ndarray, shape (3,)
        Signs of the control gains (k2, k6, k10).
    d_poles : ndarray, shape (3,)
        Pole ``a`` of each axis' derivative filter at ``dt`` (0: none).
    filter_idx : ndarray of int, shape (3,)
        Where each filtered axis' filter state sits in the sampled state (after the physical states);
        -1 for an axis without a filter.
    """

    params: object
    dt: float
    collective: float
    A: np.ndarray
    Bu: np.ndarray
    Bw: np.ndarray
    Ac: np.ndarray
    Buc: np.ndarray
    Bwc: np.ndarray
    states: tuple
    rate_idx: np.ndarray
    angle_idx: np.ndarray
    signs: np.ndarray
    d_poles: np.ndarray = field(default_factory=lambda: np.zeros(3))
    filter_idx: np.ndarray = field(default_factory=lambda: np.full(3, -1))

    @property
    def n(self) -> int:
        return self.A.shape[0]


def hover_plant(params, dt: float, collective: float = 0.0, d_filter_hz=None) -> HoverPlant:
    """The physics core linearised about hover at the trim (:func:`heli_core.linear.hover_linearisation`, the
    package's one linearisation, which the PD design reads too) and sampled at ``dt`` (zero-order hold).

    ``d_filter_hz`` (None, one cutoff [Hz] or three, None for an axis without) appends each filtered axis'
    derivative-filter state to the sampled plant (module docstring); the continuous matrices stay physical.
    """
    import control

    gains = params.control_gains
    if np.any(gains == 0.0):
        raise SweepError(f"the model has a zero control gain (k2, k6, k10 = {gains.tolist()}); it cannot be controlled")
    lin = hover_linearisation(params, float(collective))
    n = lin.A.shape[0]
    Bwc = lin.Bd * gains[None, :]  # torque k*u_d per unit equivalent stick, eq. (42)
    sysd = control.c2d(control.ss(lin.A, np.hstack([lin.Bu, Bwc]), np.eye(n), np.zeros((n, 6))), dt, method="zoh")
    A, B = np.asarray(sysd.A), np.asarray(sysd.B)
    poles = d_poles_of(d_filter_hz, dt)
    filter_idx = np.full(3, -1)
    for i in np.flatnonzero(poles > 0):  # w[k+1] = a w[k] + (1 - a) rate[k]: a state after the physical ones
        m = A.shape[0]
        A = np.block([[A, np.zeros((m, 1))], [np.zeros((1, m + 1))]])
        A[m, lin.rate_idx[i]], A[m, m] = 1.0 - poles[i], poles[i]
        B = np.vstack([B, np.zeros((1, 6))])
        filter_idx[i] = m
    return HoverPlant(params, float(dt), float(collective), A, B[:, :3], B[:, 3:], lin.A, lin.Bu,
                      Bwc, lin.states, lin.rate_idx, lin.angle_idx, np.sign(gains), poles, filter_idx)


def d_cutoffs(d_filter_hz):
    """A derivative-filter request as results record it: None (no filter) or a list of 3 cutoffs [Hz] or None."""
    if d_filter_hz is None:
        return None
    cuts = [d_filter_hz] * 3 if np.ndim(d_filter_hz) == 0 else list(d_filter_hz)
    return [None if c is None else float(c) for c in cuts]


def d_poles_of(d_filter_hz, dt: float) -> np.ndarray:
    """Each axis' derivative-filter pole at ``dt`` (:func:`controllers.pd.law.derivative_pole`), shape (3,).

    ``d_filter_hz``: None (no filter), one cutoff [Hz] for every axis, or three (None for an axis without);
    :class:`SweepError` for anything else.
    """
    from .pd.law import derivative_pole

    cuts = [d_filter_hz] * 3 if d_filter_hz is None or np.ndim(d_filter_hz) == 0 else list(d_filter_hz)
    try:
        if len(cuts) != 3:
            raise ValueError(f"d_filter_hz must be None, a cutoff in Hz or 3 of them (roll, pitch, yaw), got "
                             f"{d_filter_hz!r}")
        return np.array([derivative_pole(c, dt) for c in cuts])
    except ValueError as e:
        raise SweepError(str(e)) from e


def nominal_gains(plant: HoverPlant, bandwidth: float = 4.0, damping: float = 0.7) -> np.ndarray:
    """PD gains that hold each axis near hover while another axis is swept, shape (3, 2) = (kp, kd).

    Pole placement on the decoupled plant ``k/(s(s + a))`` (``a`` the axis' damping,
    ``k`` the control gain): ``kp = ω²/|k|``, ``kd = max(2ζω − a, 0)/|k|`` with
    ``ω = bandwidth`` [rad/s] and ``ζ = damping``. Checked for stability on the
    full linear plant by :func:`closed_loop_poles` in the sweep.
    """
    a = -np.diag(plant.Ac)[:3]
    k = np.abs(plant.params.control_gains)
    kp = bandwidth**2 / k
    kd = np.maximum(2.0 * damping * bandwidth - a, 0.0) / k
    return np.column_stack([kp, kd])


def gain_matrices(plant: HoverPlant, axis: int, kp, kd, nominal) -> np.ndarray:
    """State-feedback matrices ``K`` (u = −K x) of the PD law for each gain pair, shape (G, 3, n).

    The swept ``axis`` gets ``kp[g], kd[g]``; the other two axes their ``nominal`` (3, 2) gains.
    Each row is the slope of :func:`pd_command` in the angle and in the rate (the law is linear,
    so these are exactly ``sign·kp`` and ``sign·kd``); a filtered axis splits the rate's slope
    into ``(1 - a)`` on the rate and ``a`` on its filter state.
    """
    kp = np.atleast_1d(np.asarray(kp, dtype=float))
    kd = np.atleast_1d(np.asarray(kd, dtype=float))
    G = kp.size
    K = np.zeros((G, 3, plant.n))
    for i in range(3):
        p_i, d_i = (kp, kd) if i == axis else (np.full(G, nominal[i][0]), np.full(G, nominal[i][1]))
        K[:, i, plant.angle_idx[i]] = pd_command(p_i, d_i, plant.signs[i], 1.0, 0.0)
        rate = pd_command(p_i, d_i, plant.signs[i], 0.0, 1.0)
        if plant.filter_idx[i] < 0:
            K[:, i, plant.rate_idx[i]] = rate
        else:
            a = plant.d_poles[i]
            K[:, i, plant.rate_idx[i]], K[:, i, plant.filter_idx[i]] = (1.0 - a) * rate, a * rate
    return K


def _outputs(plant: HoverPlant, axis: int, K: np.ndarray) -> np.ndarray:
    """Output matrices (G, 3, n): attitude error, rate error, stick offset on ``axis`` (errors = −state)."""
    C = np.zeros((K.shape[0], 3, plant.n))
    C[:, 0, plant.angle_idx[axis]] = -1.0
    C[:, 1, plant.rate_idx[axis]] = -1.0
    C[:, 2, :] = -K[:, axis, :]
    return C


def closed_loop_system(plant: HoverPlant, axis, kp: float, kd: float, nominal):
    """The discrete closed loop of one gain pair as a python-control ``StateSpace``.

    Inputs: ``u_d`` roll, pitch, yaw [stick]. Outputs: attitude error [rad], rate
    error [rad/s] and stick offset from trim (before clipping) on ``axis``.
    """
    import control

    ax = axis_index(axis)
    K = gain_matrices(plant, ax, kp, kd, nominal)
    A = plant.A - plant.Bu @ K[0]
    return control.ss(A, plant.Bw, _outputs(plant, ax, K)[0], np.zeros((3, 3)), plant.dt)


def closed_loop_poles(plant: HoverPlant, axis, kp, kd, nominal) -> tuple[np.ndarray, np.ndarray]:
    """Largest closed-loop pole magnitude of each gain pair and whether the loop is stable.

    Poles from python-control (``StateSpace.poles``) of the sampled closed loop.

    Returns
    -------
    max_abs : ndarray (G,)
        Spectral radius of the discrete closed loop.
    stable : ndarray of bool (G,)
        ``max_abs < 1 - STABILITY_MARGIN``.
    """
    import control

    ax = axis_index(axis)
    K = gain_matrices(plant, ax, kp, kd, nominal)
    A_cl = plant.A[None] - plant.Bu[None] @ K
    max_abs = np.array([np.max(np.abs(control.ss(a, plant.Bw, np.eye(plant.n), 0.0, plant.dt).poles()))
                        for a in A_cl])
    return max_abs, max_abs < 1.0 - STABILITY_MARGIN


def replay_segments(env_model, dt: float) -> list:
    """Each library trace's replayed u_d (:attr:`heli_env.env_model.EnvModel.replay_ud`) taken every ``dt``
    (the samples the replay uses), as (3, m) views, in the library's order."""
    ratio = int(round(dt * env_model.sample_rate))
    return [env_model.replay_ud[:, s:s + n:ratio] for s, n in zip(env_model.starts, env_model.lengths)]


def disturbance_spectrum(env_model, dt: float, nperseg: int = 2048) -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectral density of the library's ``u_d`` per axis (Welch), at the control period.

    The u_d is the replayed gust in this model's stick units
    (:attr:`heli_env.env_model.EnvModel.replay_ud`). Each trace is taken every
    ``dt`` (the samples the replay uses), its mean removed (u_d is zero-mean by
    definition, eq. 42), its Welch estimate (Hann
    window, ``nperseg`` samples, half overlap, *no* per-segment detrending, which
    would remove the gusts slower than a segment and lose ~7 % of the variance of
    the shipped library) computed, and the traces averaged weighted by their lengths.

    Returns
    -------
    freq : ndarray (nf,)
        [Hz], 0 to the Nyquist frequency of ``dt``.
    psd : ndarray (3, nf)
        [stick²/Hz]; ``sum(psd) * df`` is the variance of u_d.
    """
    from scipy.signal import welch

    segs = replay_segments(env_model, dt)
    nps = int(min(nperseg, min(s.shape[1] for s in segs)))
    if nps < 16:
        raise SweepError(f"the disturbance traces are too short for a spectrum ({nps} samples at dt={dt} s)")
    weights = np.array([s.shape[1] for s in segs], dtype=float)
    psd = 0.0
    for w, s in zip(weights, segs):
        freq, p = welch(s - s.mean(axis=1, keepdims=True), fs=1.0 / dt, nperseg=nps, detrend=False, axis=-1)
        psd = psd + w * p
    return freq, psd / weights.sum()


def _frequency_grid(freq: np.ndarray, dt: float, n_freq: int) -> tuple[np.ndarray, np.ndarray]:
    """Integration grid: 0 plus ``n_freq`` geometrically spaced points to Nyquist, trapezoid weights.

    Geometric spacing resolves the narrow resonances of lightly damped loops
    (relative spacing ~0.3 % for 4096 points) that the Welch grid would step over.
    """
    f_lo = min(freq[1] / 10.0, 1e-3)
    g = np.concatenate([[0.0], np.geomspace(f_lo, 0.5 / dt, n_freq)])
    w = np.zeros_like(g)
    dg = np.diff(g)
    w[:-1] += dg / 2
    w[1:] += dg / 2
    return g, w


def predict_std(plant: HoverPlant, axis, kp, kd, nominal, freq, psd, n_freq: int = 4096,
                chunk: int = 16) -> np.ndarray:
    """Standard deviations predicted in the frequency domain for each gain pair, shape (G, 3).

    ``σ² = Σ_j ∫ |H_j(e^{i2πf·dt})|² S_j(f) df`` over ``0 … 1/(2 dt)``, where ``H_j`` is the
    closed loop from ``u_d`` on axis ``j`` to the output and ``S_j`` the Welch spectrum
    of ``u_d`` (:func:`disturbance_spectrum`), interpolated linearly onto a fine
    geometric grid.
    The gusts of the three axes are taken as independent (cross-spectra
    neglected); for a decoupled model only the swept axis' own gust matters.
    ``H`` is evaluated from the eigen-decomposition of the closed loop (partial
    fractions; a direct solve for a near-defective pair), the same values as
    ``control.frequency_response`` a hundred times faster.

    Returns
    -------
    ndarray (G, 3)
        σ of the attitude error [rad], the rate error [rad/s], the stick offset
        from trim before clipping [stick]. NaN for unstable pairs.
    """
    ax = axis_index(axis)
    K = gain_matrices(plant, ax, kp, kd, nominal)
    G = K.shape[0]
    C = _outputs(plant, ax, K)
    A_cl = plant.A[None] - plant.Bu[None] @ K
    g, w = _frequency_grid(freq, plant.dt, n_freq)
    S = np.array([np.interp(g, freq, p) for p in psd])  # (3, F)
    inputs = [j for j in range(3) if np.any(plant.Bw[:, j] != 0.0) and np.any(S[j] > 0)]
    Sw = S[inputs] * w[None, :]  # (J, F) spectrum times quadrature weight
    Bw = plant.Bw[:, inputs]
    z = np.exp(2j * math.pi * g * plant.dt)
    out = np.full((G, 3), np.nan)
    lam, V = np.linalg.eig(A_cl)
    stable = np.max(np.abs(lam), axis=1) < 1.0 - STABILITY_MARGIN
    cond = np.linalg.cond(V)
    # Partial fractions H(z) = sum_i R_i / (z - lam_i), residues R (G, 3 outputs, J inputs, n).
    VB = np.linalg.solve(V, np.broadcast_to(Bw, (G,) + Bw.shape).astype(complex))  # (G, n, J)
    R = (C @ V)[:, :, None, :] * VB.transpose(0, 2, 1)[:, None, :, :]
    # Inputs whose gust never reaches the swept axis (decoupled models) are left out.
    reach = np.max(np.abs(R), axis=(0, 1, 3))
    keep = reach > 1e-12 * max(reach.max(), 1e-300)
    R, Sw, Bw = R[:, :, keep], Sw[keep], Bw[:, keep]
    J = int(keep.sum())
    SwT = np.ascontiguousarray(Sw.T)  # (F, J)
    for start in range(0, G, chunk):
        idx = np.arange(start, min(G, start + chunk))
        idx = idx[stable[idx]]
        if idx.size == 0:
            continue
        good = idx[cond[idx] < 1e8]
        if good.size:
            # sum over the n modes by hand: tiny batched matmuls through a threaded BLAS stall
            # badly when the machine is busy
            Rg = R[good].reshape(good.size, 3 * J, plant.n)
            lam_g = lam[good]
            H = np.zeros((good.size, z.size, 3 * J), dtype=complex)
            for i in range(plant.n):
                H += (1.0 / (z[None, :] - lam_g[:, i:i + 1]))[:, :, None] * Rg[:, None, :, i]
            H2 = (H.real**2 + H.imag**2).reshape(good.size, z.size, 3, J)
            out[good] = (H2 * SwT[None, :, None, :]).sum(axis=(1, 3))
        for gi in idx[cond[idx] >= 1e8]:  # near-defective: solve (zI - A) X = B directly
            M = z[:, None, None] * np.eye(plant.n)[None] - A_cl[gi][None]
            X = np.linalg.solve(M, np.broadcast_to(Bw, (z.size,) + Bw.shape).astype(complex))  # (F, n, J)
            H = C[gi][None] @ X  # (F, 3, J)
            out[gi] = (np.abs(H) ** 2 * SwT[:, None, :]).sum(axis=(0, 2))
    return np.sqrt(out)


def sensor_noise_std(plant: HoverPlant, axis, kp, kd, nominal, sensors) -> np.ndarray:
    """Standard deviations the sensors add to each gain pair's outputs, shape (G, 3), NaN where unstable.

    The autopilot acts on the measured state, ``u = -K (x + n)``, so the noise enters the closed loop
    through ``-Bu K`` (and a derivative filter's state through ``(1 - a)`` times the measured rate). White noise (``sensors.attitude_noise``, ``sensors.gyro_noise`` per axis, sampled
    each period) gives the state covariance of the discrete Lyapunov equation
    ``P = A_cl P A_clᵀ + Bn Σ Bnᵀ`` (scipy); the stick also carries ``K n`` itself, uncorrelated with the
    state it acts on. Each vibration line (a sinusoid of amplitude ``a``, as the autopilot samples it)
    adds ``a²/2 |H(e^{iωdt})|²``. Added in variance to :func:`predict_std`'s gust prediction.
    """
    from scipy.linalg import solve_discrete_lyapunov

    ax = axis_index(axis)
    K = gain_matrices(plant, ax, kp, kd, nominal)
    G, n = K.shape[0], plant.n
    C = _outputs(plant, ax, K)
    N = np.zeros((n, 6))  # noise channels: attitude of each axis, then rate of each axis
    for i in range(3):
        N[plant.angle_idx[i], i] = 1.0
        N[plant.rate_idx[i], 3 + i] = 1.0
    F = np.zeros((n, 6))  # a filter's state integrates the measured rate
    for i in np.flatnonzero(plant.filter_idx >= 0):
        F[plant.filter_idx[i], 3 + i] = 1.0 - plant.d_poles[i]
    Sigma = np.diag(np.square(np.concatenate([sensors.attitude_noise, sensors.gyro_noise])))
    line_axis, line_omega, line_amp = sensors.line_arrays()
    out = np.full((G, 3), np.nan)
    for g in range(G):
        A_cl = plant.A - plant.Bu @ K[g]
        if np.max(np.abs(np.linalg.eigvals(A_cl))) >= 1.0 - STABILITY_MARGIN:
            continue
        Bn = -plant.Bu @ K[g] @ N + F  # (n, 6)
        P = solve_discrete_lyapunov(A_cl, Bn @ Sigma @ Bn.T)
        var = np.einsum("oi,ij,oj->o", C[g], P, C[g])
        Kn = K[g] @ N  # the stick's own noise (row ax of -K n)
        var[2] += Kn[ax] @ Sigma @ Kn[ax]
        for a, w, amp in zip(line_axis, line_omega, line_amp):
            z = np.exp(1j * w * plant.dt)
            h = C[g] @ np.linalg.solve(z * np.eye(n) - A_cl, Bn[:, 3 + a])  # (3,) outputs
            h[2] += -Kn[ax, 3 + a]  # the stick sees the line directly too
            var += 0.5 * amp * amp * np.abs(h) ** 2
        out[g] = np.sqrt(var)
    return out
