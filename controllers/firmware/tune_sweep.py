"""The frequency domain of a firmware tune: every candidate set's stability, margins and predicted p90.

For one axis a :class:`~controllers.firmware.firmwares.FirmwareSpec` gives a grid of its two swept gains
(the others as the aircraft flew them, the feed-forward from the model). Every grid point is one parameter
set; all of an axis' sets are linearised, closed around the hover plant at the loop's tick and lifted to the
gusts' period at once (:mod:`controllers.firmware.linear`). Per set: the tick's spectral radius (stable or
not), the gain, phase and delay margins of the loop broken at the axis' stick, and the p90 |attitude error| of a
Gaussian error with the standard deviation the library's spectrum gives (``1.645·σ``). A set is robust when it
keeps 6 dB, 45° and a delay margin (:data:`ROBUST_DELAY_MARGIN_S` by default). The time domain
(:mod:`controllers.firmware.tune`) then flies the best robust sets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..closed_loop import GAUSS_ABS_FACTOR
from ..sweep_margins import ROBUST_GAIN_MARGIN_DB, ROBUST_PHASE_MARGIN_DEG
from .linear import attitude_std, closed_loop, stick_margins

_DEG = 180.0 / np.pi
ROBUST_DELAY_MARGIN_S = 0.025
"""Default delay margin a robust set keeps besides 6 dB and 45° [s] (``heli tune --delay-margin``): the loop
survives 25 ms more transport delay than identified. Measured on the bench's agile aircraft, whose tail servo
delay of 20 ms the identification's ``--delay auto`` put at 0 (docs/firmware.md): without this criterion the
Rotorflight yaw sweep took ``yaw_p_gain`` and ``yaw_i_gain`` 1000 (66° of phase margin and 9.8 ms of delay
margin in the model) and the plain loop flying that file on the truth lost its heading (yaw p90 26° against 0.32°
predicted); with it the proposal flew 0.34°. 25 ms covers that error of the delay with a little to spare."""


@dataclass(frozen=True, eq=False)
class AxisSweep:
    """The frequency-domain table of one axis' grid.

    Attributes
    ----------
    axis : int
    names : tuple of 2 str
        The swept parameters.
    a, b : ndarray (G,)
        Their values per set (a-major grid).
    sets : tuple
        The parameter sets.
    radius : ndarray (G,)
        Spectral radius of the closed loop at the tick.
    stable : ndarray of bool (G,)
    fd_p90_deg : ndarray (G,)
        Gaussian p90 of |attitude error| from the spectrum [deg]; NaN where unstable.
    gain_margin_db, phase_margin_deg, delay_margin_s : ndarray (G,)
        NaN where unstable.
    min_delay_margin_s : float
        The delay margin a robust set keeps [s] (:data:`ROBUST_DELAY_MARGIN_S` by default; 0: none).
    """

    axis: int
    names: tuple
    a: np.ndarray
    b: np.ndarray
    sets: tuple
    radius: np.ndarray
    stable: np.ndarray
    fd_p90_deg: np.ndarray
    gain_margin_db: np.ndarray
    phase_margin_deg: np.ndarray
    delay_margin_s: np.ndarray
    min_delay_margin_s: float = ROBUST_DELAY_MARGIN_S

    @property
    def robust(self) -> np.ndarray:
        """Stable sets keeping the margins: 6 dB, 45° and a delay margin of :attr:`min_delay_margin_s`."""
        return robust(self.stable, self.gain_margin_db, self.phase_margin_deg, self.delay_margin_s,
                      self.min_delay_margin_s)

    def ranked(self) -> np.ndarray:
        """Indices of the robust sets, best (lowest predicted p90) first."""
        idx = np.flatnonzero(self.robust & np.isfinite(self.fd_p90_deg))
        return idx[np.argsort(self.fd_p90_deg[idx], kind="stable")]

    def grid(self, column: str) -> np.ndarray:
        """A column as the (len(unique a), len(unique b)) grid."""
        na, nb = np.unique(self.a).size, np.unique(self.b).size
        return np.asarray(getattr(self, column), dtype=float).reshape(na, nb)

    def to_dict(self) -> dict:
        return {"names": list(self.names), "a": self.a.tolist(), "b": self.b.tolist(),
                "stable": self.stable.tolist(), "fd_p90_deg": _list(self.fd_p90_deg),
                "gain_margin_db": _list(self.gain_margin_db), "phase_margin_deg": _list(self.phase_margin_deg),
                "delay_margin_s": _list(self.delay_margin_s)}


def robust(stable, gain_margin_db, phase_margin_deg, delay_margin_s,
           min_delay_margin_s: float = ROBUST_DELAY_MARGIN_S) -> np.ndarray:
    """Stable and keeping 6 dB, 45° and ``min_delay_margin_s`` (arrays, element by element)."""
    with np.errstate(invalid="ignore"):
        keeps_delay = np.asarray(delay_margin_s) >= min_delay_margin_s
        if min_delay_margin_s <= 0:
            keeps_delay = np.ones(np.shape(delay_margin_s), dtype=bool)
        return (np.asarray(stable, bool) & (np.asarray(gain_margin_db) >= ROBUST_GAIN_MARGIN_DB)
                & (np.asarray(phase_margin_deg) >= ROBUST_PHASE_MARGIN_DEG) & keeps_delay)


def _list(a):
    return [None if not np.isfinite(v) else float(v) for v in np.asarray(a, dtype=float)]


def evaluate_sets(spec, sets, axis: int, model_params, scale, signs, m: int, freq, psd, collective: float = 0.0):
    """Radius, stability, Gaussian p90 [deg], gain, phase and delay margins of ``sets`` on ``axis``; arrays (G,)."""
    loop = spec.loop_class(list(sets), scale, signs)
    cl = closed_loop(model_params, loop, collective)
    radius, stable = cl.stable(axis)
    sigma = attitude_std(cl, m, axis, freq, psd)
    gm, pm, dm = (np.full(len(sets), np.nan) for _ in range(3))
    idx = np.flatnonzero(stable)
    if idx.size:
        g, p, d = stick_margins(cl, axis, idx, delay=True)
        gm[idx], pm[idx], dm[idx] = g[idx], p[idx], d[idx]
    return radius, stable, sigma * _DEG * GAUSS_ABS_FACTOR[90], gm, pm, dm


def sweep_axis(spec, base, axis: int, model_params, scale, signs, m: int, freq, psd,
               collective: float = 0.0, min_delay_margin_s: float = ROBUST_DELAY_MARGIN_S) -> AxisSweep:
    """The frequency-domain table of ``axis``' grid around ``base`` (module docstring)."""
    ga, gb = spec.grid(axis)
    ff = spec.feed_forward(model_params, axis, scale[axis])
    A, B = np.meshgrid(ga, gb, indexing="ij")
    a, b = A.ravel(), B.ravel()
    sets = tuple(spec.candidate(base, axis, x, y, ff) for x, y in zip(a, b))
    radius, stable, p90, gm, pm, dm = evaluate_sets(spec, sets, axis, model_params, scale, signs, m, freq, psd,
                                                    collective)
    return AxisSweep(axis, spec.swept[axis], a, b, sets, radius, stable, p90, gm, pm, dm, float(min_delay_margin_s))


def joint_choices(sweeps: dict, axes: tuple, count: int) -> list:
    """Up to ``count`` choices of one set per axis in ``axes``, best first.

    One axis: its robust sets by predicted p90. Several (Rotorflight's roll and pitch, which share
    ``angle_level_strength``, the sweep's second gain ``b``): for every value of ``b`` each axis' best robust
    set at that ``b``, ranked by the sum of their p90s.
    """
    if len(axes) == 1:
        sw = sweeps[axes[0]]
        return [{axes[0]: int(i)} for i in sw.ranked()[:count]]
    options = []
    for level in np.unique(sweeps[axes[0]].b):
        pick, total = {}, 0.0
        for ax in axes:
            sw = sweeps[ax]
            idx = np.flatnonzero(sw.robust & (sw.b == level) & np.isfinite(sw.fd_p90_deg))
            if idx.size == 0:
                break
            best = int(idx[np.argmin(sw.fd_p90_deg[idx])])
            pick[ax] = best
            total += float(sw.fd_p90_deg[best])
        else:
            options.append((total, pick))
    options.sort(key=lambda t: t[0])
    return [p for _, p in options[:count]]
