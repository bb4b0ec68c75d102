"""The steady-state Kalman filter of one axis and its transfer functions, compiled: the per-evaluation algebra.

Every evaluation of an axis' likelihood (:meth:`~identification.likelihood.axis_likelihood.AxisLikelihood.filtered`)
solves the filter's algebraic Riccati equation for a model of three or four states and turns the predictor into
the innovation filters' polynomials. Through scipy (``solve_discrete_are``'s QZ decomposition with its argument
checks, ``np.poly`` four times) that took 1.5 ms of an evaluation's 2.3 ms, more than the filters over 30 000
samples (0.35 ms): Python's overhead on 4 x 4 matrices. Here the same quantities, compiled:

* :func:`filter_riccati`: the predicted covariance ``P`` of the filter that measures the first state, by the
  structure-preserving doubling algorithm for discrete-time algebraic Riccati equations (SDA; Chu, Fan, Lin and
  Wang, International Journal of Control 77, 2004): 5-21 doublings, each
  squaring the closed loop's transition, so that the error after ``k`` falls as ``rho^(2^k)``. Its Riccati
  residual is at most 6e-16 relative where scipy's reaches 4e-13 (3000 random models); where it does not converge,
  or its filter is not stable, the caller solves with scipy (:func:`identification.likelihood.state_space.kalman`).
* :func:`char_poly`: ``np.poly`` of a small square matrix (Faddeev-LeVerrier); :func:`predictor_polynomials`: with
  it, every polynomial of the predictor's transfer functions in one call.

Plain loops throughout, no ``np.linalg``: numba's LAPACK wrappers took 20 s to compile on a first fit.

numba compiles them on first use (``cache=True``); this module is imported on the first evaluation, so importing
the package does not load numba.
"""

from __future__ import annotations

import numba
import numpy as np

RICCATI_TOL = 1e-13
"""The doubling stops when an iterate changes ``P`` by less than this, relative to its largest entry."""

RICCATI_SETTLED = 1e-10
"""The doubling's ``A`` (the closed loop's ``2^k``-th power) must have fallen below this for ``P`` to count as the
stabilising solution (:func:`filter_riccati`)."""

RICCATI_MAX_DOUBLINGS = 60
"""Doublings before :func:`filter_riccati` gives up (each squares the closed loop: 60 reach any stable
spectral radius a float can hold)."""


@numba.njit(cache=True)
def _product(A, B):  # pragma: no cover - compiled
    """``A @ B`` of small matrices by plain loops (numba's ``@`` and ``np.linalg`` bring LAPACK wrappers that took
    20 s to compile; these loops compile in a fraction of it and run as fast on 4 x 4)."""
    n, m, p = A.shape[0], A.shape[1], B.shape[1]
    out = np.zeros((n, p))
    for i in range(n):
        for k in range(m):
            a = A[i, k]
            for j in range(p):
                out[i, j] += a * B[k, j]
    return out


@numba.njit(cache=True)
def _solve(M, B):  # pragma: no cover - compiled
    """``M^-1 B`` by Gaussian elimination with partial pivoting (``M`` small and nonsingular: here ``I + G H`` with
    ``G``, ``H`` positive semi-definite, whose eigenvalues are at least 1)."""
    n, p = M.shape[0], B.shape[1]
    A = M.copy()
    X = B.copy()
    for c in range(n):
        pivot = c
        for r in range(c + 1, n):
            if abs(A[r, c]) > abs(A[pivot, c]):
                pivot = r
        if pivot != c:
            for j in range(n):
                A[c, j], A[pivot, j] = A[pivot, j], A[c, j]
            for j in range(p):
                X[c, j], X[pivot, j] = X[pivot, j], X[c, j]
        for r in range(c + 1, n):
            f = A[r, c] / A[c, c]
            for j in range(c, n):
                A[r, j] -= f * A[c, j]
            for j in range(p):
                X[r, j] -= f * X[c, j]
    for c in range(n - 1, -1, -1):
        for j in range(p):
            v = X[c, j]
            for k in range(c + 1, n):
                v -= A[c, k] * X[k, j]
            X[c, j] = v / A[c, c]
    return X


