"""The sampling error of a sweep's p90s: a 90 % interval beside each, from blocks of the library's time.

A sweep's p90 |attitude error| (and |rate error|) is estimated from the library's gusts, a few minutes of
wind per flight. Another few minutes of the same weather would give another p90: that spread is the
prediction's sampling error, and it is set by how much *library time* the windows cover, not by how many
windows fly. Two windows over the same stretch of a trace fly the same gusts and, once their start from
rest has died out, make the same errors; they add no information. So the samples are grouped into
**blocks of trace time** (:data:`BLOCK_SECONDS` of one trace; every window's samples over that stretch
fall into its block), and the blocks are the independent units of the estimate.

The interval is Woodruff's (1952) for a quantile of clustered samples, as survey statistics uses it: the
standard error of the pooled distribution function at the p90, ``se(F(q))``, from the blocks' own
fractions below it, then the pooled quantiles at ``0.9 -+ 1.645 se``::

    F = sum_c n_c F_c / N,    d_c = n_c (F_c - F)
    var F = C/(C - 1) [sum_c d_c^2 + sum_(c, c+1 adjacent in a trace) d_c d_(c+1)] / N^2
    interval = [Q(0.9 - 1.645 se), Q(0.9 + 1.645 se)],   se = sqrt(var F)

``n_c`` samples in block ``c`` of ``C``, ``F_c`` its fraction at or below the p90, ``Q`` the same
empirical quantile as the p90 itself (numpy's "linear"), so the interval always holds the p90. The term of
adjacent blocks (a Bartlett weight of 1/2 on the lag-one covariance, which keeps the variance
non-negative) carries the correlation of gusts slower than a block over its edge. ``F_c`` is counted at a
first estimate of the p90 from every fourth sample (the exact p90 comes after the samples are
partitioned in place; the standard error hardly moves between the two). With one block there is no
spread to measure and the interval is NaN.

What it covers: the windows the sweep drew and the finite library, i.e. the spread of p90s over
other stretches of the same identified wind. What it does not: the identified model's error and any
difference between the library's wind and the weather a flight test meets.
"""

from __future__ import annotations

import math

import numpy as np

BLOCK_SECONDS = 10.0
"""Length of one block of trace time [s]: a few of the closed loop's and the fast gusts' time constants."""

LEVEL = 0.90
"""Coverage of the interval beside each p90."""

Z = 1.6448536269514722
"""Standard normal quantile of ``(1 + LEVEL) / 2``."""

QUANTILE = 0.90
"""The quantile the interval is for (the p90)."""

INTERVAL_COLUMNS = ("att_p90_lo_deg", "att_p90_hi_deg", "rate_p90_lo_dps", "rate_p90_hi_dps")
"""Columns of the sweep's table: the ends of the 90 % interval of each time-domain p90."""

_FIRST_STRIDE = 4
"""Every how many samples the first estimate of the p90 is taken from."""


