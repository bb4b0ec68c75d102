"""Gain and phase margins of every gain pair of a sweep, on the sampled loop the sweep already builds.

The sweep's stability verdicts come from the discrete closed loop of
:mod:`controllers.closed_loop` (the three-axis hover plant, the held axes closed
by their nominal gains). Its margins are those of the same loop broken at the
swept axis' stick::

    L(z) = kp·Hφ(z) + kd·Hr(z),   Hφ = s·e_angleᵀ (zI − A_o)⁻¹ b,   Hr = s·e_rateᵀ (zI − A_o)⁻¹ b

with ``A_o`` the sampled plant with the two held axes closed, ``b`` the swept
stick's column and ``s`` the sign of the axis' control gain. ``L`` is linear in
the gains, so ``Hφ`` and ``Hr`` are evaluated once on a frequency grid and every
pair's loop is a weighted sum of the two. Crossings are bracketed on the grid
and refined by bisection on the exact responses. The definitions are
:func:`control.stability_margins`' as :func:`controllers.pd.loop_analysis`
applies them: the gain margin is ``1/|L|`` at a phase crossover (``L`` real and
negative; the static crossing at ω = 0 left out, the Nyquist frequency ``π/dt``
counted when ``L(−1) < 0``) nearest to 1 on a log scale, the phase margin
``(∠L mod 360°) − 180°`` at the gain crossover ``|L| = 1`` of smallest
magnitude; no crossing is an infinite margin. For a decoupled model the loop is
:func:`controllers.pd.loop_analysis`' own and so are the margins (tested); with
coupling the held axes' loops are part of it, as they are of the verdicts.
"""

from __future__ import annotations

import math

import numpy as np

from .closed_loop import axis_index, gain_matrices

ROBUST_GAIN_MARGIN_DB = 6.0
"""Gain margin [dB] a *robust* pair keeps (the usual 6 dB, as ``scripts/train_compare.py``)."""
ROBUST_PHASE_MARGIN_DEG = 45.0
"""Phase margin [deg] a *robust* pair keeps."""
MARGIN_COLUMNS = ("gain_margin_db", "phase_margin_deg")
"""Columns the margins fill in a sweep's table (see :data:`controllers.sweep_result.COLUMNS`)."""

_N_FREQ = 2048
_BISECTIONS = 48
_PAIRS_PER_CHUNK = 256


def _broken_loop(plant, ax, nominal):
    """``(A_o, b, c_angle, c_rate)``: the sampled plant with the held axes closed, the swept stick's column
    and the rows of the PD law's slopes (unit kp, unit kd) on the swept axis."""
    K_held = gain_matrices(plant, ax, 0.0, 0.0, nominal)[0]  # the swept axis' row is zero
    A_o = plant.A - plant.Bu @ K_held
    c_angle = gain_matrices(plant, ax, 1.0, 0.0, nominal)[0, ax]
    c_rate = gain_matrices(plant, ax, 0.0, 1.0, nominal)[0, ax]
    return A_o, plant.Bu[:, ax], c_angle, c_rate


def _responses(loop, w, dt):
    """``(Hφ, Hr)`` at the frequencies ``w`` [rad/s] (any shape), each of ``w``'s shape."""
    A_o, b, c_angle, c_rate = loop
    n = A_o.shape[0]
    z = np.exp(1j * np.ravel(w) * dt)
    rhs = np.broadcast_to(b, (z.size, n)).astype(complex)[..., None]
    X = np.linalg.solve(z[:, None, None] * np.eye(n) - A_o, rhs)[..., 0]
    return (X @ c_angle).reshape(np.shape(w)), (X @ c_rate).reshape(np.shape(w))


def _crossings(loop, dt, kp, kd, part, grid, h_angle, h_rate):
    """Frequencies where ``part(L)`` changes sign between grid points, refined by bisection.

    Returns ``(pair index, L at the crossing)`` arrays, one entry per crossing.
    """
    values = part(kp[:, None] * h_angle[None] + kd[:, None] * h_rate[None])
    g, f = np.nonzero(values[:, :-1] * values[:, 1:] < 0.0)
    lo, hi = grid[f], grid[f + 1]
    s_lo = np.sign(values[g, f])
    p, d = kp[g], kd[g]
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        a, r = _responses(loop, mid, dt)
        same = np.sign(part(p * a + d * r)) == s_lo
        lo, hi = np.where(same, mid, lo), np.where(same, hi, mid)
    a, r = _responses(loop, 0.5 * (lo + hi), dt)
    return g, p * a + d * r


