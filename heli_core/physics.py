"""The one physics core: the attitude model as straight-line code, stepped by RK4.

The attitude model is the paper's minimal model (eqs. 18 and 21) plus any terms
added from :mod:`heli_core.terms`, the servo delay as a first-order Padé
approximation (eq. 31) and the quaternion kinematics (eqs. 25-26). Everything
that moves a model forward in time — the forward simulator used for
validation, the synthetic flight generator, the Gymnasium environments and the
PD linearisation — calls :func:`derivatives`, :func:`step` (RK4, continuous
inputs) or :func:`heli_core.discrete.discrete_step` (one control period under a
zero-order hold, the environments' integrator). All of them are generated from
the one table of terms, :data:`heli_core.terms.FEATURE_EXPRESSIONS`, by
:func:`kernel` and :func:`heli_core.discrete.discrete_kernel`.

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

import math

import warnings

from functools import lru_cache

import numpy as np

from .params import ModelParams
from .quaternion import quaternion_from_euler
from .servo import servo_coefficients
from .terms import FEATURE_EXPRESSIONS, STICK_ROW, STICKS, TERMS

N_STATE = 10
"""Length of the state vector (module docstring)."""
RATES = slice(0, 3)
"""Body rates p, q, r in the state [rad/s]."""
SERVO = slice(3, 6)
"""Servo (Padé) states of roll, pitch, yaw in the state, eq. (31) [stick units]."""
QUAT = slice(6, 10)
"""Attitude quaternion q0..q3 in the state, eqs. (25)-(26)."""
INPUT_NAMES = STICKS
"""The input vector ``u``: the sticks lat, lon, col, ped."""

ZERO_DISTURBANCE = (0.0, 0.0, 0.0)
"""No wind torque: the ``d`` every function here uses when given None."""


_NORM_SQUARED = "x6*x6 + x7*x7 + x8*x8 + x9*x9"
"""The quaternion's squared norm in :func:`kernel`'s ``rk4`` (eq. 26)."""


def _fmt(v: float) -> str:
    """A float as a Python expression that reads back to the same float (``float('nan')`` for a coefficient
    that overflowed: a model with a damping of 1e300/s discretised over a control period)."""
    v = float(v)
    return repr(v) if math.isfinite(v) else f"float('{v!r}')"


@lru_cache(maxsize=256)
def kernel(params: ModelParams):
    """Compile the model into straight-line Python: the right-hand side and an RK4 step.

    The source is generated from :data:`heli_core.terms.FEATURE_EXPRESSIONS` and
    the parameter values (the model's only definition), with zero terms left out
    and constants inlined: eqs. (18) and (21), the servo of eq. (31) and the
    quaternion kinematics of eqs. (25)-(26). It uses arithmetic and ``abs``
    only, so the same functions step one trajectory in Python floats (a few
    microseconds per step) and a batch of environments in numpy rows.
    :func:`model_source` shows it. Cached per parameter set.

    Parameters
    ----------
    params : ModelParams

    Returns
    -------
    namespace : dict
        ``rhs(x, u, d)`` (the state derivative) and ``rk4(x, u, d, h)`` (one step
        of length ``h`` [s]), over sequences of the components of ``x`` (N_STATE),
        ``u`` (4) and ``d`` (3); each returns a tuple of N_STATE components.
    source : str
        Their Python source.
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
    for i, (stick, tau, lag) in enumerate(zip(("lat", "lon", "ped"), params.taus, params.lags)):
        d1, n1, n2 = servo_coefficients(tau, lag)
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
        f"    n = ({_NORM_SQUARED})**0.5",
        "    return (x0, x1, x2, x3, x4, x5, x6/n, x7/n, x8/n, x9/n)",
    ]
    source = "\n".join(lines + body) + "\n"
    namespace = {"abs": abs}
    exec(compile(source, f"<heli-env model {hash(params) & 0xFFFFFFFF:08x}>", "exec"), namespace)  # noqa: S102
    return namespace, source


COMPILED_STEPS = 24_000
"""Steps of :func:`kernel`'s ``rk4`` from which :func:`compiled_rk4` pays (a minute of flight at 100 Hz and four
sub-steps): numba takes about half a second to compile a parameter set's step, which then runs in about 0.8 µs
a call where the Python one takes 15."""


@lru_cache(maxsize=1)  # find_library may ask ldconfig: once a process
def _libm_pow():
    """The C library's ``pow``, which Python's ``x**y`` calls, as a ctypes function numba can call (None where
    it cannot be found). numba compiles ``x**0.5`` to a square root, and glibc's ``pow(x, 0.5)`` differs from
    the correctly rounded root by an ulp on about one input in a thousand."""
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("m")
    if name is None:
        return None
    c_pow = ctypes.CDLL(name).pow
    c_pow.restype, c_pow.argtypes = ctypes.c_double, (ctypes.c_double, ctypes.c_double)
    return c_pow


