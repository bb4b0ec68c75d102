"""The PD law and the sign of an axis' control gain: what the controller, its design and the sweep share.

:func:`pd_command` is the package's one PD law (the controller's ``predict``, the
sweep's batched and linear closed loops); :func:`control_sign` gives the sign
``s_i`` that makes positive gains stabilise; :func:`derivative_pole` and
:func:`filtered_rate` are the D term's first-order low-pass, sampled at the
control period. They stand on the model's parameters only, not on its
linearisation, so that the controller does not import the design machinery.

The derivative filter
---------------------
A filter of cutoff ``f_c`` [Hz] (time constant ``tau = 1/(2 pi f_c)``) acts on the
rate error before the derivative gain; sampled at the control period ``dt`` it is
the pole-matched first-order low-pass::

    y[k] = a y[k-1] + (1 - a) e_rate[k],      a = exp(-dt / tau),
    F(z) = (1 - a) z / (z - a)

unit gain at DC and no added delay at the current sample. At an episode's first
period the state starts at the current rate error (``y[0] = e_rate[0]``: no
transient). No filter is ``a = 0`` and is skipped, so an unfiltered PD computes the very
numbers it computed before the filter existed.
"""

from __future__ import annotations

import numpy as np

import math

from heli_core.params import ModelParams
from heli_core.terms import AXES


def _axis_index(axis) -> int:
    """0, 1, 2 for "roll", "pitch", "yaw" (or the index itself)."""
    if isinstance(axis, str) and axis in AXES:
        return AXES.index(axis)
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and 0 <= axis < 3:
        return int(axis)
    raise ValueError(f"axis must be one of {AXES} or 0, 1, 2, got {axis!r}")


def control_sign(params: ModelParams, axis) -> float:
    """Sign of the axis' control gain (k2, k6, k10): +1 or -1.

    Raises
    ------
    ValueError
        The control gain is zero: the stick does not move that axis.
    """
    i = _axis_index(axis)
    k = float(params.control_gains[i])
    if k == 0.0:
        raise ValueError(f"the model's {AXES[i]} control gain {('k2', 'k6', 'k10')[i]} is 0: the axis cannot be controlled")
    return 1.0 if k > 0 else -1.0


def pd_command(kp, kd, sign, e_angle, e_rate):
    """The per-axis PD law: ``u = s·(kp·e_angle + kd·e_rate)``, a stick offset from trim (unclipped).

    Parameters
    ----------
    kp : float or ndarray
        Proportional gain [stick/rad].
    kd : float or ndarray
        Derivative gain [stick/(rad/s)].
    sign : float
        Sign of the axis' control gain (k2, k6, k10), so that positive gains stabilise.
    e_angle : float or ndarray
        Reference minus angle [rad] (the sweep holds level: ``-angle``).
    e_rate : float or ndarray
        Reference rate minus body rate [rad/s] (the sweep: ``-rate``).

    Notes
    -----
    The package's one PD law, for floats and numpy batches alike: the batched closed loop
    (:mod:`controllers.replay`) evaluates it for many gain pairs at once, the linear closed
    loop takes its slopes (:func:`controllers.closed_loop.gain_matrices`), and
    :class:`controllers.pd.PDController` (``predict``: ``clip(s·(kp·obs[0:3] + kd·obs[6:9]), -1, 1)``)
    computes the same numbers (``tests/test_sweep.py`` checks it; ``sign`` is ±1, so
    ``s·(kp·e + kd·ė)`` and ``(s·kp)·e + (s·kd)·ė`` agree bit for bit). The caller clips the
    result to [-1, 1] and adds the trim.
    """
    return sign * (kp * e_angle + kd * e_rate)


def check_cutoff(cutoff_hz, name: str = "d_filter_hz"):
    """A derivative-filter cutoff as a float > 0 [Hz], or None (no filter); ValueError otherwise."""
    if cutoff_hz is None:
        return None
    ok = isinstance(cutoff_hz, (int, float, np.floating, np.integer)) and not isinstance(cutoff_hz, bool)
    if not (ok and math.isfinite(cutoff_hz) and cutoff_hz > 0):
        raise ValueError(f"{name} must be a cutoff frequency > 0 Hz or None (no filter), got {cutoff_hz!r}")
    return float(cutoff_hz)


