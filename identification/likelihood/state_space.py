"""The state-space pieces of the wind-state model: discretisation, Kalman filter, smoother (one axis).

The maximum-likelihood estimator (:mod:`identification.likelihood.estimator`) and the likelihood diagnosis
(:mod:`identification.diagnosis.likelihood_diagnoser`) model one body rate and its gust as a linear system::

    rate' = -damping * rate + (inputs) + sum of gust states        (eq. 18 / 21 with the wind of eqs. 41-42)
    gust states: a slow first-order Gauss-Markov process and a fast first- or second-order one
    y = rate + white gyro noise

This module discretises it exactly (matrix exponential under the stick's hold; Van Loan's method for
the process noise), gives the steady-state Kalman filter and its innovation filters as transfer
functions for ``scipy.signal.lfilter`` (no loop over samples), the command's exact path through the
Padé servo of eq. (31), and the steady-state Rauch-Tung-Striebel smoother.
"""

from __future__ import annotations

import numpy as np
from scipy import signal
from scipy.linalg import expm, solve_discrete_are

from heli_core.servo import servo_coefficients

from .input_hold import hold_fraction

WIND_MODELS = ("gm2", "gm_so")
"""Gust models: ``"gm2"`` a slow plus a fast first-order Gauss-Markov process (a
Dryden-like spectrum falling as 1/f^2 above each corner); ``"gm_so"`` a slow
first-order process plus a fast second-order one of natural period ``T_fast`` and
damping ratio ``zeta`` (falling as 1/f^4: smooth gusts; a Butterworth low-pass at
zeta = 0.71, two cascaded first-order stages at zeta = 1)."""

ZETA_BOUNDS = (0.2, 3.0)
"""Bounds of the fast second-order gust's damping ratio."""

N_NONLINEAR = {"gm2": 6, "gm_so": 7}
"""Length of the model part of the search vector: damping, log T_slow, log T_fast, log(var_slow/R),
log(var_fast/R), the input's hold fraction (:data:`HOLD_INDEX`), and for ``"gm_so"`` log zeta. A part the
caller fixes (the damping of a structure without one, a hold the user sets) stays in the vector, unsearched."""

HOLD_INDEX = 5
"""Index of the hold fraction in the search vector (the same for every wind model)."""


def wind_block(kind: str, t_slow: float, t_fast: float, zeta: float = 1.0):
    """The gust states of one wind model.

    Returns ``Aw`` (m, m), the row ``cw`` (m,) summing the states into the
    torque, and per noise channel its input column (m,) scaled so that the
    channel's torque component has unit stationary variance.
    """
    if kind == "gm2":
        Aw = np.diag([-1.0 / t_slow, -1.0 / t_fast])
        cw = np.array([1.0, 1.0])
        # x' = -x/T + sqrt(2/T) n  has unit variance
        cols = [np.array([np.sqrt(2.0 / t_slow), 0.0]), np.array([0.0, np.sqrt(2.0 / t_fast)])]
        return Aw, cw, cols
    if kind == "gm_so":
        cw = np.array([1.0, 1.0, 0.0])
        # w'' + 2 zeta w w' + w^2 w = b n (w = 1/T_fast): var(w) = b^2 / (4 zeta w^3) for unit-intensity n
        om = 1.0 / t_fast
        Aw = np.array([[-1.0 / t_slow, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -om * om, -2.0 * zeta * om]])
        return Aw, cw, [np.array([np.sqrt(2.0 / t_slow), 0.0, 0.0]), np.array([0.0, 0.0, np.sqrt(4 * zeta * om ** 3)])]
    raise ValueError(f"wind model must be one of {WIND_MODELS}, got {kind!r}")


