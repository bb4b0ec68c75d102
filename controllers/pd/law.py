"""The PD law and the sign of an axis' control gain: what the controller, its design and the sweep share.

:func:`pd_command` is the package's one PD law (the controller's ``predict``, the
sweep's batched and linear closed loops); :func:`control_sign` gives the sign
``s_i`` that makes positive gains stabilise. Both stand on the model's
parameters only, not on its linearisation, so that the controller does not
import the design machinery.
"""

from __future__ import annotations

import numpy as np

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