def derivative_pole(cutoff_hz, dt: float) -> float:
    """The sampled filter's pole ``a = exp(-2 pi f_c dt)`` (module docstring); 0.0 for no filter (None).

    Parameters
    ----------
    cutoff_hz : float or None
        Cutoff of the D term's first-order low-pass [Hz], > 0; None: no filter.
    dt : float
        Control period [s], > 0.
    """
    cutoff_hz = check_cutoff(cutoff_hz)
    if cutoff_hz is None:
        return 0.0
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"a derivative filter needs a control period dt > 0 s, got {dt!r}")
    return math.exp(-2.0 * math.pi * cutoff_hz * dt)


def filtered_rate(previous, e_rate, pole, start=None):
    """One period of the D term's low-pass: ``a·y[k-1] + (1-a)·e_rate[k]`` (``e_rate`` itself where ``start``).

    Parameters
    ----------
    previous : float or ndarray, or None
        The filter's output of the previous period [rad/s]; None: every element starts now.
    e_rate : float or ndarray
        This period's rate error [rad/s].
    pole : float or ndarray
        ``a`` of :func:`derivative_pole`, broadcast against ``e_rate``; 0 passes ``e_rate`` through.
    start : ndarray of bool, optional
        Elements whose episode starts now (broadcast against ``e_rate``): their state restarts at ``e_rate``.

    Returns
    -------
    ndarray or float
        The filtered rate error [rad/s], the next period's ``previous``.
    """
    if previous is None:
        return e_rate
    y = pole * previous + (1.0 - pole) * e_rate
    return y if start is None else np.where(start, e_rate, y)


def law_state_space(kp: float, kd: float, sign: float, cutoff_hz=None, dt: float = 0.0):
    """The per-axis PD law as a linear system from (attitude error, rate error) to the stick offset.

    ``(Ak, Bk, Ck, Dk)`` with ``w' = Ak w + Bk e`` (``w[k+1]`` for ``dt > 0``), ``u = Ck w + Dk e``,
    ``e = (e_angle, e_rate)``. Without a filter there is no state (``Ak`` is 0 × 0) and ``Dk = s (kp, kd)``.
    With one, sampled (``dt > 0``): ``w`` is the filter's previous output, ``Ak = a``, ``Bk = (0, 1 - a)``,
    ``Ck = s kd a``, ``Dk = s (kp, kd (1 - a))`` (:func:`filtered_rate`); continuous (``dt = 0``):
    ``w`` is the filtered rate error, ``tau w' = e_rate - w``, ``Ck = s kd``, ``Dk = s (kp, 0)``.

    Parameters
    ----------
    kp, kd : float
        Gains [stick/rad], [stick/(rad/s)].
    sign : float
        Sign of the axis' control gain.
    cutoff_hz : float or None
        The derivative filter's cutoff [Hz]; None: none.
    dt : float
        Control period [s]; 0 for continuous time.

    Returns
    -------
    Ak (m, m), Bk (m, 2), Ck (1, m), Dk (1, 2) : ndarray, m = 0 or 1
    """
    cutoff_hz = check_cutoff(cutoff_hz)
    if cutoff_hz is None:
        return np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((1, 0)), sign * np.array([[kp, kd]], dtype=float)
    if dt:
        a = derivative_pole(cutoff_hz, dt)
        return (np.array([[a]]), np.array([[0.0, 1.0 - a]]), np.array([[sign * kd * a]]),
                sign * np.array([[kp, kd * (1.0 - a)]]))
    w = 2.0 * math.pi * cutoff_hz
    return np.array([[-w]]), np.array([[0.0, w]]), np.array([[sign * kd]]), sign * np.array([[kp, 0.0]])