@lru_cache(maxsize=32)
def compiled_rk4(params: ModelParams):
    """:func:`kernel`'s ``rk4`` for ``params`` compiled by numba, or None where the C library's ``pow`` is not
    found. The same source, so the same IEEE arithmetic in the same order (numba without fast-math neither
    reorders nor contracts multiply-adds), its one power the C library's, as Python's: the same state bit for
    bit. It takes and returns tuples of floats (``x`` N_STATE, ``u`` 4, ``d`` 3). Cached per parameter set."""
    import numba

    c_pow = _libm_pow()
    if c_pow is None:
        return None
    source = kernel(params)[1]
    power = f"({_NORM_SQUARED})**0.5"
    assert source.count(power) == 1, "kernel()'s normalisation changed: change compiled_rk4's with it"
    namespace = {"abs": abs, "c_pow": c_pow}
    exec(compile(source.replace(power, f"c_pow({_NORM_SQUARED}, 0.5)"),  # noqa: S102
                 f"<heli-env compiled model {hash(params) & 0xFFFFFFFF:08x}>", "exec"), namespace)
    namespace["rhs"] = numba.njit(namespace["rhs"])  # rk4 calls it from its globals, this namespace
    return numba.njit(namespace["rk4"])


def model_source(params: ModelParams) -> str:
    """The Python source the physics core runs for ``params`` (for reading and debugging).

    Parameters
    ----------
    params : ModelParams

    Returns
    -------
    str
        The ``rhs`` and ``rk4`` functions of :func:`kernel`: eqs. (18), (21), (25)-(26), (31).
    """
    return kernel(params)[1]


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
    out = kernel(params)[0]["rhs"](x, u, ZERO_DISTURBANCE if d is None else np.asarray(d, dtype=float))
    shape = np.broadcast_shapes(x.shape[1:], u.shape[1:])
    return np.array([np.broadcast_to(v, shape) for v in out])


def step(x, u, d, params: ModelParams, dt: float, substeps: int = 1):
    """Advance the state by ``dt`` with inputs and disturbance held (zero-order hold).

    Classical fourth-order Runge-Kutta over eqs. (18), (21), (31), (25) with
    ``substeps`` equal sub-steps; the quaternion is renormalised after each
    (eq. 26). A state that blows up becomes non-finite rather than raising.

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

    Returns
    -------
    ndarray, shape (N_STATE, ...), or tuple of N_STATE floats
        The state after ``dt``.
    """
    rk4 = kernel(params)[0]["rk4"]
    d = ZERO_DISTURBANCE if d is None else d
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
    """A state at the given rates, Euler angles and settled servo states.

    Parameters
    ----------
    rates : sequence of 3 float or ndarray (3, *batch)
        Body rates p, q, r [rad/s].
    euler : sequence of 3 float or ndarray (3, *batch)
        Roll, pitch, yaw [rad] (converted to the quaternion of eqs. 25-26).
    sticks : sequence of 3 float or ndarray (3, *batch)
        The (lat, lon, ped) commands the servo states of eq. (31) are settled on [stick units].
    batch : tuple of int
        Trailing batch shape.

    Returns
    -------
    ndarray, shape (N_STATE, *batch)
    """
    x = np.zeros((N_STATE,) + tuple(batch))
    x[RATES] = np.reshape(rates, (3,) + (1,) * len(batch))
    x[SERVO] = np.reshape(sticks, (3,) + (1,) * len(batch))
    x[QUAT] = np.reshape(quaternion_from_euler(*euler), (4,) + (1,) * len(batch))
    return x


def trim_sticks(params: ModelParams, col):
    """Cyclic and pedal sticks (lat, lon, ped) that hold the aircraft at rest, for a collective.

    At rest (zero rates, servo settled) each rate derivative is
    ``F_i(col) + G_i(col) * stick_i`` (eqs. 18, 21: offsets kd, collective torque,
    and the control gain, possibly scheduled by the collective); the trim is
    ``-F_i / G_i``.

    Parameters
    ----------
    params : ModelParams
    col : float or ndarray
        Collective stick [-1, 1].

    Returns
    -------
    tuple of 3 (float or ndarray, shaped like ``col``)
        Trim of lat, lon, ped [stick units].
    """
    rhs = kernel(params)[0]["rhs"]
    zero = 0.0 * col
    rest = (zero, zero, zero, zero, zero, zero, 1.0 + zero, zero, zero, zero)
    f = rhs(rest, (zero, zero, col, zero), ZERO_DISTURBANCE)
    out = []
    for i, idx in enumerate((3, 4, 5)):
        x = list(rest)
        x[idx] = 1.0 + zero  # servo settled on a unit stick
        u = [zero, zero, col, zero]
        u[STICK_ROW[i]] = 1.0 + zero
        g = rhs(tuple(x), tuple(u), ZERO_DISTURBANCE)[i] - f[i]
        out.append(-f[i] / g)
    return tuple(out)


