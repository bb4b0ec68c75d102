"""The likelihood's innovation filters over a flight, compiled: the inner loop of every axis fit.

Every evaluation of an axis' likelihood (:meth:`~identification.likelihood.axis_likelihood.AxisLikelihood.filtered`)
runs the measured rate and each regressor (30 000 samples each on a 300 s flight) through the steady-state
Kalman filter's innovation filters, of order three or four. ``scipy.signal.lfilter`` does it a row at a time,
each sample waiting on the one before; :func:`filter_rows` does the same arithmetic in the same order, so its
output is lfilter's bit for bit (a test holds it to that), two rows at a time so that their recursions overlap,
in a loop compiled for the filter's own length: 0.22 ms for four rows of order three, where the loop padded to six
coefficients took 0.39 ms (and lfilter 0.95 ms for five rows). Compiled by numba (``cache=True``); this module is
imported on the first evaluation, so importing the package does not load numba.

Bit for bit, so that the change of speed changed no fitted value (the search itself no longer hangs on the
innovations' last digits: ``axis_search.FD_STEP``).
"""

from __future__ import annotations

import numba
import numpy as np
from numba.extending import overload

PAIR_TAPS = 6
"""Most coefficients (order + 1) the paired filter loop holds in registers; longer filters take the general loop."""

MIN_TAPS = 4
"""Fewest coefficients the paired loop is compiled for: shorter filters are padded with zeros (they add exact
zeros). The likelihood's filters have 4 (gust model ``gm2``) or 5 (``gm_so``) coefficients; a loop compiled for
their own number ran them 1.7 times faster than one padded to :data:`PAIR_TAPS`."""


def _row(c, r, state):  # pragma: no cover - compiled by its overload
    """Row ``r`` of ``c`` as a tuple one longer than the filter state ``state``."""


@overload(_row, inline="always")
def _row_typed(c, r, state):  # pragma: no cover - compiled
    width = state.count + 1
    if width == 4:
        return lambda c, r, state: (c[r, 0], c[r, 1], c[r, 2], c[r, 3])
    if width == 5:
        return lambda c, r, state: (c[r, 0], c[r, 1], c[r, 2], c[r, 3], c[r, 4])
    if width == 6:
        return lambda c, r, state: (c[r, 0], c[r, 1], c[r, 2], c[r, 3], c[r, 4], c[r, 5])
    return None


def _tap(x, p, a, z):  # pragma: no cover - compiled by its overload
    """One sample of direct form II transposed with coefficients ``p`` / ``a`` (``a[0]`` = 1): the output and the
    next state ``z``, in lfilter's order of operations."""


@overload(_tap, inline="always")
def _tap_typed(x, p, a, z):  # pragma: no cover - compiled
    if z.count == 3:
        return lambda x, p, a, z: _step3(z[0] + p[0] * x, x, p, a, z)
    if z.count == 4:
        return lambda x, p, a, z: _step4(z[0] + p[0] * x, x, p, a, z)
    if z.count == 5:
        return lambda x, p, a, z: _step5(z[0] + p[0] * x, x, p, a, z)
    return None


@numba.njit(cache=True, inline="always")
def _step3(y, x, p, a, z):  # pragma: no cover - compiled
    return y, (z[1] + x * p[1] - y * a[1], z[2] + x * p[2] - y * a[2], x * p[3] - y * a[3])


@numba.njit(cache=True, inline="always")
def _step4(y, x, p, a, z):  # pragma: no cover - compiled
    return y, (z[1] + x * p[1] - y * a[1], z[2] + x * p[2] - y * a[2], z[3] + x * p[3] - y * a[3],
               x * p[4] - y * a[4])


@numba.njit(cache=True, inline="always")
def _step5(y, x, p, a, z):  # pragma: no cover - compiled
    return y, (z[1] + x * p[1] - y * a[1], z[2] + x * p[2] - y * a[2], z[3] + x * p[3] - y * a[3],
               z[4] + x * p[4] - y * a[4], x * p[5] - y * a[5])


@numba.njit(cache=True)
def _filter_pairs(b, an, U, out, state):  # pragma: no cover - compiled
    """:func:`filter_rows` for coefficients as long as ``state`` (a tuple of zeros, the filter's state at rest)
    plus one, compiled for that length, two rows a step, their states in registers, so that their recursions
    overlap."""
    a = _row(an, 0, state)
    rows, n = U.shape
    for r in range(0, rows, 2):
        s = min(r + 1, rows - 1)
        p = _row(b, r, state)
        q = _row(b, s, state)
        z = w = state
        for k in range(n):
            out[r, k], z = _tap(U[r, k], p, a, z)
            out[s, k], w = _tap(U[s, k], q, a, w)


@numba.njit(cache=True)
def _filter_long(b, an, U, out):  # pragma: no cover - compiled
    """:func:`filter_rows` for filters longer than :data:`PAIR_TAPS` (coefficients already divided by ``a[0]``)."""
    rows, n = U.shape
    nb = an.size
    z = np.zeros((rows, nb - 1))
    for k in range(n):
        for r in range(rows):
            x = U[r, k]
            y = z[r, 0] + b[r, 0] * x
            for j in range(nb - 2):
                z[r, j] = z[r, j + 1] + x * b[r, j + 1] - y * an[j + 1]
            z[r, nb - 2] = x * b[r, nb - 1] - y * an[nb - 1]
            out[r, k] = y


def filter_rows(B, a, U):
    """Each row ``U[r]`` through the filter ``B[r] / a`` from rest: ``scipy.signal.lfilter(B[r], a, U[r])`` for
    every row, bit for bit (the same direct form II transposed, the same operations in the same order, the
    coefficients divided by ``a[0]``), 2-3 times faster on the likelihood's filters. ``B`` (rows, l) and ``a``
    (l,) of one length, ``l >= 2``. The loop for a filter's length is compiled when a filter of that length first
    comes (a first fit compiles the two its gust models use, not every length)."""
    U = np.asarray(U, dtype=float)
    rows, n = U.shape
    nb = a.size
    out = np.empty((rows, n))
    if nb > PAIR_TAPS:
        _filter_long(np.asarray(B, dtype=float) / a[0], np.asarray(a, dtype=float) / a[0], U, out)
        return out
    width = max(nb, MIN_TAPS)
    b = np.zeros((rows, width))
    an = np.zeros((1, width))
    b[:, :nb] = B / a[0]
    an[0, :nb] = a / a[0]
    _filter_pairs(b, an, U, out, (0.0,) * (width - 1))
    return out