def trace_blocks(windows, steps: int, ratio: int, sample_rate: float,
                 block_seconds: float = BLOCK_SECONDS) -> tuple[np.ndarray, np.ndarray]:
    """The block of trace time each replayed sample falls in, and the pairs of adjacent blocks.

    Parameters
    ----------
    windows : sequence of (trace, offset)
        The replayed windows (trace index, first sample).
    steps : int
        Control periods per window.
    ratio : int
        Library samples per control period.
    sample_rate : float
        The library's sample rate [Hz].
    block_seconds : float
        Block length [s].

    Returns
    -------
    blocks : ndarray of int, shape (steps, W)
        Block index of every (period, window), numbered 0 .. C-1 over the blocks some window touches.
    adjacent : ndarray of int, shape (n_adjacent, 2)
        Pairs of blocks next to each other in one trace.
    """
    per_block = max(1, int(round(block_seconds * sample_rate)))
    wins = np.asarray(windows, dtype=np.int64).reshape(-1, 2)
    sample = wins[None, :, 1] + ratio * np.arange(steps, dtype=np.int64)[:, None]  # (steps, W)
    key = np.stack(np.broadcast_arrays(wins[None, :, 0], sample // per_block), axis=-1).reshape(-1, 2)
    used, blocks = np.unique(key, axis=0, return_inverse=True)
    nxt = {(int(t), int(b)): i for i, (t, b) in enumerate(used)}
    adjacent = [(i, nxt[(int(t), int(b) + 1)]) for i, (t, b) in enumerate(used) if (int(t), int(b) + 1) in nxt]
    return blocks.reshape(steps, -1).astype(np.int64), np.array(adjacent, dtype=np.int64).reshape(-1, 2)


def woodruff_levels(values: np.ndarray, blocks: np.ndarray, adjacent: np.ndarray, q: float = QUANTILE,
                    z: float = Z) -> np.ndarray:
    """The probability levels ``q -+ z se(F(q))`` whose pooled quantiles bound the interval, per row.

    Parameters
    ----------
    values : ndarray, shape (rows, N)
        Samples of each row (|error|), in the replay's layout: sample ``k * W + w`` is period ``k`` of
        window ``w`` (not yet partitioned).
    blocks : ndarray of int, shape (N,)
        Block of each sample (:func:`trace_blocks`, flattened).
    adjacent : ndarray of int, shape (n_adjacent, 2)
    q, z : float

    Returns
    -------
    ndarray, shape (rows, 2)
        The lower and upper level, in [0, 1]; NaN for a row without two blocks or with non-finite samples.
    """
    rows, N = values.shape
    C = int(blocks.max()) + 1 if blocks.size else 0
    out = np.full((rows, 2), np.nan)
    if C < 2:
        return out
    first = np.quantile(values[:, ::_FIRST_STRIDE], q, axis=1)
    sizes = np.bincount(blocks, minlength=C).astype(float)
    for j in range(rows):
        if not math.isfinite(first[j]):
            continue
        below = np.bincount(blocks, weights=(values[j] <= first[j]), minlength=C)
        d = below - sizes * (below.sum() / N)
        var = float(d @ d)
        if adjacent.size:
            var += float(d[adjacent[:, 0]] @ d[adjacent[:, 1]])
        se = math.sqrt(max(var, 0.0) * C / (C - 1)) / N
        out[j] = (max(q - z * se, 0.0), min(q + z * se, 1.0))
    return out


def quantiles_at(values: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Each row's empirical quantiles (numpy's "linear") at its own two ``levels``, partitioning in place.

    Parameters
    ----------
    values : ndarray, shape (rows, N)
    levels : ndarray, shape (rows, 2)
        NaN gives NaN.

    Returns
    -------
    ndarray, shape (rows, 2)
    """
    rows, N = values.shape
    out = np.full((rows, 2), np.nan)
    for j in range(rows):
        if not np.all(np.isfinite(levels[j])):
            continue
        pos = levels[j] * (N - 1)
        lo = np.floor(pos).astype(int)
        hi = np.minimum(lo + 1, N - 1)
        row = values[j]
        row.partition(sorted(set(lo.tolist()) | set(hi.tolist())))
        out[j] = row[lo] + (pos - lo) * (row[hi].astype(np.float64) - row[lo])
    return out


def half_width(table: dict, name: str = "att") -> np.ndarray:
    """Half the interval's width relative to the p90, per pair (NaN where there is none)."""
    unit = "deg" if name == "att" else "dps"
    lo, hi = np.asarray(table[f"{name}_p90_lo_{unit}"], float), np.asarray(table[f"{name}_p90_hi_{unit}"], float)
    p90 = np.asarray(table[f"{name}_p90_{unit}"], float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return 0.5 * (hi - lo) / p90


def interval_summary(table: dict, stable) -> dict:
    """Median and largest relative half-width of the attitude p90's interval over the simulated pairs."""
    hw = half_width(table)[np.asarray(stable, bool)]
    hw = hw[np.isfinite(hw)]
    return {"median_half_width": float(np.median(hw)) if hw.size else None,
            "max_half_width": float(np.max(hw)) if hw.size else None}