def discrete_model(damping: float, t_slow: float, t_fast: float, q_slow: float, q_fast: float, zeta: float,
                   dt: float, hold: str, kind: str = "gm2"):
    """Exact discretisation of the axis model over one sample.

    State ``(rate, gust states...)``. Returns ``Ad``, the input vectors ``g0``,
    ``g1`` such that ``x[k+1] = Ad x[k] + g0 u[k] + g1 u[k+1]`` (``g1 = 0`` for a
    held input; ``hold`` a name or fraction, :func:`hold_fraction`) and the process-noise
    covariance ``Qd`` by Van Loan's method, for stationary gust-torque variances ``q_slow``, ``q_fast``.
    """
    Ad, ga, gb, Qd = discrete_system(damping, t_slow, t_fast, q_slow, q_fast, zeta, dt, kind)
    g0, g1 = input_vectors(ga, gb, hold)
    return Ad, g0, g1, Qd


def discrete_system(damping: float, t_slow: float, t_fast: float, q_slow: float, q_fast: float, zeta: float,
                    dt: float, kind: str = "gm2"):
    """The part of :func:`discrete_model` the input's hold does not touch: ``Ad``, the held input's vector
    ``ga``, the ramp's ``gb`` (:func:`input_vectors` combines them for a hold) and ``Qd``."""
    Aw, cw, cols = wind_block(kind, t_slow, t_fast, zeta)
    m = Aw.shape[0] + 1
    A = np.zeros((m, m))
    A[0, 0] = -damping
    A[0, 1:] = cw
    A[1:, 1:] = Aw
    M = np.zeros((m + 2, m + 2))
    M[:m, :m] = A * dt
    M[0, m] = dt
    M[m, m + 1] = 1.0
    E = expm(M)
    Ad = E[:m, :m]
    ga, gb = E[:m, m], E[:m, m + 1]
    Qd = np.zeros((m, m))
    for q, col in zip((q_slow, q_fast), cols):  # unit intensities keep expm well scaled
        b = np.concatenate([[0.0], col])
        V = np.zeros((2 * m, 2 * m))
        V[:m, :m] = -A * dt
        V[:m, m:] = np.outer(b, b) * dt
        V[m:, m:] = A.T * dt
        F = expm(V)
        Qd += q * (F[m:, m:].T @ F[:m, m:])
    return Ad, ga, gb, 0.5 * (Qd + Qd.T)


def input_vectors(ga, gb, hold):
    """``g0``, ``g1`` of :func:`discrete_model` from :func:`discrete_system`'s ``ga``, ``gb`` for a hold."""
    frac = hold_fraction(hold)  # u(t) = u_k + frac (u_{k+1} - u_k) (t - t_k)/dt
    return ga - frac * gb, frac * gb


def kalman(Ad, Qd, R: float = 1.0):
    """Steady-state Kalman filter of a rate (the first state) measured with white noise of variance ``R``.

    Returns the predicted covariance ``P`` (m, m), the filter gain ``L`` (m,)
    (``x_{k|k} = x_{k|k-1} + L e_k``) and the innovation variance ``S``.

    ``P`` by compiled structured doubling (:func:`~identification.likelihood.steady_kernels.filter_riccati`, a
    fifteenth of scipy's time on these small models); where that does not converge to a stable filter, by
    ``scipy.linalg.solve_discrete_are``, which raises ``LinAlgError`` where no stabilising solution exists.
    """
    from .steady_kernels import filter_riccati  # numba loads with the first evaluation, not with the package

    P, doublings = filter_riccati(np.ascontiguousarray(Ad, dtype=float), np.ascontiguousarray(Qd, dtype=float),
                                  float(R))
    if doublings < 0:
        m = Ad.shape[0]
        C = np.zeros((m, 1))
        C[0, 0] = 1.0
        P = solve_discrete_are(Ad.T, C, Qd, np.array([[R]]))
    S = float(P[0, 0] + R)
    L = P[:, 0] / S
    return P, L, S


