"""Smoothing the identified disturbance and the paper's rule for how much (Section 3.3).

The interval-level equivalent input u_d of eq. (46) is smoothed by repeated
10-point moving averages (:func:`smooth`), alternating the window's
half-sample offset, so that two passes are exactly centred (an odd number of
passes leaves a lag of Δt/2, 0.01 s at the default Δt). With
``smoothing="auto"`` the number of passes is the one whose fitted normal
distribution of ``u_d`` (:func:`scipy.stats.norm.fit`) is closest in least
squares (integrated squared difference of the two densities,
:func:`normal_distance`) to the fitted normal of the pilot's stick on that
axis, stick minus its mean: the paper's assumption is that the pilot's stick
mirrors the gusts (:func:`smoothing_rule`).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage, stats

from ..errors import DisturbanceError

SMOOTHING_WINDOW = 10
"""Points of each moving average (Section 3.3: "a 10 point moving average")."""

MAX_PASSES = 40
"""Largest number of smoothing passes ``smoothing="auto"`` considers."""


def smooth(values: np.ndarray, passes: int, window: int = SMOOTHING_WINDOW) -> np.ndarray:
    """``passes`` repeated ``window``-point moving averages along the last axis (Section 3.3).

    Even windows are centred half a sample off; successive passes alternate the
    offset so that every two passes are exactly centred. Ends use the nearest value.
    """
    out = np.asarray(values, dtype=float)
    for k in range(int(passes)):
        out = _smooth_pass(out, k, window)
    return out


def _smooth_pass(values: np.ndarray, k: int, window: int = SMOOTHING_WINDOW) -> np.ndarray:
    """Pass number ``k`` (from 0) of :func:`smooth`: odd passes shift the even window the other way."""
    origin = -(k % 2) if window % 2 == 0 else 0
    return ndimage.uniform_filter1d(values, window, axis=-1, mode="nearest", origin=origin)


def normal_distance(mu1, s1, mu2, s2) -> np.ndarray:
    """Integrated squared difference of two normal densities (closed form), vectorised."""
    s1, s2 = np.asarray(s1, dtype=float), np.asarray(s2, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        self1 = 1.0 / (2.0 * np.sqrt(np.pi) * s1)
        self2 = 1.0 / (2.0 * np.sqrt(np.pi) * s2)
        cross = stats.norm.pdf(np.asarray(mu1) - np.asarray(mu2), scale=np.sqrt(s1 * s1 + s2 * s2))
    return np.where((s1 > 0) & (s2 > 0), self1 + self2 - 2.0 * cross, np.inf)


def smoothing_rule(ud_raw: np.ndarray, stick: np.ndarray, rows) -> tuple[np.ndarray, list[int]]:
    """The paper's rule (Section 3.3), evaluated for every pass count 0 .. :data:`MAX_PASSES` on ``rows``.

    Parameters
    ----------
    ud_raw : ndarray, shape (3, n_intervals)
        Zero-mean equivalent input before smoothing [stick units].
    stick : ndarray, shape (3, n)
        The pilot's recorded lat, lon, ped sticks.
    rows : sequence of int
        Axes (rows) identified.

    Returns
    -------
    cost : ndarray, shape (3, MAX_PASSES + 1)
        Integrated squared difference between the fitted normal of the smoothed
        u_d (re-centred to zero mean, as the profile is) and that of the stick
        minus its mean, per pass count; NaN on the other rows.
    auto : list of int
        Per axis the pass count of least cost (0 on the other rows).
    """
    # norm.fit's estimates are the sample mean and the population std: taken for every
    # pass count at once on all axes, without keeping the smoothed profiles.
    moments = np.empty((MAX_PASSES + 1, 2, 3))
    cur = ud_raw
    for k in range(MAX_PASSES + 1):
        moments[k] = cur.mean(axis=-1), cur.std(axis=-1)
        cur = _smooth_pass(cur, k)
    cost = np.full((3, MAX_PASSES + 1), np.nan)
    auto = [0, 0, 0]
    for i in rows:
        mu_s, sd_s = stats.norm.fit(stick[i] - stick[i].mean())
        # a smoothed profile is re-centred to zero mean, so its fitted normal is centred
        cost[i] = normal_distance(0.0, moments[:, 1, i], mu_s, sd_s)
        auto[i] = int(np.argmin(cost[i]))
    return cost, auto


def check_smoothing(smoothing):
    """``smoothing`` as ``"auto"`` or a whole number of passes; :class:`DisturbanceError` otherwise."""
    if smoothing == "auto":
        return smoothing
    if isinstance(smoothing, (int, np.integer)) and not isinstance(smoothing, bool) and 0 <= smoothing <= 10 * MAX_PASSES:
        return int(smoothing)
    raise DisturbanceError(f"smoothing must be 'auto' or a number of passes 0..{10 * MAX_PASSES}, got {smoothing!r}")
