"""The plant of one axis: the decoupled linearisation of the identified model, continuous and sampled.

Each axis is designed on the decoupled linearisation of the identified model at
rest (zero rates, servo settled, collective 0). For roll, eq. (18) gives::

    p' = -k3 p + k2 c + d          c: stick after the servo, d: gust torque per inertia
    c  = exp(-s tau) u  ~  (n1 - n2 s) / (1 + d1 s) u      first-order Padé servo, eq. (31)
    phi' = p

and pitch and yaw the same with (k6, k7, tau_pitch) and (k10, k11, tau_yaw) of
eq. (21). The matrices come from :func:`heli_core.linear.hover_linearisation`,
the package's one linearisation of the physics core, and keep only the axis' own block:
the flybar cross-coupling (k4, k8) and the gyroscopic products (k1, k5, k9) are
left out (per-axis design on the decoupled part; the paper finds the coupling
"swamped by wind disturbance", Section 3), and so are the collective-scheduled
gains (``gs1``-``gs3``, zero at collective 0). Products like ``p|p|`` have zero
slope at rest and drop out of a linearisation anyway.

The environment holds each action over the control period (zero-order hold) and
may queue it for whole periods (``action_delay``): :func:`_sampled` gives the
axis as the environment runs it.
"""

from __future__ import annotations

import math
import warnings

import control
import numpy as np

from heli_core.deprecation import module_getattr
from heli_core.linear import hover_linearisation
from heli_core.params import ModelParams
from heli_core.terms import AXES

from .law import _axis_index


def _check_dt(dt) -> float:
    if not (isinstance(dt, (int, float, np.floating, np.integer)) and math.isfinite(dt) and dt >= 0):
        raise ValueError(f"dt must be a control period >= 0 s (0 for continuous time), got {dt!r}")
    return float(dt)


def _check_delay(delay_steps, dt) -> int:
    if int(delay_steps) != delay_steps or delay_steps < 0:
        raise ValueError(f"delay_steps must be a whole number of control periods >= 0, got {delay_steps!r}")
    if delay_steps and dt == 0:
        raise ValueError("delay_steps needs a control period dt > 0")
    return int(delay_steps)


def _axis_ss(params: ModelParams, axis: int):
    """Continuous state space of one decoupled axis, eqs. (18), (21), (31).

    States ``(rate, [servo z], angle)``, inputs ``(stick u, torque d)``, outputs
    ``(angle, rate)``. The servo state appears only when the axis has a delay. The axis'
    own block of the package's one linearisation (:func:`heli_core.linear.hover_linearisation`)
    at collective 0.
    """
    A, B, states = hover_linearisation(params, 0.0).axis_block(axis)
    C = np.zeros((2, A.shape[0]))
    C[0, -1] = 1.0  # angle
    C[1, 0] = 1.0  # rate
    return A, B, C


def _sampled(params: ModelParams, axis: int, dt: float, delay_steps: int = 0):
    """(A, B, C) of the axis as the environment runs it: ZOH at ``dt`` and ``delay_steps`` periods of action delay.

    ``dt == 0`` returns the continuous matrices. The delay is a shift register
    in front of the stick input (the environment's ``action_delay`` queue).
    """
    A, B, C = _axis_ss(params, axis)
    if dt == 0:
        return A, B, C
    d = control.c2d(control.ss(A, B, C, np.zeros((2, 2))), dt, "zoh")
    A, B, C = np.asarray(d.A), np.asarray(d.B), np.asarray(d.C)
    if delay_steps:
        n, m = A.shape[0], delay_steps
        Aa = np.zeros((n + m, n + m))
        Aa[:n, :n] = A
        Aa[:n, n + m - 1] = B[:, 0]  # the oldest queued action reaches the aircraft
        for k in range(1, m):
            Aa[n + k, n + k - 1] = 1.0
        Ba = np.zeros((n + m, 2))
        Ba[n, 0] = 1.0
        Ba[:n, 1] = B[:, 1]
        A, B, C = Aa, Ba, np.hstack([C, np.zeros((2, m))])
    return A, B, C


def _tf(sys) -> control.TransferFunction:
    """:func:`control.ss2tf` of a SISO system, leading numerator coefficients that are rounding noise removed."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy's BadCoefficients for those same near-zero coefficients
        tf = control.ss2tf(sys)
    num = np.atleast_1d(np.squeeze(tf.num[0][0])).astype(float)
    den = np.atleast_1d(np.squeeze(tf.den[0][0])).astype(float)
    scale = max(np.max(np.abs(num)), 1e-300)
    first = np.nonzero(np.abs(num) > 1e-12 * scale)[0]
    num = num[first[0]:] if first.size else np.zeros(1)
    return control.tf(num, den, sys.dt)


def plant(params: ModelParams, axis, output: str = "angle") -> control.TransferFunction:
    """Continuous transfer function from the axis' stick offset to its angle (or rate).

    The decoupled linearisation at rest of eqs. (18), (21) with the Padé servo of
    eq. (31) when the model has a delay for the axis. For roll::

        P(s) = k2 (n1 - n2 s) / ((1 + d1 s) (s + k3) s)       (without delay: k2 / (s (s + k3)))

    Parameters
    ----------
    params : ModelParams
        Identified model.
    axis : {"roll", "pitch", "yaw"} or int
        Axis; its stick is lat, lon or ped.
    output : {"angle", "rate"}
        Roll/pitch/yaw angle [rad] or body rate p/q/r [rad/s].

    Returns
    -------
    control.TransferFunction
        Continuous time, from stick [stick units] to angle [rad] or rate [rad/s].
        The model's sign is kept (pitch is negative for the paper's k6 < 0).
    """
    i = _axis_index(axis)
    if output not in ("angle", "rate"):
        raise ValueError(f"output must be 'angle' or 'rate', got {output!r}")
    A, B, C = _axis_ss(params, i)
    if output == "angle":
        return _tf(control.ss(A, B[:, :1], C[:1], 0.0))
    # the angle (last state) does not feed back into the rate: leave it out for a minimal realisation
    return _tf(control.ss(A[:-1, :-1], B[:-1, :1], C[1:, :-1], 0.0))



__getattr__ = module_getattr(__name__)
"""The law's :func:`~controllers.pd.law.control_sign`, once importable from here (deprecated: :mod:`controllers._deprecated`)."""