def covariance_root(C: np.ndarray) -> np.ndarray:
    """A square root ``L`` with ``L L' = C`` of a symmetric positive semi-definite matrix (eigenvalues < 0 cut):
    ``L @ standard normals`` draws with covariance ``C`` (a process noise's ``Qd`` may be singular)."""
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    return V * np.sqrt(np.clip(w, 0.0, None))


def concentrated_nll(cost: float, n: int) -> float:
    """Negative log-likelihood of ``n`` Gaussian innovations whose least-squares ``cost`` is half their sum of
    squares, with their variance concentrated out (set to its estimate ``2 cost / n``)."""
    return 0.5 * n * (np.log(2.0 * np.pi * 2.0 * cost / n) + 1.0)


def innovation_filters(Ad, g0, g1, L, *more):
    """Linear filters giving the innovations from the measurements and each input.

    With ``Phi = Ad (I - L e0')`` the predictor is
    ``x_{k+1|k} = Phi x_{k|k-1} + Ad L y_k + g0 u_k + g1 u_{k+1}``, so
    ``e = y - H_y(z) y - H_u(z) u`` with the returned ``(b_y, b_u, a)``; then, for each further input vector of
    ``more``, the numerator of its strictly proper path to the predicted rate (over the same ``a``). One compiled
    call (:func:`~identification.likelihood.steady_kernels.predictor_polynomials`).
    """
    from .steady_kernels import predictor_polynomials

    gain = Ad @ L  # the predictor's gain on the innovation: Phi = Ad - gain e0', and the measurement's input
    a, numerators = predictor_polynomials(np.ascontiguousarray(Ad), gain, np.array([gain, g0, g1, *more], dtype=float))
    b_y, b0, b1 = numerators[:3]
    b_u = b0.copy()
    b_u[:-1] += b1[1:]  # z * (strictly proper): the u_{k+1} path
    return (b_y, b_u, a, *numerators[3:])


def servo_step(damping: float, tau: float, dt: float, hold: str, lag: float = 0.0) -> tuple:
    """One sample of the servo of eq. (31) (its Padé delay ``tau`` and first-order ``lag``,
    :func:`heli_core.servo.servo_coefficients`) driving a rate of ``damping``, discretised exactly with the stick
    held, linearly interpolated or a fraction between (``hold``, :func:`hold_fraction`).

    The continuous system ``rate' = -damping*rate + f*u + g*z``, ``z' = (u - z)/d1`` (the Padé servo split into
    feed-through ``f`` and state ``g``) over one sample, from a rate of zero. Returns ``(e_rz, e_zz, h0, h1)``:
    the command's increment of the rate from ``k`` to ``k+1`` (per unit control gain) is
    ``e_rz*z[k] + h0[0]*u[k] + h1[0]*u[k+1]`` and the servo's next state ``e_zz*z[k] + h0[1]*u[k] + h1[1]*u[k+1]``.

    Raises
    ------
    ValueError
        Neither a delay nor a lag (no servo state: the command enters the rate directly).
    """
    from .gyro_path import path_step  # the general path (a gyro filter before the servo): one state here

    if servo_coefficients(tau, lag)[0] <= 0.0:
        raise ValueError(f"a servo needs a delay or a lag > 0, got tau={tau!r}, lag={lag!r}")
    e_rz, e_zz, h0, h1 = path_step(damping, dt, hold, tau, lag)
    return float(e_rz[0]), float(e_zz[0, 0]), h0, h1


