"""Sums over the intervals of the integral method (Fig. 5): splitting, pooling and integrating within each.

The integral method (:mod:`identification.integral.method`) restarts the model
from the measured rate at the start of every interval ``[T_{i-1}, T_i)``
(eq. 34) and integrates the features within it by the trapezium rule (eq. 36).
This module holds those sums, vectorised over intervals and samples:
:func:`split_intervals` and :func:`pool_intervals` lay one or several flights
out as (intervals x samples), :func:`interval_integral` integrates within every
interval by two-level prefix sums in BLAS, and :func:`disturbance_basis` gives
the per-interval polynomial of the disturbance (eq. 43 and its smooth
extensions) that is projected out. The small dense solvers call LAPACK directly
(the normal equations are a few columns wide and solved many times).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.linalg import lapack


def split_intervals(values: np.ndarray, n_int: int, length: int):
    """values (..., n) -> (inner (..., n_int, length), first (..., n_int)) for adjacent intervals of ``length`` steps.

    Interval i spans samples ``i*length .. (i+1)*length``: ``first`` holds its
    first sample (the measured initial value of eq. 34) and ``inner`` the
    remaining ``length``, so an interval's end point is the next one's first
    sample. Both are views of ``values`` (no copy).
    """
    values = np.asarray(values, dtype=float)
    stop = n_int * length
    inner = values[..., 1 : stop + 1].reshape(values.shape[:-1] + (n_int, length))
    return inner, values[..., 0:stop:length]


def pool_intervals(parts):
    """Concatenate per-flight (inner, first) pairs along the interval axis (no copy for one flight)."""
    if len(parts) == 1:
        return parts[0]
    return (np.concatenate([p[0] for p in parts], axis=-2), np.concatenate([p[1] for p in parts], axis=-1))


@lru_cache(maxsize=16)
def disturbance_basis(N: int, dt: float, order: int):
    """Per-interval disturbance basis of degree ``order`` on N samples of step dt.

    Returns ``B`` (N, o): integrals t^(j+1)/(j+1) of the torque polynomial t^j;
    ``Q``: orthonormal basis of B; ``B_pinv``; ``Qt`` (N+1, o): orthonormal basis
    of the polynomials themselves on the N+1 samples of an interval; ``QB``
    (N, 2o) = [Q, B_pinv^T], so that one product gives both the projection
    coefficients and the least-squares polynomial coefficients of a signal.
    """
    tt = np.arange(1, N + 1) * dt
    B = np.stack([tt ** (j + 1) / (j + 1) for j in range(order + 1)], axis=1)
    Q, _ = np.linalg.qr(B)
    Qt, _ = np.linalg.qr(np.vander(np.arange(N + 1) * dt, order + 1))
    B_pinv = np.linalg.pinv(B)
    QB = np.ascontiguousarray(np.hstack([Q, B_pinv.T]))
    QT = np.ascontiguousarray(Q.T)
    for arr in (B, Q, Qt, B_pinv, QB, QT):
        arr.setflags(write=False)
    return B, Q, B_pinv, Qt, QB, QT


@lru_cache(maxsize=64)
def _integral_plan(N: int, diag: float, scale: float):
    """Block size b (a divisor of N near sqrt(N)) and the matrices of a two-level weighted prefix sum.

    ``inner`` (b, b) maps a block of samples to ``scale`` times its weighted
    running sums (weight 1 on earlier samples, ``diag`` on the current one);
    ``outer`` (nb, nb) sums the totals of the earlier blocks.
    """
    divisors = [b for b in range(4, N // 4 + 1) if N % b == 0]
    if not divisors:
        return None
    b = min(divisors, key=lambda d: abs(d - N**0.5))
    inner = scale * (np.triu(np.ones((b, b)), 1) + diag * np.eye(b))
    outer = np.triu(np.ones((N // b, N // b)), 1)
    for arr in (inner, outer):
        arr.setflags(write=False)
    return b, inner, outer


def interval_integral(inner: np.ndarray, first, scale: float, diag: float = 0.5, first_weight: float = 0.5,
                       out=None) -> np.ndarray:
    """Running integral over every interval (eq. 36), as small matrix products.

    For interval samples ``f_0 = first`` and ``f_1..f_N = inner`` (n_int, N)
    returns, for k = 1..N, ``scale * (first_weight*f_0 + f_1 + ... + f_{k-1} + diag*f_k)``:
    the trapezium rule times dt when ``scale = dt`` (weights 1/2, 1/2), the left
    rectangle with ``diag=0, first_weight=1``. ``first=None`` means f_0 = 0.
    ``out`` must be C-contiguous.

    numpy's cumsum runs at several ns per element; splitting each interval into
    blocks, prefix-summing inside the blocks (one BLAS product) and adding the
    prefix of the block totals turns it into BLAS work. Exact up to rounding
    (the same sums, regrouped).
    """
    n_int, N = inner.shape
    if out is None:
        out = np.empty((n_int, N))
    plan = _integral_plan(N, float(diag), float(scale))
    if plan is None:
        np.cumsum(inner, axis=-1, out=out)
        if diag != 1.0:
            out -= (1.0 - diag) * inner
        out *= scale
        if first is not None:
            out += (scale * first_weight) * first[:, None]
        return out
    b, inner_m, outer_m = plan
    nb = N // b
    blocks = inner.reshape(n_int * nb, b)
    running = out.reshape(n_int * nb, b)
    np.matmul(blocks, inner_m, out=running)  # weighted running sums within each block
    totals = running[:, b - 1] + (scale * (1.0 - diag)) * blocks[:, b - 1]
    before = totals.reshape(n_int, nb) @ outer_m  # sums of the earlier blocks
    if first is not None:
        before += (scale * first_weight) * first[:, None]
    out.reshape(n_int, nb, b)[...] += before[:, :, None]
    return out


_DOT_CHUNK = 8192


def sum_squares(x: np.ndarray) -> float:
    """``x @ x`` for a contiguous 1-D array, summed over chunks.

    OpenBLAS runs ddot on more than 10000 elements on several threads; when the
    other cores are busy, the call then waits for them for milliseconds. The
    chunks stay single-threaded (the sum is the same up to rounding).
    """
    if x.size <= _DOT_CHUNK:
        return float(np.dot(x, x))
    total = 0.0
    for i in range(0, x.size, _DOT_CHUNK):
        part = x[i : i + _DOT_CHUNK]
        total += float(np.dot(part, part))
    return total


def symmetric_eigenvalues(G: np.ndarray) -> np.ndarray:
    """Eigenvalues of the small symmetric matrix G, ascending (LAPACK dsyevd, as numpy's eigvalsh, less its overhead)."""
    w, _, info = lapack.dsyevd(G, compute_v=0, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError("Eigenvalues did not converge")
    return w


def solve_small(G: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solution of the small system G x = rhs (LAPACK dgesv, as numpy's solve, less its overhead)."""
    _, _, x, info = lapack.dgesv(G, rhs)
    if info != 0:
        raise np.linalg.LinAlgError("Singular matrix")
    return x
