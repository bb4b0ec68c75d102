"""The one linearisation of the physics core about hover, for design and for the frequency-domain prediction.

:func:`hover_linearisation` differentiates the core's right-hand side (:func:`heli_core.physics.kernel`,
eqs. 18, 21, 31) about hover at the trim — rates 0, every servo settled on its trim stick, the given
collective — by central differences, which are exact for its linear terms and for products of two
variables (``p|p|`` has zero slope at rest). It therefore picks up every term of the model: the decoupled
eqs. (18), (21), the flybar coupling, the Padé servo of eq. (31), gains scheduled on the collective. The
attitude of eq. (25) is linearised at level flight (Euler rates equal body rates).

Both the PD design (:mod:`controllers.pd.linearisation`, each axis' own block at collective 0) and the gain
sweep's closed loop (:func:`controllers.closed_loop.hover_plant`, all three axes at the library's mean
collective, sampled at the control period) read their matrices from here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .params import ModelParams
from .physics import kernel, trim_sticks
from .servo import servo_coefficients
from .terms import AXES, STICK_ROW

STEP = 1e-6
"""Central-difference step [state and stick units]."""
ZERO = 1e-9
"""Entries below this are rounding noise of the differences and set to 0."""


@dataclass(frozen=True, eq=False)
class HoverLinearisation:
    """``x' = A x + Bu u + Bd d`` about hover.

    Attributes
    ----------
    A : ndarray, shape (n, n)
    Bu : ndarray, shape (n, 3)
        Per unit stick offset of lat, lon, ped [stick].
    Bd : ndarray, shape (n, 3)
        Per unit gust torque per inertia on roll, pitch, yaw [rad/s²].
    states : tuple of str
        ``p, q, r``, a servo state per delayed axis (``servo_roll`` ...), ``roll, pitch, yaw``.
    rate_idx, angle_idx : ndarray of int, shape (3,)
        Where the rates and the angles sit in the state.
    servo_idx : dict of int to int
        Axis → index of its servo state, for the delayed axes.
    collective : float
        Collective stick of the hover point.
    """

    A: np.ndarray
    Bu: np.ndarray
    Bd: np.ndarray
    states: tuple
    rate_idx: np.ndarray
    angle_idx: np.ndarray
    servo_idx: dict
    collective: float

    def axis_block(self, axis: int) -> tuple[np.ndarray, np.ndarray, list]:
        """One axis' own block: ``(A, B, states)`` over (rate, [servo], angle) with ``B = [Bu_axis, Bd_axis]``
        (coupling to the other axes left out: per-axis design on the decoupled part)."""
        idx = [int(self.rate_idx[axis])] + ([self.servo_idx[axis]] if axis in self.servo_idx else []) + \
              [int(self.angle_idx[axis])]
        A = self.A[np.ix_(idx, idx)]
        B = np.column_stack([self.Bu[idx, axis], self.Bd[idx, axis]])
        return A, B, [self.states[i] for i in idx]


def hover_linearisation(params: ModelParams, collective: float = 0.0) -> HoverLinearisation:
    """Linearise the physics core about hover at the trim for ``collective`` (module docstring)."""
    rhs = kernel(params)[0]["rhs"]
    trim = [float(v) for v in trim_sticks(params, float(collective))]
    delayed = [i for i, (tau, lag) in enumerate(zip(params.taus, params.lags)) if servo_coefficients(tau, lag)[0] != 0.0]
    x0 = [0.0, 0.0, 0.0, trim[0], trim[1], trim[2], 1.0, 0.0, 0.0, 0.0]
    u0 = [trim[0], trim[1], float(collective), trim[2]]
    d0 = [0.0, 0.0, 0.0]
    rows = [0, 1, 2] + [3 + i for i in delayed]  # core state indices kept (rates, delayed servos)

    def jac(kind, index):
        out = []
        for s in (STEP, -STEP):
            x, u, d = list(x0), list(u0), list(d0)
            {"x": x, "u": u, "d": d}[kind][index] += s
            out.append(np.array(rhs(tuple(x), tuple(u), tuple(d)), dtype=float))
        return ((out[0] - out[1]) / (2 * STEP))[rows]

    m = len(rows)
    n = m + 3
    A, Bu, Bd = np.zeros((n, n)), np.zeros((n, 3)), np.zeros((n, 3))
    for j, v in enumerate(rows):
        A[:m, j] = jac("x", v)
    for i in range(3):
        Bu[:m, i] = jac("u", STICK_ROW[i])
        Bd[:m, i] = jac("d", i)
        A[m + i, i] = 1.0  # level-flight attitude kinematics, eq. (25)
    for M in (A, Bu, Bd):
        M[np.abs(M) < ZERO] = 0.0
    states = ("p", "q", "r") + tuple(f"servo_{AXES[i]}" for i in delayed) + ("roll", "pitch", "yaw")
    return HoverLinearisation(A, Bu, Bd, states, np.arange(3), np.arange(m, m + 3),
                              {a: 3 + k for k, a in enumerate(delayed)}, float(collective))
