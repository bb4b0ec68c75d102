"""The steady-state Kalman filter of one axis and its transfer functions, compiled: the per-evaluation algebra.

Every evaluation of an axis' likelihood (:meth:`~identification.likelihood.axis_likelihood.AxisLikelihood.filtered`)
solves the filter's algebraic Riccati equation for a model of three or four states and turns the predictor into
the innovation filters' polynomials. Through scipy (``solve_discrete_are``'s QZ decomposition with its argument
checks, ``np.poly`` four times) that took 1.5 ms of an evaluation's 2.3 ms, more than the filters over 30 000
samples (0.35 ms): Python's overhead on 4 x 4 matrices. Here the same quantities, compiled:

* :func:`filter_riccati`: the predicted covariance ``P`` of the filter that measures the first state, by the
  structure-preserving doubling algorithm for discrete-time algebraic Riccati equations (SDA; Chu, Fan, Lin and
  Wang, International Journal of Control 77, 2004): about 15-20 doublings, each
  squaring the closed loop's transition, so that the error after ``k`` falls as ``rho^(2^k)``. Its Riccati
  residual is at or below scipy's (1e-16 against 1e-14 relative where they differ); where it does not converge,
  or its filter is not stable, the caller solves with scipy (:func:`identification.likelihood.state_space.kalman`).
* :func:`char_poly`: ``np.poly`` of a square matrix, from its eigenvalues multiplied out one root at a time;
  :func:`predictor_polynomials`: with it, every polynomial of the predictor's transfer functions in one call.

numba compiles them on first use (``cache=True``); this module is imported on the first evaluation, so importing
the package does not load numba.
"""

from __future__ import annotations

import numba
import numpy as np

RICCATI_TOL = 1e-13
"""The doubling stops when an iterate changes ``P`` by less than this, relative to its largest entry."""

RICCATI_MAX_DOUBLINGS = 60
"""Doublings before :func:`filter_riccati` gives up (each squares the closed loop: 60 reach any stable
spectral radius a float can hold)."""


@numba.njit(cache=True)
def filter_riccati(Ad, Qd, R):  # pragma: no cover - compiled
    """``(P, doublings)``: the stabilising solution ``P`` of ``P = Ad P Ad' - Ad P e0 (e0' P e0 + R)^-1 e0' P Ad' +
    Qd`` (the steady-state predicted covariance of the filter measuring state 0 with noise variance ``R``) by
    structured doubling, and the doublings it took; ``doublings`` is -1 where it did not converge within
    :data:`RICCATI_MAX_DOUBLINGS`, or the converged ``P`` is not finite or gives a filter that is not stable.

    The control-form iteration on ``A = Ad'``, ``G = e0 e0' / R``, ``H = Qd``::

        A <- A (I + G H)^-1 A,  G <- G + A (I + G H)^-1 G A',  H <- H + A' H (I + G H)^-1 A

    ``H`` converges to ``P`` (each step doubles the horizon of the Riccati recursion it sums)."""
    m = Ad.shape[0]
    eye = np.eye(m)
    A = np.ascontiguousarray(Ad.T)
    G = np.zeros((m, m))
    G[0, 0] = 1.0 / R
    H = 0.5 * (Qd + Qd.T)
    for doubling in range(RICCATI_MAX_DOUBLINGS):
        M = eye + G @ H
        WA = np.linalg.solve(M, A)
        WG = np.linalg.solve(M, G)
        H_next = H + A.T @ H @ WA
        G = G + A @ WG @ A.T
        A = A @ WA
        change = np.abs(H_next - H).max()
        H = 0.5 * (H_next + H_next.T)
        G = 0.5 * (G + G.T)
        scale = np.abs(H).max()
        if not np.isfinite(scale):
            return H, -1
        if change <= RICCATI_TOL * scale:
            gain = (Ad @ np.ascontiguousarray(H[:, 0])) / (H[0, 0] + R)  # the predictor's gain: x+ = Ad x + gain e
            closed = Ad.copy()
            closed[:, 0] -= gain
            if H[0, 0] + R <= 0.0 or np.abs(np.linalg.eigvals(closed.astype(np.complex128))).max() >= 1.0:
                return H, -1
            return H, doubling + 1
    return H, -1


@numba.njit(cache=True)
def char_poly(M):  # pragma: no cover - compiled
    """``np.poly(M)`` of a real square matrix: the characteristic polynomial's coefficients (highest power first)
    from its eigenvalues, multiplied out one root at a time (numpy's algorithm), real part."""
    roots = np.linalg.eigvals(M.astype(np.complex128))
    c = np.zeros(roots.size + 1, dtype=np.complex128)
    c[0] = 1.0
    for k in range(roots.size):
        for j in range(k + 1, 0, -1):
            c[j] = c[j] - roots[k] * c[j - 1]
    return c.real.copy()


@numba.njit(cache=True)
def predictor_polynomials(Ad, L, inputs):  # pragma: no cover - compiled
    """``(den, numerators)`` of the steady-state predictor ``x+ = Phi x + b u``, ``Phi = Ad - (Ad L) e0'``, read at
    its first state: ``den`` the characteristic polynomial of ``Phi`` (m + 1,) and, for each row ``b`` of
    ``inputs`` (k, m), the numerator of ``e0' (zI - Phi)^-1 b`` (k, m + 1): ``e0' adj(zI - Phi) b =
    det(zI - Phi + b e0') - det(zI - Phi)`` (the determinant lemma), so it is ``char_poly(Phi - b e0') - den``."""
    m = Ad.shape[0]
    gain = Ad @ np.ascontiguousarray(L)
    Phi = Ad.copy()
    Phi[:, 0] -= gain
    den = char_poly(Phi)
    numerators = np.empty((inputs.shape[0], m + 1))
    for i in range(inputs.shape[0]):
        shifted = Phi.copy()
        shifted[:, 0] -= inputs[i]
        numerators[i] = char_poly(shifted) - den
    return den, numerators
