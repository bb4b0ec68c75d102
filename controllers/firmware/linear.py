"""The firmware loops linearised and closed around the linearised hover plant, at the loop's own tick.

What a gain sweep needs for every candidate set, in the frequency domain:

* **the loop's own linearisation** (:func:`linearise`): the tick of the firmware loop itself
  (:meth:`~controllers.firmware.loop.FirmwareLoop.tick`) probed by central differences about rest — memory
  0, no error, no rate — so that the matrices are the implementation's, not a second derivation of it.
  About rest every branch is linear: the square-root controller is in its linear band, the integrator below
  its leak threshold and its limit, no output clamped (the saturation flag is held at 0, the one memory row
  left out of the state). The result is ``x⁺ = A x + B y``, ``u = C x + D y`` with ``y`` = (attitude error,
  gyro) per axis and ``u`` the stick offsets (the command scale and signs applied);
* **the closed loop at the tick** ``h = 1/loop_rate`` (:func:`closed_loop`): the physics core linearised
  about hover and sampled at ``h`` (:func:`controllers.closed_loop.hover_plant`, zero-order hold: the stick
  is held over a tick), the loop reading the attitude error ``−angle`` and the body rates at each tick;
* **lifted to the control period** ``T = m·h`` over which the replayed gust is held
  (:func:`lifted`): ``A_T = A_clᵐ``, ``B_T = Σ_{j<m} A_clʲ B_w``, exact for a gust held over ``T`` and
  records at the period's start, as :func:`controllers.replay.fly` takes them;
* **the error's standard deviation** (:func:`attitude_std`): the library's Welch spectrum of ``u_d`` at
  ``T`` through the lifted loop, as :func:`controllers.closed_loop.predict_std` does for the PD law;
* **gain and phase margins** of the loop broken at one stick, at the tick (:func:`stick_margins`), with the
  definitions of :mod:`controllers.sweep_margins`.

For a PD law the same construction gives :mod:`controllers.closed_loop`'s matrices (tested: with the
firmware's filters off, I and FF zero, the linearised ArduPilot loop is ``u = −s·A_P(FF + P)·φ − s·P·p``,
the PD it maps to).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from heli_core.terms import AXES

from ..closed_loop import STABILITY_MARGIN, hover_plant

PROBE = 1e-7
"""Central-difference step of the probes [rad, rad/s and memory units]."""
_N_FREQ = 1500
_N_MARGIN = 2500


@dataclass(frozen=True, eq=False)
class LinearController:
    """``G`` firmware loops linearised about rest: ``x⁺ = A x + B y``, ``u = C x + D y``.

    Attributes
    ----------
    A : ndarray (G, n, n)
    B : ndarray (G, n, 6)
        Inputs ``y``: attitude error roll, pitch, yaw [rad], then gyro p, q, r [rad/s].
    C : ndarray (G, 3, n)
    D : ndarray (G, 3, 6)
        Outputs ``u``: stick offsets lat, lon, ped [stick] (scale and signs applied).
    rows : ndarray of int
        The memory rows probed (the loop's flag row left out).
    states : ndarray of int
        Which of the probed states (row-major over ``rows`` × axes) are kept: those that reach the output.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    rows: np.ndarray
    states: np.ndarray


def _state_rows(loop) -> np.ndarray:
    """Memory rows that are linear state: all but the last (the saturation flag of both firmwares)."""
    return np.arange(loop.memory_rows - 1)


def linearise(loop) -> LinearController:
    """The loop's tick probed about rest (module docstring), one linear controller per parameter set.

    Parameters
    ----------
    loop : FirmwareLoop
        Built from a sequence of ``G`` sets (arrays (3, G) per tick) or one set.
    """
    G = loop.sets
    single = loop.single
    rows = _state_rows(loop)
    nx = rows.size * 3
    shape = () if single else (G,)

    def run(x_flat, y):
        """Outputs (G, 3) and next states (G, nx) for states (G, nx) and inputs (G, 6)."""
        mem = loop.initial_memory(shape)
        body = np.moveaxis(x_flat.reshape((G, rows.size, 3)), 0, -1)  # (rows, 3, G)
        mem[rows] = body[..., 0] if single else body
        e = y[:, 0:3].T if not single else y[0, 0:3]
        g = y[:, 3:6].T if not single else y[0, 3:6]
        out, new, _ = loop.tick(mem, e, g)
        u = loop.sticks(out)
        if single:
            return u[None, :], new[rows].reshape(1, nx)
        return u.T, np.moveaxis(new[rows], -1, 0).reshape(G, nx)

    cols_x, cols_y = [], []
    zero_x, zero_y = np.zeros((G, nx)), np.zeros((G, 6))
    for j in range(nx):
        dx = zero_x.copy()
        dx[:, j] = PROBE
        (up, xp), (um, xm) = run(dx, zero_y), run(-dx, zero_y)
        cols_x.append(((up - um) / (2 * PROBE), (xp - xm) / (2 * PROBE)))
    for j in range(6):
        dy = zero_y.copy()
        dy[:, j] = PROBE
        (up, xp), (um, xm) = run(zero_x, dy), run(zero_x, -dy)
        cols_y.append(((up - um) / (2 * PROBE), (xp - xm) / (2 * PROBE)))
    C = np.stack([c[0] for c in cols_x], axis=-1)
    A = np.stack([c[1] for c in cols_x], axis=-1)
    D = np.stack([c[0] for c in cols_y], axis=-1)
    B = np.stack([c[1] for c in cols_y], axis=-1)
    keep = _influential(A, C)
    return LinearController(A[:, keep][:, :, keep], B[:, keep], C[:, :, keep], D, rows, keep)


def _influential(A: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Indices of the states that reach the output: a state that moves neither the output nor another kept
    state (an integrator whose gain is 0, a filter of a term whose gain is 0) is memory the linear loop never
    reads, and its eigenvalue (often 1) would be taken for an unstable mode. Dropped when so in every set."""
    n = A.shape[-1]
    keep = np.ones(n, dtype=bool)
    changed = True
    while changed:
        changed = False
        for j in np.flatnonzero(keep):
            others = keep.copy()
            others[j] = False
            if not np.any(C[:, :, j]) and not np.any(A[:, others, j]):
                keep[j] = False
                changed = True
    return np.flatnonzero(keep)


@dataclass(frozen=True, eq=False)
class ClosedLoop:
    """Plant and loops closed at the tick ``h``: ``z⁺ = A z + Bw u_d``, ``z = (plant state, loop state)``.

    Attributes
    ----------
    A : ndarray (G, N, N)
    Bw : ndarray (N, 3)
        Per unit equivalent stick of gust ``u_d`` (roll, pitch, yaw), torque ``k·u_d`` (eq. 42).
    h : float
        Tick [s].
    plant : HoverPlant
        The plant sampled at ``h``.
    ctrl : LinearController
    measure : ndarray (6, n_p)
        Loop inputs from the plant state: ``−angle`` then rates.
    """

    A: np.ndarray
    Bw: np.ndarray
    h: float
    plant: object
    ctrl: LinearController
    measure: np.ndarray

    @property
    def n_plant(self) -> int:
        return self.plant.n

    def stable(self, axis: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(spectral radius (G,), stable (G,)) of the tick's closed loop, neutral constants left out.

        A mode at exactly ``z = 1`` that the gusts cannot excite is a conserved constant, not an instability:
        Rotorflight's tail holds the integral of the yaw rate (its I-term), not a heading, so heading plus the
        accumulated error stays where it started. Such modes (``|λ − 1| < 1e-8`` and a gust input below 1e-9 of
        the largest) are left out of the radius. With ``axis``, only the modes that show in that axis' attitude
        or rate (a component above 1e-9 of the largest) count: on a decoupled plant an unstable roll loop does
        not make the tail's unstable.
        """
        radius = np.empty(self.A.shape[0])
        rows = None
        if axis is not None:
            rows = np.zeros((2, self.A.shape[-1]))
            rows[0, self.plant.angle_idx[axis]] = 1.0
            rows[1, self.plant.rate_idx[axis]] = 1.0
        for g, A in enumerate(self.A):
            if not np.all(np.isfinite(A)):  # a plant whose discretisation overflowed (a damping of 1e300/s)
                radius[g] = np.inf
                continue
            lam, V = np.linalg.eig(A)
            mags = np.abs(lam)
            if rows is not None:
                seen = np.abs(rows @ V).max(axis=0) / np.maximum(np.abs(V).max(axis=0), 1e-300)
                mags = np.where(seen > 1e-9, mags, 0.0)
            near = np.abs(lam - 1.0) < 1e-8
            if np.any(near):
                try:
                    reach = np.abs(np.linalg.solve(V, self.Bw.astype(complex))).max(axis=1)
                    mags = np.where(near & (reach < 1e-9 * max(reach.max(), 1e-300)), 0.0, mags)
                except np.linalg.LinAlgError:
                    pass
            radius[g] = mags.max()
        return radius, radius < 1.0 - STABILITY_MARGIN

    def angle_row(self, axis: int) -> np.ndarray:
        """Row (N,) giving the attitude error ``−angle`` of ``axis`` from the state."""
        row = np.zeros(self.A.shape[-1])
        row[self.plant.angle_idx[axis]] = -1.0
        return row


def measurement(plant) -> np.ndarray:
    """The loop inputs (6, n) from the plant state: attitude error ``−angle`` (3), then body rates (3)."""
    M = np.zeros((6, plant.n))
    for i in range(3):
        M[i, plant.angle_idx[i]] = -1.0
        M[3 + i, plant.rate_idx[i]] = 1.0
    return M


def closed_loop(params, loop, collective: float = 0.0) -> ClosedLoop:
    """The linearised plant (sampled at the loop's tick) and the linearised loops, closed (module docstring)."""
    h = loop.dt
    plant = hover_plant(params, h, collective)
    ctrl = linearise(loop)
    M = measurement(plant)
    G, nc = ctrl.A.shape[0], ctrl.A.shape[1]
    n = plant.n
    A = np.zeros((G, n + nc, n + nc))
    A[:, :n, :n] = plant.A[None] + plant.Bu[None] @ ctrl.D @ M[None]
    A[:, :n, n:] = plant.Bu[None] @ ctrl.C
    A[:, n:, :n] = ctrl.B @ M[None]
    A[:, n:, n:] = ctrl.A
    Bw = np.zeros((n + nc, 3))
    Bw[:n] = plant.Bw
    return ClosedLoop(A, Bw, h, plant, ctrl, M)


def lifted(cl: ClosedLoop, m: int) -> tuple[np.ndarray, np.ndarray]:
    """``(A_T (G, N, N), B_T (G, N, 3))``: ``m`` ticks with the gust held (module docstring)."""
    G, N = cl.A.shape[0], cl.A.shape[1]
    A_T = np.broadcast_to(np.eye(N), (G, N, N)).copy()
    B_T = np.zeros((G, N, 3))
    for _ in range(m):
        B_T = B_T + A_T @ cl.Bw[None]
        A_T = cl.A @ A_T
    return A_T, B_T


def attitude_std(cl: ClosedLoop, m: int, axis: int, freq: np.ndarray, psd: np.ndarray,
                 n_freq: int = _N_FREQ) -> np.ndarray:
    """Standard deviation of the attitude error of ``axis`` [rad] in the library's gusts, per set (G,).

    ``σ² = Σ_j ∫ |H_j(e^{i2πfT})|² S_j(f) df`` over ``0 … 1/(2T)``, ``H_j`` the lifted loop from the gust of
    axis ``j`` to the error, ``S_j`` the Welch spectrum at ``T = m·h``
    (:func:`controllers.closed_loop.disturbance_spectrum`), on a geometric grid with trapezoid weights. NaN
    where the tick's loop is unstable.
    """
    from ..closed_loop import _frequency_grid

    T = cl.h * m
    A_T, B_T = lifted(cl, m)
    _, stable = cl.stable(axis)
    grid, w = _frequency_grid(freq, T, n_freq)
    S = np.array([np.interp(grid, freq, p) for p in psd]) * w[None, :]  # (3, F)
    z = np.exp(2j * math.pi * grid * T)
    c = cl.angle_row(axis)
    out = np.full(A_T.shape[0], np.nan)
    N = A_T.shape[1]
    for g in np.flatnonzero(stable):
        lam, V = np.linalg.eig(A_T[g])
        if np.linalg.cond(V) < 1e8:
            left = c @ V  # (N,)
            right = np.linalg.solve(V, B_T[g])  # (N, 3)
            res = left[:, None] * right
            # modes the gusts do not reach (a neutral constant at z = 1, see ClosedLoop.stable) add nothing
            reach = np.abs(right).max(axis=1)
            neutral = (np.abs(lam - 1.0) < 1e-8) & (reach < 1e-9 * max(reach.max(), 1e-300))
            live = (np.abs(res).max(axis=1) > 1e-12 * max(np.abs(res).max(), 1e-300)) & ~neutral
            H = (res[live][None, :, :] / (z[:, None, None] - lam[live][None, :, None])).sum(axis=1)
        else:
            M = z[:, None, None] * np.eye(N)[None] - A_T[g][None]
            H = (c[None, None, :] @ np.linalg.solve(M, np.broadcast_to(B_T[g], (z.size, N, 3))))[:, 0, :]
        out[g] = math.sqrt(float(np.sum((H.real**2 + H.imag**2) * S.T)))
    return out


def _axis_block(ctrl: LinearController, g: int, axis: int):
    """``(A, B, C, D)`` of set ``g``'s loop on ``axis`` alone: its memory rows, inputs (error, gyro) of the axis,
    its stick. Both firmwares' loops are per axis (their cross terms are 0 about rest)."""
    idx = np.flatnonzero(ctrl.states % 3 == axis)
    cols = [axis, 3 + axis]
    return (ctrl.A[g][np.ix_(idx, idx)], ctrl.B[g][np.ix_(idx, cols)], ctrl.C[g][axis, idx],
            ctrl.D[g][axis, cols])


def _block_response(block, z: np.ndarray) -> np.ndarray:
    """``C (zI − A)⁻¹ B + D`` of an axis block at ``z`` (F,): (F, 2)."""
    A, B, C, D = block
    X = np.linalg.solve(z[:, None, None] * np.eye(A.shape[0])[None] - A[None],
                        np.broadcast_to(B.astype(complex), (z.size,) + B.shape))
    return np.einsum("i,fij->fj", C, X) + D[None, :]


def _held_plant(cl: ClosedLoop, g: int, axis: int):
    """``(A, b, Cy)``: the sampled plant with the other two axes closed by set ``g``'s loops, from ``axis``'
    stick to that axis' loop inputs (attitude error, gyro)."""
    plant, M = cl.plant, cl.measure
    n = plant.n
    blocks = [(i, _axis_block(cl.ctrl, g, i)) for i in range(3) if i != axis]
    sizes = [b[1][0].shape[0] for b in blocks]
    N = n + sum(sizes)
    A = np.zeros((N, N))
    A[:n, :n] = plant.A
    at = n
    for (i, (Ak, Bk, Ck, Dk)), size in zip(blocks, sizes):
        y_i = M[[i, 3 + i]]  # (2, n)
        A[:n, :n] += np.outer(plant.Bu[:, i], Dk @ y_i)
        A[:n, at:at + size] = np.outer(plant.Bu[:, i], Ck)
        A[at:at + size, :n] = Bk @ y_i
        A[at:at + size, at:at + size] = Ak
        at += size
    b = np.zeros(N)
    b[:n] = plant.Bu[:, axis]
    Cy = np.zeros((2, N))
    Cy[:, :n] = M[[axis, 3 + axis]]
    return A, b, Cy


def _held_response(held, z: np.ndarray) -> np.ndarray:
    """The held plant's response (F, 2) at ``z`` (F,)."""
    A, b, Cy = held
    X = np.linalg.solve(z[:, None, None] * np.eye(A.shape[0])[None] - A[None],
                        np.broadcast_to(b.astype(complex), (z.size, b.size))[..., None])[..., 0]
    return X @ Cy.T


def _same_held_axes(ctrl: LinearController, axis: int) -> bool:
    """Whether every set flies the two other axes with the same loop (a sweep of ``axis``)."""
    for i in range(3):
        if i == axis:
            continue
        ref = _axis_block(ctrl, 0, i)
        for g in range(1, ctrl.A.shape[0]):
            if not all(np.array_equal(a, b) for a, b in zip(ref, _axis_block(ctrl, g, i))):
                return False
    return True


def _decoupled(plant, axis: int) -> bool:
    """Whether ``axis``' states (rate, servo, angle) and stick are apart from the other axes' in the sampled
    plant: then the other axes' loops do not enter the broken loop, whatever their gains."""
    own = [int(plant.rate_idx[axis]), int(plant.angle_idx[axis])]
    own += [i for i, name in enumerate(plant.states) if name == f"servo_{AXES[axis]}"]
    others = [i for i in range(plant.n) if i not in own]
    other_sticks = [i for i in range(3) if i != axis]
    return (not np.any(plant.A[np.ix_(own, others)]) and not np.any(plant.A[np.ix_(others, own)])
            and not np.any(plant.Bu[np.ix_(own, other_sticks)]) and not np.any(plant.Bu[np.ix_(others, [axis])]))


def _margins_of(L: np.ndarray, grid: np.ndarray) -> tuple[float, float, float]:
    """(gain margin factor, phase margin [deg], delay margin [s]) of a loop gain ``L`` on ``grid`` [rad/s] (its
    last point the Nyquist frequency), crossings by linear interpolation (:func:`stick_margins`)."""
    factors = []
    im = L.imag
    for f in np.flatnonzero(im[:-2] * im[1:-1] < 0):
        t = im[f] / (im[f] - im[f + 1])
        x = L[f] + t * (L[f + 1] - L[f])
        if x.real < 0:
            factors.append(1.0 / abs(x.real))
    if L[-1].real < 0:
        factors.append(1.0 / abs(L[-1].real))
    gm = min(factors, key=lambda v: abs(math.log(v))) if factors else math.inf
    mag = np.abs(L) - 1.0
    phases, delays = [], []
    for f in np.flatnonzero(mag[:-1] * mag[1:] < 0):
        t = mag[f] / (mag[f] - mag[f + 1])
        x = L[f] + t * (L[f + 1] - L[f])
        phase = float(np.remainder(np.angle(x, deg=True), 360.0) - 180.0)
        phases.append(phase)
        w = grid[f] * (grid[f + 1] / grid[f]) ** t
        delays.append(math.radians(phase) / w if phase > 0 else 0.0)
    pm = min(phases, key=abs) if phases else math.inf
    dm = min(delays) if delays else math.inf
    return gm, pm, dm


def stick_margins(cl: ClosedLoop, axis: int, sets=None, delay: bool = False):
    """Gain [dB] and phase [deg] margins of the loop broken at ``axis``' stick, per set, at the tick.

    ``L(z) = −K(z)·P(z)``: ``K`` the set's loop on ``axis`` (attitude error and gyro in, stick out), ``P`` the
    plant sampled at the tick with the other two axes closed, from the stick to those two inputs; both on a
    geometric grid of 2500 frequencies up to the Nyquist frequency ``π/h`` (spacing 0.37 %), crossings by
    linear interpolation. Definitions of :mod:`controllers.sweep_margins`: the gain margin is ``1/|L|`` at a
    phase crossover (L real and negative; the Nyquist end counted when ``L(−1) < 0``) nearest to 1 on a log
    scale, the phase margin ``(∠L mod 360°) − 180°`` at the gain crossover of smallest ``|margin|``; +inf
    where there is none. With ``delay`` also the **delay margin** [s]: the smallest ``PM/ω`` over the gain
    crossovers, the extra transport delay (an unmodelled servo lag) that would bring the loop to the edge;
    0 where a crossover has no phase margin. NaN for sets not in ``sets`` (default: every set). When the
    other axes' loops do not enter (a decoupled plant) or every set holds them alike (a sweep of ``axis``),
    ``P`` is evaluated once.
    """
    G = cl.A.shape[0]
    gm = np.full(G, np.nan)
    pm = np.full(G, np.nan)
    dm = np.full(G, np.nan)
    w_nyq = math.pi / cl.h
    grid = np.geomspace(w_nyq * 1e-4, w_nyq, _N_MARGIN)
    grid[-1] = w_nyq
    z = np.exp(1j * grid * cl.h)
    z[-1] = -1.0
    shared = _decoupled(cl.plant, axis) or _same_held_axes(cl.ctrl, axis)
    P = _held_response(_held_plant(cl, 0, axis), z) if shared else None
    for g in range(G) if sets is None else sets:
        Pg = P if shared else _held_response(_held_plant(cl, g, axis), z)
        K = _block_response(_axis_block(cl.ctrl, g, axis), z)
        L = -(K * Pg).sum(axis=1)
        L[-1] = L[-1].real
        gm[g], pm[g], dm[g] = _margins_of(L, grid)
    with np.errstate(divide="ignore"):
        gm_db = 20.0 * np.log10(gm)
    return (gm_db, pm, dm) if delay else (gm_db, pm)
