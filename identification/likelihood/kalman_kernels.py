"""The likelihood's innovation filters over a flight, compiled: the inner loop of every axis fit.

Every evaluation of an axis' likelihood (:meth:`~identification.likelihood.axis_likelihood.AxisLikelihood.filtered`)
runs the measured rate and each regressor (30 000 samples each on a 300 s flight) through the steady-state
Kalman filter's innovation filters, of order three or four. ``scipy.signal.lfilter`` does it a row at a time,
each sample waiting on the one before; :func:`filter_rows` does the same arithmetic in the same order, so its
output is lfilter's bit for bit (a test holds it to that), two rows at a time so that their recursions overlap:
0.34 ms for the bench's five rows where lfilter took 0.95 ms. Compiled by numba (``cache=True``); this module is
imported on the first evaluation, so importing the package does not load numba.

Bit for bit, so that the change of speed changed no fitted value (the search itself no longer hangs on the
innovations' last digits: ``axis_search.FD_STEP``).
"""

from __future__ import annotations

import numba
import numpy as np

PAIR_TAPS = 6
"""Coefficients (order + 1) the paired filter loop holds in registers; longer filters take the general loop."""


@numba.njit(cache=True, inline="always")
def _tap(x, p, a, z):  # pragma: no cover - compiled
    """One sample of direct form II transposed with :data:`PAIR_TAPS` coefficients ``p`` / ``a`` (``a[0]`` = 1): the
    output and the next state ``z`` (five values), in lfilter's order of operations."""
    y = z[0] + p[0] * x
    return y, (z[1] + x * p[1] - y * a[1], z[2] + x * p[2] - y * a[2], z[3] + x * p[3] - y * a[3],
               z[4] + x * p[4] - y * a[4], x * p[5] - y * a[5])


@numba.njit(cache=True)
def _filter_pairs(b, an, U, out):  # pragma: no cover - compiled
    """:func:`filter_rows` with :data:`PAIR_TAPS` coefficients (zeros padding shorter filters: they add exact
    zeros), two rows a step, their states in registers, so that their recursions overlap."""
    a = (an[0], an[1], an[2], an[3], an[4], an[5])
    rows, n = U.shape
    for r in range(0, rows, 2):
        s = min(r + 1, rows - 1)
        p = (b[r, 0], b[r, 1], b[r, 2], b[r, 3], b[r, 4], b[r, 5])
        q = (b[s, 0], b[s, 1], b[s, 2], b[s, 3], b[s, 4], b[s, 5])
        z = w = (0.0, 0.0, 0.0, 0.0, 0.0)
        for k in range(n):
            out[r, k], z = _tap(U[r, k], p, a, z)
            out[s, k], w = _tap(U[s, k], q, a, w)


@numba.njit(cache=True)
def filter_rows(B, a, U):  # pragma: no cover - compiled
    """Each row ``U[r]`` through the filter ``B[r] / a`` from rest: ``scipy.signal.lfilter(B[r], a, U[r])`` for
    every row, bit for bit (the same direct form II transposed, the same operations in the same order, the
    coefficients divided by ``a[0]``), 2-3 times faster on the likelihood's filters. ``B`` (rows, l) and ``a``
    (l,) of one length, ``l >= 2``."""
    rows, n = U.shape
    nb = a.size
    out = np.empty((rows, n))
    if nb <= PAIR_TAPS:
        b = np.zeros((rows, PAIR_TAPS))
        an = np.zeros(PAIR_TAPS)
        b[:, :nb] = B / a[0]
        an[:nb] = a / a[0]
        _filter_pairs(b, an, U, out)
        return out
    b = B / a[0]
    an = a / a[0]
    z = np.zeros((rows, nb - 1))
    for k in range(n):
        for r in range(rows):
            x = U[r, k]
            y = z[r, 0] + b[r, 0] * x
            for j in range(nb - 2):
                z[r, j] = z[r, j + 1] + x * b[r, j + 1] - y * an[j + 1]
            z[r, nb - 2] = x * b[r, nb - 1] - y * an[nb - 1]
            out[r, k] = y
    return out