SERVO_STEP = 2.0
"""Most RK4 step over the servo's time constant (eq. 31's ``d1``, half a delay plus a lag) :func:`simulate` takes:
RK4 is stable on a first-order pole up to 2.785 step lengths per time constant, and a 5 ms delay on a 50 Hz
log (``d1`` 2.5 ms) is 8 (the fit-rate choice's thinned logs met it: a model the likelihood had fitted, exactly
discretised, diverged in its forward simulation at 0.1 s)."""


def stable_substeps(params: ModelParams, dt: float) -> int:
    """RK4 sub-steps per sample ``dt`` [s] that keep each axis' servo pole within :data:`SERVO_STEP` (1 where the
    servos are slow enough, or absent). The rates' own dampings are left as they are: a damping too fast for the
    step is the fit's failure to place it, which the forward simulation reports."""
    d1 = [servo_coefficients(tau, lag)[0] for tau, lag in zip(params.taus, params.lags)]
    fastest = min((d for d in d1 if d > 0.0), default=math.inf)
    return max(1, math.ceil(dt / (SERVO_STEP * fastest))) if math.isfinite(fastest) and dt > 0 else 1


def simulate(params: ModelParams, time, sticks, torque=None, x0=None, substeps: int | None = None, *,
             disturbance=None):
    """Forward-simulate the model with measured inputs (zero-order hold between samples).

    RK4 (:func:`step`) over eqs. (18), (21), (31), (25)-(26), the paper's numerical
    solution of the identified model ("numerically simulated using ode45").

    Parameters
    ----------
    params : ModelParams
    time : ndarray, shape (n,)
        Sample times [s], uniformly spaced.
    sticks : ndarray, shape (4, n)
        lat, lon, col, ped in [-1, 1].
    torque : ndarray, shape (3, n), optional
        Wind torque per inertia ``k·u_d`` [rad/s^2] held over each sample interval (eq. 42).
    x0 : ndarray, shape (N_STATE,), optional
        Initial state; default rest, level, servo settled on the first sticks.
    substeps : int, optional
        RK4 sub-steps per sample interval; default as many as the servo's time constant needs
        (:func:`stable_substeps`).
    disturbance : ndarray, optional
        Deprecated name of ``torque`` (in the package's words a disturbance is u_d, in stick units).

    Returns
    -------
    ndarray, shape (N_STATE, n)
        State at every sample time; NaN from the sample where the simulation diverged.
    """
    if disturbance is not None:
        warnings.warn("simulate(disturbance=...) is deprecated: the argument is the wind torque k*u_d [rad/s^2], "
                      "pass it as torque=...", DeprecationWarning, stacklevel=2)
        torque = disturbance if torque is None else torque
    time = np.asarray(time, dtype=float)
    sticks = np.asarray(sticks, dtype=float)
    n = time.size
    dt = float(np.median(np.diff(time))) if n > 1 else 0.0
    if x0 is None:
        x0 = initial_state(sticks=sticks[list(STICK_ROW), 0])
    x = tuple(float(v) for v in x0)
    u_rows = sticks.T.tolist()
    d_rows = None if torque is None else np.asarray(torque, dtype=float).T.tolist()
    rk4 = kernel(params)[0]["rk4"]
    substeps = stable_substeps(params, dt) if substeps is None else substeps
    h = dt / substeps
    out = np.empty((n, N_STATE))
    out[0] = x
    zero = ZERO_DISTURBANCE
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
    """Body rates of ``params`` driven by a flight's sticks from its first measured state.

    What an identifier's ``predict`` returns: the model simulated (RK4, no wind,
    :func:`simulate`) from the flight's first rates, attitude and sticks.

    Parameters
    ----------
    params : ModelParams
    flight : Flight-like
        Anything with ``time`` (n,), ``rates`` (3, n) [rad/s], ``attitude`` (3, n) [rad]
        and ``sticks`` (4, n) arrays, e.g. :class:`identification.flight.Flight`.

    Returns
    -------
    ndarray, shape (3, n)
        p, q, r [rad/s].
    """
    x0 = initial_state(rates=flight.rates[:, 0], euler=flight.attitude[:, 0],
                       sticks=flight.sticks[list(STICK_ROW), 0])
    return simulate(params, flight.time, flight.sticks, x0=x0)[:3]
