"""Streams of a decoded log and their resampling onto one uniform time grid.

A flight controller logs its streams at different, often jittery rates (ArduCopter
3.3: IMU 50 Hz, ATT/RATE/RCIN 10 Hz; PX4: gyro ~400 Hz, sticks ~5 Hz). The
canonical :class:`~identification.flight.Flight` needs one uniform time base, so
every stream is brought onto a grid as follows (the method of
:func:`resample_stream`):

1. **Time base cleaned.** Samples whose time does not increase past every earlier
   one (decoder glitches, e.g. the first frames of a blackbox log) are dropped
   and counted.
2. **Grid.** Uniform, at the rate of the body-rate stream (its median sample
   rate) capped at :data:`DEFAULT_MAX_RATE` Hz, or at the rate asked for; it
   spans the time that every stream used covers.
3. **Anti-aliasing.** A stream sampled more than 1.5x faster than the grid is
   first low-passed with a zero-phase 4th-order Butterworth filter (forward and
   backward, :func:`scipy.signal.sosfiltfilt`) at 0.4x the grid rate, so
   decimation does not fold vibration into the band the models use.
4. **Interpolation.** Linear interpolation in time (:func:`numpy.interp`) onto
   the grid; angles are unwrapped first and wrapped back to (-pi, pi] after, so
   a yaw crossing 360 deg does not sweep through zero. Slower streams (sticks,
   10 Hz controller outputs) are therefore piecewise linear between their samples.
5. **Gaps.** A stream interval longer than ``max(GAP_FACTOR x its median
   interval, MIN_GAP_S)`` is a gap (logging paused, dropped messages): grid
   points inside it are marked invalid rather than bridged, and the segment
   chosen later never spans one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

DEFAULT_MAX_RATE = 200.0
"""Hz: the default grid rate is the gyro stream's rate, at most this (enough for attitude dynamics)."""
GAP_FACTOR = 5.0
"""A stream interval longer than this many median intervals is a gap."""
MIN_GAP_S = 0.05
"""s: intervals shorter than this are never gaps, however fast the stream."""
ANTIALIAS_FRACTION = 0.4
"""Cut-off of the anti-alias filter as a fraction of the grid rate."""


@dataclass(frozen=True)
class Stream:
    """One logged signal group on its own clock.

    Attributes
    ----------
    time : ndarray, shape (n,)
        Sample times [s] on the log's own clock (strictly increasing once built by :func:`make_stream`).
    values : ndarray, shape (k, n)
        The k channels, already in the units the importer documents.
    name : str
        Where it came from, e.g. ``"IMU.GyrX/Y/Z"``.
    angles : bool
        True for angles in rad (interpolated on the unwrapped phase).
    dropped : int
        Samples dropped because their time did not increase.
    """

    time: np.ndarray
    values: np.ndarray
    name: str
    angles: bool = False
    dropped: int = 0

    @property
    def rate(self) -> float:
        """Median sample rate [Hz]."""
        return 1.0 / float(np.median(np.diff(self.time)))

    @property
    def span(self) -> tuple[float, float]:
        return float(self.time[0]), float(self.time[-1])


def make_stream(time, values, name: str, angles: bool = False) -> Stream | None:
    """Build a :class:`Stream`, dropping samples whose time does not increase; None if < 2 samples remain.

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times [s].
    values : array_like, shape (k, n) or (n,)
    name : str
    angles : bool
    """
    t = np.asarray(time, dtype=float)
    v = np.atleast_2d(np.asarray(values, dtype=float))
    if v.shape[1] != t.size:
        raise ValueError(f"stream {name}: {t.size} times but values of shape {v.shape}")
    finite = np.isfinite(t) & np.isfinite(v).all(axis=0)
    t, v = t[finite], v[:, finite]
    # Keep a sample only when its time exceeds every earlier one (running maximum).
    if t.size:
        prev_max = np.maximum.accumulate(np.concatenate(([-np.inf], t[:-1])))
        keep = t > prev_max
    else:
        keep = np.zeros(0, dtype=bool)
    dropped = int((~finite).sum() + (~keep).sum())
    t, v = t[keep], v[:, keep]
    if t.size < 2:
        return None
    return Stream(t, v, name, angles, dropped)


def gap_threshold(stream: Stream) -> float:
    """Interval [s] beyond which the stream is considered interrupted."""
    return max(GAP_FACTOR * float(np.median(np.diff(stream.time))), MIN_GAP_S)


def stream_gaps(stream: Stream) -> np.ndarray:
    """Gaps of a stream as an array of shape (m, 2): [start, end] times [s] of each over-long interval."""
    dt = np.diff(stream.time)
    i = np.flatnonzero(dt > gap_threshold(stream))
    return np.column_stack([stream.time[i], stream.time[i + 1]]) if i.size else np.zeros((0, 2))


def uniform_grid(t0: float, t1: float, rate: float) -> np.ndarray:
    """Uniform times from ``t0`` to at most ``t1`` at ``rate`` Hz (``t0 + k / rate``, exact multiples)."""
    n = int(np.floor((t1 - t0) * rate + 1e-9)) + 1
    return t0 + np.arange(n) / rate


def valid_on_grid(grid: np.ndarray, stream: Stream) -> np.ndarray:
    """Boolean mask of grid points covered by the stream: inside its span and not inside one of its gaps."""
    ok = (grid >= stream.time[0]) & (grid <= stream.time[-1])
    gaps = stream_gaps(stream)
    if gaps.size:
        # Vectorised over gaps: a grid point is bad if it lies strictly inside any gap.
        lo = np.searchsorted(grid, gaps[:, 0], side="right")
        hi = np.searchsorted(grid, gaps[:, 1], side="left")
        marks = np.zeros(grid.size + 1, dtype=int)
        np.add.at(marks, lo, 1)
        np.add.at(marks, hi, -1)
        ok &= np.cumsum(marks[:-1]) == 0
    return ok


def resample_stream(stream: Stream, grid: np.ndarray) -> np.ndarray:
    """A stream's values on a uniform grid (anti-aliased, linearly interpolated; see the module docstring).

    Parameters
    ----------
    stream : Stream
    grid : ndarray, shape (m,)
        Uniform times [s].

    Returns
    -------
    ndarray, shape (k, m)
        Values at the grid times; outside the stream's span they hold its end values
        (such points are marked invalid by :func:`valid_on_grid`).
    """
    v = stream.values
    if stream.angles:
        v = np.unwrap(v, axis=1)
    grid_rate = 1.0 / float(grid[1] - grid[0]) if grid.size > 1 else stream.rate
    src_rate = stream.rate
    if src_rate > 1.5 * grid_rate:
        sos = signal.butter(4, ANTIALIAS_FRACTION * grid_rate, fs=src_rate, output="sos")
        padlen = 3 * (2 * len(sos) + 1)
        if v.shape[1] > padlen:
            v = signal.sosfiltfilt(sos, v, axis=1)
    out = np.array([np.interp(grid, stream.time, row) for row in v])  # k rows, k <= 4
    if stream.angles:
        out = np.angle(np.exp(1j * out))
    return out


def valid_runs(mask: np.ndarray) -> np.ndarray:
    """Runs of True in a boolean mask as an array (m, 2) of [start, stop) indices."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    return edges.reshape(-1, 2)
