"""Model parameters and the one physics core of the package.

The attitude model is the paper's minimal model (eqs. 18 and 21) plus any terms
added from :mod:`identification.terms`, the servo delay as a first-order Padé
approximation (eq. 31) and the quaternion kinematics (eqs. 25-26). Everything
that moves a model forward in time — the forward simulator used for
validation, the synthetic flight generator, the Gymnasium environments and the
PD linearisation — calls :func:`derivatives`, :func:`step` (RK4, continuous
inputs) or :func:`discrete_step` (one control period under a zero-order hold,
the environments' integrator) from here. All three are generated from the one
table of terms, :data:`identification.terms.FEATURE_EXPRESSIONS`.

State vector ``x`` (shape ``(N_STATE, ...)``, trailing axes are batch)::

    0..2  p, q, r        body rates                         [rad/s]
    3..5  z_roll ... yaw servo (Padé) states, eq. (31)      [stick units]
    6..9  q0, q1, q2, q3 attitude quaternion, eqs. (25)-(26) [-]

Input vector ``u`` (shape ``(4, ...)``): ``lat, lon, col, ped`` sticks in [-1, 1].
Disturbance ``d`` (shape ``(3, ...)``): wind torque per inertia on roll, pitch,
yaw [rad/s^2], i.e. the ``k2*u_d`` part of eq. (42) (the constant offsets
``kd`` are model parameters).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .terms import BASE_PARAMS, EXTRA_PARAMS, FEATURE_EXPRESSIONS, TERMS

N_STATE = 10
RATES = slice(0, 3)
SERVO = slice(3, 6)
QUAT = slice(6, 10)
INPUT_NAMES = ("lat", "lon", "col", "ped")
_CMD_INPUT = (0, 1, 3)  # indices in u of the stick driving roll, pitch, yaw


@dataclass(frozen=True)
class ModelParams:
    """Parameters of the coupled attitude model, eqs. (18) and (21).

    All fields default to 0, so a decoupled model simply leaves the coupling
    terms at zero. Names and signs follow the paper.

    Attributes
    ----------
    k1, k5, k9 : float
        Gyroscopic inertia ratios [-] (eqs. 19, 22, 23).
    k2, k6, k10 : float
        Control effectiveness of lateral cyclic, longitudinal cyclic and pedal
        [rad/s^2 per unit stick].
    k3, k7, k11 : float
        Damping of roll, pitch and yaw [1/s].
    k4, k8 : float
        Flybar cross-coupling (``+k4*q`` in roll, ``-k8*p`` in pitch) [1/s].
    k12 : float
        Main-rotor reaction torque per unit collective, entering as ``-k12*col``
        [rad/s^2].
    kd1, kd2, kd3 : float
        Constant torque offsets [rad/s^2].
    tau_roll, tau_pitch, tau_yaw : float
        Servo transport delay per axis [s], modelled by the first-order Padé
        approximation of eq. (31); 0 means no delay.
    extra : tuple of (str, float)
        Added catalogue terms (:data:`identification.terms.EXTRA_PARAMS`) and
        their values, e.g. ``(("nld1", 0.2),)``.
    """

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    kd1: float = 0.0
    k5: float = 0.0
    k6: float = 0.0
    k7: float = 0.0
    k8: float = 0.0
    kd2: float = 0.0
    k9: float = 0.0
    k10: float = 0.0
    k11: float = 0.0
    k12: float = 0.0
    kd3: float = 0.0
    tau_roll: float = 0.0
    tau_pitch: float = 0.0
    tau_yaw: float = 0.0
    extra: tuple = field(default=())

    def __post_init__(self):
        for name in BASE_PARAMS + ("tau_roll", "tau_pitch", "tau_yaw"):
            v = getattr(self, name)
            if (isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.floating, np.integer))
                    or not math.isfinite(float(v))):
                raise ValueError(f"parameter {name} must be a finite number, got {v!r}")
            object.__setattr__(self, name, float(v))
        for name in ("tau_roll", "tau_pitch", "tau_yaw"):
            if not 0.0 <= getattr(self, name) <= 2.0:
                raise ValueError(f"{name} must be a delay in [0, 2] s, got {getattr(self, name)}")
        extra = tuple((str(k), float(v)) for k, v in dict(self.extra).items())
        if len(extra) != len(self.extra):
            raise ValueError(f"extra terms must have unique names, got {[k for k, _ in self.extra]}")
        for k, v in extra:
            if k not in EXTRA_PARAMS:
                raise ValueError(f"unknown extra term {k!r}; known: {', '.join(EXTRA_PARAMS)}")
            if not math.isfinite(v):
                raise ValueError(f"extra term {k} must be finite, got {v}")
        object.__setattr__(self, "extra", tuple(sorted(extra)))

    # ------------------------------------------------------------------ access
    @property
    def taus(self) -> tuple[float, float, float]:
        """Servo delays (roll, pitch, yaw) [s]."""
        return (self.tau_roll, self.tau_pitch, self.tau_yaw)

    @property
    def control_gains(self) -> np.ndarray:
        """(k2, k6, k10): torque per unit stick on each axis [rad/s^2]."""
        return np.array([self.k2, self.k6, self.k10])

    def values(self) -> dict[str, float]:
        """All term parameters (base and extra) by name."""
        out = {name: getattr(self, name) for name in BASE_PARAMS}
        out.update(dict(self.extra))
        return out

    def get(self, name: str) -> float:
        """Value of a base or extra parameter; 0 for an extra term not in the model."""
        if name in BASE_PARAMS or name.startswith("tau_"):
            return getattr(self, name)
        if name not in TERMS:
            raise KeyError(f"unknown parameter {name!r}")
        return dict(self.extra).get(name, 0.0)

    def with_values(self, **values) -> "ModelParams":
        """A copy with some parameters replaced; extra-term names add or replace terms."""
        base = {k: v for k, v in values.items() if k in BASE_PARAMS or k.startswith("tau_")}
        extra = dict(self.extra)
        for k, v in values.items():
            if k not in base:
                if k not in EXTRA_PARAMS:
                    raise KeyError(f"unknown parameter {k!r}")
                extra[k] = v
        return dataclasses.replace(self, **base, extra=tuple(extra.items()))


# ---------------------------------------------------------------------- servo
@lru_cache(maxsize=256)
def servo_coefficients(tau: float) -> tuple[float, float, float]:
    """Coefficients ``(d1, n1, n2)`` of the servo-delay model, eq. (31).

    ``theta + d1*theta' = n1*delta - n2*delta'`` is the first-order Padé
    approximation of ``exp(-s*tau)``, computed with ``control.pade``.
    """
    if tau <= 0.0:
        return (0.0, 1.0, 0.0)
    import control

    num, den = control.pade(tau, 1)  # (-s + 2/tau) / (s + 2/tau)
    return (den[0] / den[1], num[1] / den[1], -num[0] / den[1])


def _fmt(v: float) -> str:
    return repr(float(v))


@lru_cache(maxsize=256)
def _kernel(params: ModelParams):
    """Compile the model into straight-line Python: the right-hand side and an RK4 step.

    The source is generated from :data:`identification.terms.FEATURE_EXPRESSIONS`
    and the parameter values (the model's only definition), with zero terms
    left out and constants inlined. It uses arithmetic and ``abs`` only, so the
    same functions step one trajectory in Python floats (a few microseconds per
    step) and a batch of environments in numpy rows. :func:`model_source` shows it.

    Returns
    -------
    namespace : dict
        ``rhs(x, u, d)`` and ``rk4(x, u, d, h)`` over sequences of components.
    source : str
    """
    acc = [[], [], []]
    for name, value in params.values().items():
        if value != 0.0:
            term = TERMS[name]
            acc[term.axis].append(f"{_fmt(term.sign * value)}*({FEATURE_EXPRESSIONS[term.feature]})")
    lines = [
        "def rhs(x, u, d):",
        '    """Eqs. (18), (21) with the servo of eq. (31) and the quaternion kinematics of eq. (25)."""',
        "    p, q, r, z0, z1, z2, q0, q1, q2, q3 = x",
        "    lat, lon, col, ped = u",
    ]
    dz = []
    for i, (stick, tau) in enumerate(zip(("lat", "lon", "ped"), params.taus)):
        d1, n1, n2 = servo_coefficients(tau)
        if d1 == 0.0:
            lines.append(f"    c{i} = {stick}")
            dz.append(f"0.0*z{i}")
        else:  # (n1 - n2 s)/(1 + d1 s) = -n2/d1 + (n1 + n2/d1)/(1 + d1 s)
            lines.append(f"    c{i} = {_fmt(-n2 / d1)}*{stick} + {_fmt(n1 + n2 / d1)}*z{i}")
            dz.append(f"{_fmt(1.0 / d1)}*({stick} - z{i})")
    for i, rate in enumerate("pqr"):
        lines.append(f"    a{i} = d[{i}] + 0.0*{rate}" + "".join(f" + {t}" for t in acc[i]))
    lines += [
        "    # eq. (25); the paper's q3' row has a typo (q3*p for q2*p)",
        f"    return (a0, a1, a2, {dz[0]}, {dz[1]}, {dz[2]},",
        "            -0.5*(q1*p + q2*q + q3*r), 0.5*(q0*p + q2*r - q3*q),",
        "            0.5*(q0*q + q3*p - q1*r), 0.5*(q0*r + q1*q - q2*p))",
    ]
    xs = [f"x{i}" for i in range(N_STATE)]
    body = [
        "",
        "",
        "def rk4(x, u, d, h):",
        '    """One classical Runge-Kutta step of length h with u and d held; quaternion renormalised (eq. 26)."""',
        "    " + ", ".join(xs) + " = x",
        "    hh = 0.5*h",
        "    h6 = h/6.0",
        "    k1 = rhs(x, u, d)",
        "    k2 = rhs((" + ", ".join(f"{x} + hh*k1[{i}]" for i, x in enumerate(xs)) + "), u, d)",
        "    k3 = rhs((" + ", ".join(f"{x} + hh*k2[{i}]" for i, x in enumerate(xs)) + "), u, d)",
        "    k4 = rhs((" + ", ".join(f"{x} + h*k3[{i}]" for i, x in enumerate(xs)) + "), u, d)",
    ]
    for i, x in enumerate(xs):
        body.append(f"    {x} = {x} + h6*(k1[{i}] + 2.0*k2[{i}] + 2.0*k3[{i}] + k4[{i}])")
    body += [
        "    n = (x6*x6 + x7*x7 + x8*x8 + x9*x9)**0.5",
        "    return (x0, x1, x2, x3, x4, x5, x6/n, x7/n, x8/n, x9/n)",
    ]
    source = "\n".join(lines + body) + "\n"
    namespace = {"abs": abs}
    exec(compile(source, f"<heli-env model {hash(params) & 0xFFFFFFFF:08x}>", "exec"), namespace)  # noqa: S102
    return namespace, source


def model_source(params: ModelParams) -> str:
    """The Python source the physics core runs for ``params`` (for reading and debugging)."""
    return _kernel(params)[1]


_ZERO_D = (0.0, 0.0, 0.0)


def derivatives(x, u, d, params: ModelParams) -> np.ndarray:
    """Time derivative of the state: eqs. (18), (21), (31) and (25).

    Parameters
    ----------
    x : ndarray, shape (N_STATE, ...)
        State (see module docstring).
    u : ndarray, shape (4, ...)
        Sticks lat, lon, col, ped in [-1, 1].
    d : ndarray, shape (3, ...) or None
        Wind torque per inertia on roll, pitch, yaw [rad/s^2].
    params : ModelParams

    Returns
    -------
    ndarray, shape (N_STATE, ...)
    """
    x = np.asarray(x, dtype=float)
    u = np.asarray(u, dtype=float)
    out = _kernel(params)[0]["rhs"](x, u, _ZERO_D if d is None else np.asarray(d, dtype=float))
    shape = np.broadcast_shapes(x.shape[1:], u.shape[1:])
    return np.array([np.broadcast_to(v, shape) for v in out])


def step(x, u, d, params: ModelParams, dt: float, substeps: int = 1):
    """Advance the state by ``dt`` with inputs and disturbance held (zero-order hold).

    Classical fourth-order Runge-Kutta with ``substeps`` equal sub-steps; the
    quaternion is renormalised after each (eq. 26). A state that blows up
    becomes non-finite rather than raising.

    Parameters
    ----------
    x : ndarray, shape (N_STATE, ...), or a sequence of N_STATE floats
        State. A sequence of floats takes the fast scalar path and a tuple is returned.
    u : ndarray, shape (4, ...), or sequence of 4 floats
        Sticks lat, lon, col, ped.
    d : ndarray, shape (3, ...), sequence of 3 floats, or None
        Wind torque per inertia [rad/s^2].
    params : ModelParams
    dt : float
        Step [s].
    substeps : int
        RK4 sub-steps.
    """
    rk4 = _kernel(params)[0]["rk4"]
    d = _ZERO_D if d is None else d
    h = dt / substeps
    if isinstance(x, np.ndarray):
        xs = tuple(x)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            for _ in range(substeps):
                xs = rk4(xs, u, d, h)
        return np.array(xs)
    xs = tuple(x)
    try:
        for _ in range(substeps):
            xs = rk4(xs, u, d, h)
    except (ZeroDivisionError, OverflowError):
        return (float("nan"),) * N_STATE
    return xs


def initial_state(rates=(0.0, 0.0, 0.0), euler=(0.0, 0.0, 0.0), sticks=(0.0, 0.0, 0.0), batch=()):
    """A state at the given rates [rad/s], Euler angles [rad] and settled servo states.

    ``sticks`` are the (lat, lon, ped) commands the servo states are settled on.
    ``batch`` is the trailing batch shape.
    """
    x = np.zeros((N_STATE,) + tuple(batch))
    x[RATES] = np.reshape(rates, (3,) + (1,) * len(batch))
    x[SERVO] = np.reshape(sticks, (3,) + (1,) * len(batch))
    x[QUAT] = np.reshape(quaternion_from_euler(*euler), (4,) + (1,) * len(batch))
    return x


# ------------------------------------------------------------- discrete time
_LINEAR_FEATURES = {"p": ("state", 0), "q": ("state", 1), "r": ("state", 2),
                    "u_lat": ("servo", 0), "u_lon": ("servo", 1), "u_ped": ("servo", 2),
                    "col": ("input", 2), "1": ("input", 4)}
_STICK_INPUT = (0, 1, 3)  # lat, lon, ped in the input vector (lat, lon, col, ped, 1, d0, d1, d2)


def linear_structure(params: ModelParams):
    """The model split into its linear part and its remaining products, eqs. (18), (21), (31).

    With the state ``s = (p, q, r, z0, z1, z2)`` and the held input vector
    ``v = (lat, lon, col, ped, 1, d0, d1, d2)``::

        s' = A s + B v + G n(s, v)

    where ``n`` holds the non-linear features (products of rates, ``p|p|``,
    commands times collective) per axis and ``G`` routes them to the rate rows.

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
    for i, tau in enumerate(params.taus):
        d1, n1, n2 = servo_coefficients(tau)
        if d1 == 0.0:
            servo.append((1.0, 0.0))
        else:  # (n1 - n2 s)/(1 + d1 s) = -n2/d1 + (n1 + n2/d1)/(1 + d1 s)
            servo.append((-n2 / d1, n1 + n2 / d1))
            A[3 + i, 3 + i] = -1.0 / d1
            B[3 + i, _STICK_INPUT[i]] = 1.0 / d1
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
            B[term.axis, _STICK_INPUT[kind[1]]] += c * feed
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

    The linear part is discretised exactly for a zero-order hold (matrix
    exponential of the augmented system, ``scipy.linalg.expm``); the remaining
    products of rates are held over the step and integrated through the same
    exponential (exponential Euler); the attitude turns by the rotation of the
    mean of the start and end rates (eq. 25) and is renormalised (eq. 26).
    The statements read :data:`DISCRETE_INPUTS` and assign
    :data:`DISCRETE_OUTPUTS`; they use
    arithmetic and ``abs`` only, so the one text is compiled into the
    float/numpy step of :func:`_discrete_kernel` and into the fused numba loop
    of the vector environment (:mod:`heli_env.kernels`), which therefore agree
    bit for bit.
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
def _discrete_kernel(params: ModelParams, dt: float):
    """Compile :func:`discrete_step_statements` into ``dstep(x, u, d)`` for floats and numpy batches.

    Returns the function and its source.
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
    the mean of the start and end rates. :func:`step` (RK4) is the reference
    it is checked against.

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
    return _discrete_kernel(params, float(dt))[0](x, u, _ZERO_D if d is None else d)


def trim_sticks(params: ModelParams, col):
    """Cyclic and pedal sticks (lat, lon, ped) that hold the aircraft at rest, for a collective.

    At rest (zero rates, servo settled) each rate derivative is
    ``F_i(col) + G_i(col) * stick_i`` (eqs. 18, 21: offsets kd, collective torque,
    and the control gain, possibly scheduled by the collective); the trim is
    ``-F_i / G_i``. Works on floats and arrays of collective.
    """
    rhs = _kernel(params)[0]["rhs"]
    zero = 0.0 * col
    rest = (zero, zero, zero, zero, zero, zero, 1.0 + zero, zero, zero, zero)
    f = rhs(rest, (zero, zero, col, zero), _ZERO_D)
    out = []
    for i, idx in enumerate((3, 4, 5)):
        x = list(rest)
        x[idx] = 1.0 + zero  # servo settled on a unit stick
        u = [zero, zero, col, zero]
        u[_STICK_INPUT[i] if _STICK_INPUT[i] != 3 else 3] = 1.0 + zero
        g = rhs(tuple(x), tuple(u), _ZERO_D)[i] - f[i]
        out.append(-f[i] / g)
    return tuple(out)


def quaternion_from_euler(phi, theta, psi) -> np.ndarray:
    """Unit quaternion (q0, q1, q2, q3) of ZYX Euler angles roll, pitch, yaw [rad]."""
    cr, sr = np.cos(np.multiply(phi, 0.5)), np.sin(np.multiply(phi, 0.5))
    cp, sp = np.cos(np.multiply(theta, 0.5)), np.sin(np.multiply(theta, 0.5))
    cy, sy = np.cos(np.multiply(psi, 0.5)), np.sin(np.multiply(psi, 0.5))
    return np.array([
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ])


def euler_from_quaternion(quat) -> np.ndarray:
    """ZYX Euler angles (phi, theta, psi) [rad] of a quaternion, shape (4, ...) -> (3, ...).

    Equivalent to eqs. (27)-(29) with atan2 in place of the paper's arcsin/arccos,
    so that the yaw angle keeps its sign and the full range (-pi, pi].
    """
    q0, q1, q2, q3 = quat
    phi = np.arctan2(2.0 * (q0 * q1 + q2 * q3), 1.0 - 2.0 * (q1 * q1 + q2 * q2))
    theta = np.arcsin(np.clip(2.0 * (q0 * q2 - q3 * q1), -1.0, 1.0))
    psi = np.arctan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))
    return np.array([phi, theta, psi])


def simulate(params: ModelParams, time, sticks, disturbance=None, x0=None, substeps: int = 1):
    """Forward-simulate the model with measured inputs (zero-order hold between samples).

    Parameters
    ----------
    params : ModelParams
    time : ndarray, shape (n,)
        Sample times [s], uniformly spaced.
    sticks : ndarray, shape (4, n)
        lat, lon, col, ped in [-1, 1].
    disturbance : ndarray, shape (3, n), optional
        Wind torque per inertia [rad/s^2] held over each sample interval.
    x0 : ndarray, shape (N_STATE,), optional
        Initial state; default rest, level, servo settled on the first sticks.
    substeps : int
        RK4 sub-steps per sample interval.

    Returns
    -------
    ndarray, shape (N_STATE, n)
        State at every sample time.
    """
    time = np.asarray(time, dtype=float)
    sticks = np.asarray(sticks, dtype=float)
    n = time.size
    dt = float(np.median(np.diff(time))) if n > 1 else 0.0
    if x0 is None:
        x0 = initial_state(sticks=sticks[list(_CMD_INPUT), 0])
    x = tuple(float(v) for v in x0)
    u_rows = sticks.T.tolist()
    d_rows = None if disturbance is None else np.asarray(disturbance, dtype=float).T.tolist()
    rk4 = _kernel(params)[0]["rk4"]
    h = dt / substeps
    out = np.empty((n, N_STATE))
    out[0] = x
    zero = _ZERO_D
    for k in range(n - 1):
        d = zero if d_rows is None else d_rows[k]
        u = u_rows[k]
        try:
            for _ in range(substeps):
                x = rk4(x, u, d, h)
        except (ZeroDivisionError, OverflowError):
            out[k + 1:] = np.nan
            break
        out[k + 1] = x
    return out.T


def forward_rates(params: ModelParams, flight) -> np.ndarray:
    """Body rates (3, n) [rad/s] of ``params`` driven by a flight's sticks from its first measured state.

    What an identifier's ``predict`` returns: the model simulated (RK4, no wind) from the flight's first
    rates, attitude and sticks.
    """
    x0 = initial_state(rates=flight.rates[:, 0], euler=flight.attitude[:, 0], sticks=flight.sticks[list(_CMD_INPUT), 0])
    return simulate(params, flight.time, flight.sticks, x0=x0)[:3]
