"""Attitude from body rates (eqs. 25-29) and the paper's 10 s detrend.

The quaternion kinematics of eq. (25) are integrated exactly for rates held
constant over each sample interval (the rotation increment is the quaternion
exponential of ``omega*dt/2``, trapezoidal mean of the two samples), starting
from the level attitude of eq. (26). Euler angles follow from the rotation
matrix of eq. (27) with :func:`heli_core.quaternion.euler_from_quaternion`.
"""

from __future__ import annotations

import math

import numpy as np

from heli_core.quaternion import euler_from_quaternion, quaternion_from_euler

DETREND_PERIOD = 10.0
"""Length of the linear pieces removed from the angles before comparison [s] (Section 3.2)."""


def quaternions_from_rates(time, rates, euler0=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Integrate eq. (25) over a rate history.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    rates : ndarray, shape (3, n)
        Body rates p, q, r [rad/s].
    euler0 : tuple of 3 float
        Initial roll, pitch, yaw [rad]; eq. (26) is the default level start.

    Returns
    -------
    ndarray, shape (4, n)
        Unit quaternions (q0, q1, q2, q3).
    """
    time = np.asarray(time, dtype=float)
    rates = np.asarray(rates, dtype=float)
    dt = np.diff(time)
    mean = 0.5 * (rates[:, 1:] + rates[:, :-1]) * dt  # rotation vector per step
    angle = np.sqrt(np.sum(mean * mean, axis=0))
    half = 0.5 * angle
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(angle > 1e-12, np.sin(half) / angle, 0.5)
    inc = np.vstack([np.cos(half), mean * scale]).T.tolist()  # body-frame increments
    out = np.empty((time.size, 4))
    a0, a1, a2, a3 = (float(v) for v in quaternion_from_euler(*euler0))
    out[0] = (a0, a1, a2, a3)
    for k, (b0, b1, b2, b3) in enumerate(inc, start=1):
        # q_{k} = q_{k-1} (x) dq : the exact solution of eq. (25) for constant omega
        a0, a1, a2, a3 = (
            a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
        )
        norm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
        a0, a1, a2, a3 = a0 / norm, a1 / norm, a2 / norm, a3 / norm
        out[k] = (a0, a1, a2, a3)
    return out.T


def attitude_from_rates(time, rates, euler0=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Euler angles (phi, theta, psi) [rad], shape (3, n), from body rates, eqs. (25)-(29)."""
    return euler_from_quaternion(quaternions_from_rates(time, rates, euler0))


def detrend_piecewise(time, values, period: float = 10.0) -> np.ndarray:
    """Subtract the best least-squares continuous piecewise-linear function over ``period`` s pieces.

    The paper removes integration drift from modelled and measured angles this
    way (Matlab ``detrend`` with break points every 10 s, Section 3.2). Matlab's
    trend is continuous at the break points (a line plus one ramp per break);
    :func:`scipy.signal.detrend` with ``bp`` is not (it fits every piece on its
    own and so also removes jumps), so the regression is built here.

    Parameters
    ----------
    time : ndarray, shape (n,)
    values : ndarray, shape (..., n)
    period : float
        Length of the linear pieces [s].
    """
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    idx = np.searchsorted(time, np.arange(time[0] + period, time[-1], period))
    idx = np.unique(idx[(idx > 1) & (idx < time.size - 1)])
    s = (time - time[0]) / max(time[-1] - time[0], np.finfo(float).tiny)  # scaled for conditioning
    basis = np.column_stack([np.ones_like(s), s] + [np.maximum(s - s[i], 0.0) for i in idx])  # (n, 2 + breaks)
    y = values.reshape(-1, time.size).T  # (n, m)
    coef = np.linalg.lstsq(basis, y, rcond=None)[0]
    return (y - basis @ coef).T.reshape(values.shape)


def detrended_angles(time, angles, period: float = DETREND_PERIOD) -> np.ndarray:
    """Unwrapped angles minus their best piecewise-linear fit over ``period`` s pieces [deg].

    Section 3.2: "to remove drift in integration, the best least squares
    piecewise linear function over 10 s periods is subtracted from the data and
    the model" (:func:`detrend_piecewise`).

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times [s].
    angles : array_like, shape (3, n)
        Roll, pitch, yaw [rad], wrapped or not.
    period : float
        Length of the linear pieces [s].

    Returns
    -------
    ndarray, shape (3, n)
        Detrended angles [deg].
    """
    angles = np.unwrap(np.asarray(angles, dtype=float), axis=-1)
    return np.degrees(detrend_piecewise(time, angles, period))