@numba.njit(cache=True)
def filter_riccati(Ad, Qd, R):  # pragma: no cover - compiled
    """``(P, doublings)``: the stabilising solution ``P`` of ``P = Ad P Ad' - Ad P e0 (e0' P e0 + R)^-1 e0' P Ad' +
    Qd`` (the steady-state predicted covariance of the filter measuring state 0 with noise variance ``R``) by
    structured doubling, and the doublings it took; ``doublings`` is -1 where it did not converge within
    :data:`RICCATI_MAX_DOUBLINGS` to a stabilising solution, or ``P`` is not finite.

    The control-form iteration on ``A = Ad'``, ``G = e0 e0' / R``, ``H = Qd``::

        A <- A (I + G H)^-1 A,  G <- G + A (I + G H)^-1 G A',  H <- H + A' H (I + G H)^-1 A

    ``H`` converges to ``P`` (each step doubles the horizon of the Riccati recursion it sums), and ``A`` to 0 as the
    ``2^k``-th power of the filter's closed loop when ``P`` is the stabilising solution: the doubling stops when
    ``H`` has settled and ``A`` has vanished (:data:`RICCATI_SETTLED`), so that a fixed point whose filter is not
    stable (``A`` growing) is never returned as converged."""
    m = Ad.shape[0]
    eye = np.eye(m)
    A = np.ascontiguousarray(Ad.T)
    G = np.zeros((m, m))
    G[0, 0] = 1.0 / R
    H = 0.5 * (Qd + Qd.T)
    for doubling in range(RICCATI_MAX_DOUBLINGS):
        W = _solve(eye + _product(G, H), np.hstack((A, G)))  # (I + G H)^-1 [A, G]
        WA, WG = W[:, :m], W[:, m:]
        H_next = H + _product(_product(A.T, H), WA)
        G = G + _product(_product(A, WG), A.T)
        A = _product(A, WA)
        change = np.abs(H_next - H).max()
        H = 0.5 * (H_next + H_next.T)
        G = 0.5 * (G + G.T)
        scale = np.abs(H).max()
        if not (np.isfinite(scale) and np.isfinite(np.abs(A).max())):
            return H, -1
        if change <= RICCATI_TOL * scale and np.abs(A).max() <= RICCATI_SETTLED:
            return H, (doubling + 1) if H[0, 0] + R > 0.0 else -1
    return H, -1


@numba.njit(cache=True)
def char_poly(M):  # pragma: no cover - compiled
    """``np.poly(M)`` of a small real square matrix: the characteristic polynomial's coefficients (highest power
    first), by the Faddeev-LeVerrier recursion ``N_k = M N_(k-1) + c_(k-1) I``, ``c_k = -tr(M N_k) / k`` (within
    1e-14 of numpy's, which multiplies out the eigenvalues, on the likelihood's 3- and 4-state predictors)."""
    m = M.shape[0]
    c = np.zeros(m + 1)
    c[0] = 1.0
    MN = np.zeros((m, m))  # M N_0, N_0 = 0
    for k in range(1, m + 1):
        N = MN  # N_k = M N_(k-1) + c_(k-1) I: the product the last step's trace was taken of
        for i in range(m):
            N[i, i] += c[k - 1]
        MN = _product(M, N)
        trace = 0.0
        for i in range(m):
            trace += MN[i, i]
        c[k] = -trace / k
    return c


@numba.njit(cache=True)
def predictor_polynomials(Ad, gain, inputs):  # pragma: no cover - compiled
    """``(den, numerators)`` of the steady-state predictor ``x+ = Phi x + b u``, ``Phi = Ad - gain e0'`` (``gain`` the
    predictor's, ``Ad L``), read at its first state: ``den`` the characteristic polynomial of ``Phi`` (m + 1,) and,
    for each row ``b`` of ``inputs`` (k, m), the numerator of ``e0' (zI - Phi)^-1 b`` (k, m + 1): ``e0' adj(zI - Phi)
    b = det(zI - Phi + b e0') - det(zI - Phi)`` (the determinant lemma), so it is ``char_poly(Phi - b e0') - den``."""
    m = Ad.shape[0]
    Phi = Ad.copy()
    Phi[:, 0] -= gain
    den = char_poly(Phi)
    numerators = np.empty((inputs.shape[0], m + 1))
    for i in range(inputs.shape[0]):
        shifted = Phi.copy()
        shifted[:, 0] -= inputs[i]
        numerators[i] = char_poly(shifted) - den
    return den, numerators