def _gain_part(L):
    return np.abs(L) - 1.0


def _nearest(values, pair, n_pairs, key):
    """Per pair, the entry of ``values`` (one per crossing, of pair ``pair``) with the smallest ``key``;
    +inf where a pair has no crossing."""
    out = np.full(n_pairs, math.inf)
    if values.size:
        order = np.lexsort((key, pair))  # by pair, then by key
        pairs, first = np.unique(pair[order], return_index=True)
        out[pairs] = values[order][first]
    return out


def loop_margins(plant, axis, kp, kd, nominal) -> tuple[np.ndarray, np.ndarray]:
    """Gain margin [dB] and phase margin [deg] of each pair's sampled loop, broken at the swept stick.

    Parameters
    ----------
    plant : controllers.closed_loop.HoverPlant
        The sweep's sampled hover plant.
    axis : {"roll", "pitch", "yaw"} or int
        Swept axis.
    kp, kd : array (G,)
        Gains of the swept axis [stick/rad], [stick/(rad/s)].
    nominal : array (3, 2)
        Gains of the held axes.

    Returns
    -------
    gain_margin_db, phase_margin_deg : ndarray (G,)
        +inf where the loop never reaches −180° (gain margin) or never crosses |L| = 1 (phase margin);
        negative for a loop the pair destabilises.
    """
    ax = axis_index(axis)
    kp = np.atleast_1d(np.asarray(kp, dtype=float))
    kd = np.atleast_1d(np.asarray(kd, dtype=float))
    dt = plant.dt
    loop = _broken_loop(plant, ax, nominal)
    w_nyq = math.pi / dt
    grid = np.geomspace(w_nyq * 1e-5, w_nyq, _N_FREQ)
    grid[-1] = w_nyq
    h_angle, h_rate = _responses(loop, grid, dt)
    h_angle[-1], h_rate[-1] = h_angle[-1].real, h_rate[-1].real  # z = -1: real; exp(1j*pi) is not quite
    gm = np.full(kp.size, math.inf)
    pm = np.full(kp.size, math.inf)
    for start in range(0, kp.size, _PAIRS_PER_CHUNK):
        sl = slice(start, min(kp.size, start + _PAIRS_PER_CHUNK))
        p, d = kp[sl], kd[sl]
        g, L = _crossings(loop, dt, p, d, np.imag, grid, h_angle, h_rate)
        left = L.real < 0.0  # the negative real axis; the Nyquist end point is real, counted on its own
        at_nyq = p * h_angle[-1].real + d * h_rate[-1].real
        g = np.concatenate([g[left], np.flatnonzero(at_nyq < 0.0)])
        factors = 1.0 / np.abs(np.concatenate([L[left], at_nyq[at_nyq < 0.0]]))  # L < 0 there: finite
        gm[sl] = _nearest(factors, g, p.size, np.abs(np.log(factors)))  # nearest to 1 on a log scale
        g, L = _crossings(loop, dt, p, d, _gain_part, grid, h_angle, h_rate)
        phase = np.remainder(np.angle(L, deg=True), 360.0) - 180.0
        pm[sl] = _nearest(phase, g, p.size, np.abs(phase))
    return 20.0 * np.log10(gm), pm  # inf stays inf


def robust(gain_margin_db, phase_margin_deg, min_gain_margin_db: float = ROBUST_GAIN_MARGIN_DB,
           min_phase_margin_deg: float = ROBUST_PHASE_MARGIN_DEG) -> np.ndarray:
    """Whether each pair keeps both margins (an infinite margin keeps any)."""
    gm = np.asarray(gain_margin_db, dtype=float)
    pm = np.asarray(phase_margin_deg, dtype=float)
    return (gm >= min_gain_margin_db) & (pm >= min_phase_margin_deg)
