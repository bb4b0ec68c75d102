"""One control period of the model under a zero-order hold: the environments' integrator.

A digital controller holds its sticks over a control period ``dt``. Over that
period the linear part of eqs. (18), (21) and the servo of eq. (31) is solved
exactly (the matrix exponential of :func:`linear_structure`), the products of
rates (gyroscopic terms, ``p|p|``) are held and integrated through the same
exponential, and the quaternion of eq. (25) turns by the mean of the start and
end rates, renormalised as eq. (26) asks. :func:`discrete_step_statements`
writes this as straight-line statements; :func:`discrete_kernel` compiles them
for Python floats and numpy batches, and :mod:`heli_env.kernels` compiles the
same text into the vector environment's numba loop, so the two agree bit for bit.
The RK4 step of :mod:`heli_core.physics` is the reference it is checked against.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .params import ModelParams
from .physics import ZERO_DISTURBANCE, _fmt
from .servo import servo_coefficients
from .terms import FEATURE_EXPRESSIONS, STICK_ROW, TERMS

_LINEAR_FEATURES = {"p": ("state", 0), "q": ("state", 1), "r": ("state", 2),
                    "u_lat": ("servo", 0), "u_lon": ("servo", 1), "u_ped": ("servo", 2),
                    "col": ("input", 2), "1": ("input", 4)}
"""Features that are linear in the state ``s`` or the held input ``v`` of :func:`linear_structure`."""


def linear_structure(params: ModelParams):
    """The model split into its linear part and its remaining products, eqs. (18), (21), (31).

    With the state ``s = (p, q, r, z0, z1, z2)`` and the held input vector
    ``v = (lat, lon, col, ped, 1, d0, d1, d2)``::

        s' = A s + B v + G n(s, v)

    where ``n`` holds the non-linear features (products of rates, ``p|p|``,
    commands times collective) per axis and ``G`` routes them to the rate rows.
    The sticks of the axes sit at columns :data:`heli_core.terms.STICK_ROW` of ``v``.

    Parameters
    ----------
    params : ModelParams

    Returns
    -------
    A : ndarray (6, 6)
    B : ndarray (6, 8)
    nonlinear : tuple of (axis, expression, coefficient)
    servo : tuple of 3 (feedthrough, state gain)
        Per axis, the servo output is ``feedthrough*stick + state_gain*z`` (eq. 31);
        ``(1, 0)`` where there is no delay.
    """
    A = np.zeros((6, 6))
    B = np.zeros((6, 8))
    servo = []
    for i, (tau, lag) in enumerate(zip(params.taus, params.lags)):
        d1, n1, n2 = servo_coefficients(tau, lag)
        if d1 == 0.0:
            servo.append((1.0, 0.0))
        else:  # (n1 - n2 s)/(1 + d1 s) = -n2/d1 + (n1 + n2/d1)/(1 + d1 s)
            servo.append((-n2 / d1, n1 + n2 / d1))
            A[3 + i, 3 + i] = -1.0 / d1
            B[3 + i, STICK_ROW[i]] = 1.0 / d1
    nonlinear = []
    for name, value in params.values().items():
        if value == 0.0:
            continue
        term = TERMS[name]
        c = term.sign * value
        kind = _LINEAR_FEATURES.get(term.feature)
        if kind is None:
            nonlinear.append((term.axis, FEATURE_EXPRESSIONS[term.feature], c))
        elif kind[0] == "state":
            A[term.axis, kind[1]] += c
        elif kind[0] == "servo":
            feed, gain = servo[kind[1]]
            B[term.axis, STICK_ROW[kind[1]]] += c * feed
            A[term.axis, 3 + kind[1]] += c * gain
        else:
            B[term.axis, kind[1]] += c
    for i in range(3):
        B[i, 5 + i] = 1.0  # the disturbance torque
    return A, B, tuple(nonlinear), tuple(servo)


DISCRETE_INPUTS = ("p", "q", "r", "z0", "z1", "z2", "q0", "q1", "q2", "q3",  # state
                   "lat", "lon", "col", "ped",  # sticks
                   "d0", "d1", "d2")  # disturbance torque
"""Names the statements of :func:`discrete_step_statements` read: state, sticks, disturbance torque."""

DISCRETE_OUTPUTS = ("pn", "qn", "rn", "z0n", "z1n", "z2n", "b0", "b1", "b2", "b3")
"""Names of the new state they assign: rates, servo states and the unit quaternion."""


@lru_cache(maxsize=64)
def discrete_step_statements(params: ModelParams, dt: float) -> tuple[str, ...]:
    """One control period of length ``dt`` with u and d held, as straight-line statements.

    The linear part (eqs. 18, 21, 31) is discretised exactly for a zero-order
    hold (matrix exponential of the augmented system, ``scipy.linalg.expm``);
    the remaining products of rates are held over the step and integrated
    through the same exponential (exponential Euler); the attitude turns by the
    rotation of the mean of the start and end rates (eq. 25) and is
    renormalised (eq. 26). The statements read :data:`DISCRETE_INPUTS` and
    assign :data:`DISCRETE_OUTPUTS`; they use arithmetic and ``abs`` only, so
    the one text is compiled into the float/numpy step of
    :func:`discrete_kernel` and into the fused numba loop of the vector
    environment (:mod:`heli_env.kernels`), which therefore agree bit for bit.

    Parameters
    ----------
    params : ModelParams
    dt : float
        Control period [s].

    Returns
    -------
    tuple of str
        Python statements, one assignment each.
    """
    from scipy.linalg import expm

    A, B, nonlinear, servo = linear_structure(params)
    M = np.zeros((14, 14))
    M[:6, :6] = A
    M[:6, 6:] = B
    E = expm(M * dt)
    Ad, Bd = E[:6, :6], E[:6, 6:]
    names_s = ("p", "q", "r", "z0", "z1", "z2")
    names_v = ("lat", "lon", "col", "ped", "1.0", "e0", "e1", "e2")
    lines = []
    for i, (feed, gain) in enumerate(servo):
        stick = ("lat", "lon", "ped")[i]
        lines.append(f"c{i} = {stick}" if gain == 0.0 else f"c{i} = {_fmt(feed)}*{stick} + {_fmt(gain)}*z{i}")
    for i in range(3):
        extra = "".join(f" + {_fmt(c)}*({expr})" for axis, expr, c in nonlinear if axis == i)
        lines.append(f"e{i} = d{i}{extra}")
    for row in range(6):
        if row >= 3 and servo[row - 3][1] == 0.0:
            lines.append(f"{names_s[row]}n = {names_s[row]}")  # no servo delay: the state is unused
            continue
        terms = [f"{_fmt(Ad[row, j])}*{names_s[j]}" for j in range(6) if Ad[row, j] != 0.0]
        terms += [f"{_fmt(Bd[row, j])}*{names_v[j]}" if names_v[j] != "1.0" else _fmt(Bd[row, j])
                  for j in range(8) if Bd[row, j] != 0.0]
        lines.append(f"{names_s[row]}n = " + (" + ".join(terms) if terms else f"0.0*{names_s[row]}"))
    hdt = 0.25 * dt  # half the step times the mean of two rates
    lines += [
        f"wx = {_fmt(hdt)}*(p + pn)",
        f"wy = {_fmt(hdt)}*(q + qn)",
        f"wz = {_fmt(hdt)}*(r + rn)",
        "a0 = q0 - q1*wx - q2*wy - q3*wz",
        "a1 = q1 + q0*wx + q2*wz - q3*wy",
        "a2 = q2 + q0*wy + q3*wx - q1*wz",
        "a3 = q3 + q0*wz + q1*wy - q2*wx",
        "n = (a0*a0 + a1*a1 + a2*a2 + a3*a3)**0.5",
        "b0 = a0/n",
        "b1 = a1/n",
        "b2 = a2/n",
        "b3 = a3/n",
    ]
    return tuple(lines)


@lru_cache(maxsize=64)
def discrete_kernel(params: ModelParams, dt: float):
    """Compile :func:`discrete_step_statements` into ``dstep(x, u, d)`` for floats and numpy batches.

    Cached per parameter set and period.

    Parameters
    ----------
    params : ModelParams
    dt : float
        Control period [s].

    Returns
    -------
    dstep : callable
        ``dstep(x, u, d)`` over sequences of the components of ``x`` (N_STATE),
        ``u`` (4 sticks) and ``d`` (3 torques [rad/s^2]); returns the N_STATE
        components of the state one period later.
    source : str
        Its Python source.
    """
    lines = [
        "def dstep(x, u, d):",
        '    """One control period, zero-order hold: exact linear part, exponential Euler for products."""',
        f"    {', '.join(DISCRETE_INPUTS[:10])} = x",
        f"    {', '.join(DISCRETE_INPUTS[10:14])} = u",
        f"    {', '.join(DISCRETE_INPUTS[14:])} = d",
        *("    " + line for line in discrete_step_statements(params, dt)),
        f"    return ({', '.join(DISCRETE_OUTPUTS)})",
    ]
    source = "\n".join(lines) + "\n"
    namespace = {"abs": abs}
    exec(compile(source, f"<heli-env discrete model {hash((params, dt)) & 0xFFFFFFFF:08x}>", "exec"), namespace)  # noqa: S102
    return namespace["dstep"], source


def discrete_step(x, u, d, params: ModelParams, dt: float):
    """Advance one control period ``dt`` with the sticks and the disturbance held (digital control).

    The integrator of the environments: the linear part of eqs. (18), (21), (31)
    is exact under a zero-order hold, products of rates (gyroscopic terms,
    ``p|p|``) are held over the step, and the quaternion of eq. (25) turns by
    the mean of the start and end rates. :func:`heli_core.physics.step` (RK4) is
    the reference it is checked against.

    Parameters
    ----------
    x : ndarray (N_STATE, ...) or sequence of N_STATE floats
    u : ndarray (4, ...) or sequence of 4 floats
        lat, lon, col, ped.
    d : ndarray (3, ...), sequence of 3 floats, or None
        Wind torque per inertia [rad/s^2].
    params : ModelParams
    dt : float
        Control period [s].

    Returns
    -------
    tuple of N_STATE components (floats or arrays)
    """
    return discrete_kernel(params, float(dt))[0](x, u, ZERO_DISTURBANCE if d is None else d)
