"""Attitude as a unit quaternion, and its conversion to and from ZYX Euler angles (eqs. 25-29).

The physics core carries the attitude as the quaternion ``(q0, q1, q2, q3)`` of
eqs. (25)-(26); reports, rewards and logs speak Euler angles roll, pitch, yaw
(eqs. 27-29). The conversion is written here once, as the text of the five
arguments of ``atan2``/``asin`` (:data:`EULER_ARGUMENTS`). That text is compiled
into :func:`euler_arguments`, which :func:`euler_from_quaternion` (numpy arrays)
and :func:`euler_from_quaternion_scalar` (Python floats, the per-step path of a
single environment) share, and :mod:`heli_env.kernels` puts the same text into
the vector environment's numba loop, so every path does the same arithmetic and
agrees bit for bit.
"""

from __future__ import annotations

import math

import numpy as np


def quaternion_from_euler(phi, theta, psi) -> np.ndarray:
    """Unit quaternion of ZYX Euler angles, the attitude state of eqs. (25)-(26).

    Parameters
    ----------
    phi, theta, psi : float or ndarray, shape (...)
        Roll, pitch, yaw [rad].

    Returns
    -------
    ndarray, shape (4, ...)
        ``(q0, q1, q2, q3)``, ``q0`` the scalar part.
    """
    cr, sr = np.cos(np.multiply(phi, 0.5)), np.sin(np.multiply(phi, 0.5))
    cp, sp = np.cos(np.multiply(theta, 0.5)), np.sin(np.multiply(theta, 0.5))
    cy, sy = np.cos(np.multiply(psi, 0.5)), np.sin(np.multiply(psi, 0.5))
    return np.array([
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ])


EULER_ARGUMENTS = (
    "2.0 * (q0 * q1 + q2 * q3)",
    "1.0 - 2.0 * (q1 * q1 + q2 * q2)",
    "2.0 * (q0 * q2 - q3 * q1)",
    "2.0 * (q0 * q3 + q1 * q2)",
    "1.0 - 2.0 * (q2 * q2 + q3 * q3)",
)
"""Eqs. (27)-(29) with ``atan2`` for the paper's arcsin/arccos, as expressions over ``q0 .. q3``:
roll = atan2(a0, a1), pitch = asin(clip(a2, -1, 1)), yaw = atan2(a3, a4). The one definition of
the conversion (module docstring)."""

_SOURCE = (
    "def euler_arguments(q0, q1, q2, q3):\n"
    f"    return ({', '.join(EULER_ARGUMENTS)})\n"
)
_namespace: dict = {}
exec(compile(_SOURCE, "<heli_core euler_arguments>", "exec"), _namespace)  # noqa: S102
euler_arguments = _namespace["euler_arguments"]
euler_arguments.__doc__ = """The five arguments :data:`EULER_ARGUMENTS` of a quaternion.

Parameters
----------
q0, q1, q2, q3 : float or ndarray, shape (...)
    Unit quaternion, ``q0`` the scalar part.

Returns
-------
tuple of 5 (float or ndarray, shape (...))
    ``a0 .. a4``: roll = atan2(a0, a1), pitch = asin(a2) (after clipping to [-1, 1]),
    yaw = atan2(a3, a4).
"""


def euler_from_quaternion(quat) -> np.ndarray:
    """ZYX Euler angles of a quaternion, eqs. (27)-(29).

    Equivalent to eqs. (27)-(29) with atan2 in place of the paper's arcsin/arccos,
    so that the yaw angle keeps its sign and the full range (-pi, pi].

    Parameters
    ----------
    quat : ndarray, shape (4, ...)
        ``(q0, q1, q2, q3)``, unit norm.

    Returns
    -------
    ndarray, shape (3, ...)
        Roll ``phi``, pitch ``theta``, yaw ``psi`` [rad].
    """
    a0, a1, a2, a3, a4 = euler_arguments(*quat)
    return np.array([np.arctan2(a0, a1), np.arcsin(np.clip(a2, -1.0, 1.0)), np.arctan2(a3, a4)])


def euler_from_quaternion_scalar(q0: float, q1: float, q2: float, q3: float) -> tuple[float, float, float]:
    """:func:`euler_from_quaternion` of one quaternion in Python floats (eqs. 27-29).

    The per-step path of the single environment and the synthetic pilot, where
    numpy's per-call overhead would dominate.

    Parameters
    ----------
    q0, q1, q2, q3 : float
        Unit quaternion, ``q0`` the scalar part.

    Returns
    -------
    tuple of 3 float
        Roll, pitch, yaw [rad].
    """
    a0, a1, a2, a3, a4 = euler_arguments(q0, q1, q2, q3)
    return (math.atan2(a0, a1), math.asin(max(-1.0, min(1.0, a2))), math.atan2(a3, a4))


def euler_rates(phi, theta, p, q, r) -> np.ndarray:
    """The rates of the ZYX Euler angles (roll, pitch, yaw) at attitude ``phi``, ``theta`` for body rates
    ``p``, ``q``, ``r`` [rad/s]: the kinematics the angles of eqs. (27)-(29) follow. Arrays or floats; returns
    shape (3,) + their shape. Infinite at ``theta`` = +-90 deg (gimbal lock), where the angles are undefined."""
    s, c = np.sin(phi), np.cos(phi)
    return np.array([p + (q * s + r * c) * np.tan(theta), q * c - r * s, (q * s + r * c) / np.cos(theta)])