def servo_increments(sticks, damping: float, tau: float, dt: float, hold: str, lag: float = 0.0,
                     corner_hz: float | None = None) -> np.ndarray:
    """The command's exact contribution to the rate over each sample, through the servo of eq. (31)
    (:func:`servo_step`): ``v[k]``, the rate's increment from ``k`` to ``k+1`` due to the command (per unit
    control gain), so that the rate sees ``k2*v[k]`` as a one-sample input. The servo state starts settled on the
    first stick. With ``corner_hz`` the stick passes the gyro filter the log states first, and with neither a servo
    nor a filter it enters the rate directly (:func:`~identification.likelihood.gyro_path.path_increments`; a flight
    pooled with filtered ones).
    """
    if corner_hz is not None or (tau <= 0.0 and lag <= 0.0):
        from .gyro_path import path_increments

        return path_increments(sticks, damping, tau, dt, hold, lag, corner_hz)
    e_rz, e_zz, h0, h1 = servo_step(damping, tau, dt, hold, lag)
    u = np.asarray(sticks, dtype=float)
    u_next = np.append(u[1:], u[-1])
    w = h0[1] * u + h1[1] * u_next
    z = np.empty_like(u)
    z[0] = u[0]
    z[1:] = signal.lfilter([1.0], [1.0, -e_zz], w[:-1], zi=[e_zz * u[0]])[0]
    return e_rz * z + h0[0] * u + h1[0] * u_next


def lti_apply(A, B, C, D, u) -> np.ndarray:
    """Output of ``x[k+1] = A x[k] + B u[k]``, ``y = C x + D u`` from rest, by transfer functions (lfilter)."""
    y = np.zeros((C.shape[0], u.shape[1]))
    for i in range(B.shape[1]):
        num, den = signal.ss2tf(A, B, C, D, input=i)
        y += np.array([signal.lfilter(row, den, u[i]) for row in np.atleast_2d(num)])
    return y


def rts_smooth(y, drive, damping, t_slow, t_fast, q_slow, q_fast, zeta, dt, hold="linear",
               wind_model="gm2", direct=None) -> np.ndarray:
    """Steady-state Rauch-Tung-Striebel smoother of one axis: the states (rate, gust states...), shape (m, n).

    ``y`` is the measured rate (n,), ``drive`` the known torque from the inputs
    (the linear terms and the offset, n); ``direct`` (n,), when given, the rate's increment from ``k`` to ``k+1``
    due to an input that enters it over the sample on its own (a command through the servo,
    :func:`servo_increments`). Forward: the steady-state Kalman filter
    started at the first measurement; backward:
    ``x_{k|n} = x_{k|k} + G (x_{k+1|n} - x_{k+1|k})`` with the constant smoother gain
    ``G = P_f Ad' P^-1``. Both passes are linear filters (no loop over samples).
    """
    Ad, g0, g1, Qd = discrete_model(damping, t_slow, t_fast, q_slow, q_fast, zeta, dt, hold, wind_model)
    P, L, S = kalman(Ad, Qd)
    m = Ad.shape[0]
    I = np.eye(m)
    Phi = Ad - np.outer(Ad @ L, I[0])
    n = y.size
    u_next = np.append(drive[1:], drive[-1])
    x0 = np.zeros(m)
    x0[0] = y[0]
    # predicted states x_{k|k-1}; the initial state enters as an impulse one step before the record
    U = [np.concatenate([[0.0], y]), np.concatenate([[0.0], drive]), np.concatenate([[0.0], u_next]),
         np.concatenate([[1.0], np.zeros(n)])]
    B = [Ad @ L, g0, g1, x0]
    if direct is not None:
        U.append(np.concatenate([[0.0], np.asarray(direct, dtype=float)]))
        B.append(I[0])
    pred = lti_apply(Phi, np.column_stack(B), I, np.zeros((m, len(B))), np.vstack(U))[:, 1:]
    e = y - pred[0]
    filt = pred + np.outer(L, e)
    Pf = P - np.outer(P[:, 0], P[0, :]) / S
    G = Pf @ Ad.T @ np.linalg.inv(P)
    pred_next = np.hstack([pred[:, 1:], np.zeros((m, 1))])  # the last smoothed state is the filtered one
    g = (filt - G @ pred_next)[:, ::-1]
    # backward in reversed time: z_j = G z_{j-1} + g_j, i.e. w_{j+1} = G w_j + G g_j, z_j = w_j + g_j
    return lti_apply(G, G, I, I, g)[:, ::-1]


