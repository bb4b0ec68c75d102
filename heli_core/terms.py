"""The library of named model terms (candidate physical effects), the axes and their sticks.

Every attitude model in this package is linear in its parameters: each body-rate
derivative is a sum of *terms*, each term a parameter times a *feature* of the
measured or simulated signals (paper eqs. 18 and 21)::

    p' = k1*q*r + k2*u_lat - k3*p + k4*q + kd1 (+ added terms)          (18)
    q' = k5*p*r + k6*u_lon - k7*q - k8*p + kd2 (+ added terms)          (21)
    r' = k9*p*q + k10*u_ped - k11*r - k12*col + kd3 (+ added terms)     (21)

where ``u_*`` is the stick after the servo (the Padé-delayed command of eq. 31
when a delay is identified, else the stick itself). The physics core
(:mod:`heli_core.physics`, :mod:`heli_core.discrete`) evaluates these terms to
step the model; the integral method (:mod:`identification.integral.method`)
integrates the same features to fit the parameters. Adding a physical effect is
adding a term here, never editing the fitter or the simulator (the layout of
pysindy's feature library vs its optimizers).

Sign convention: a term's ``sign`` is the sign the paper writes in front of the
parameter, so that the identified values keep the paper's meaning
(``k3 > 0`` is damping, ``k12`` enters as ``-k12*col``).

This module also names, once for the whole package, the three axes
(:data:`AXES`), the stick driving each (:data:`INPUT_FOR_AXIS`) and that stick's
row in a stick vector ``(lat, lon, col, ped)`` (:data:`STICK_ROW`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

AXES = ("roll", "pitch", "yaw")
"""Axis names in state order: roll rate p, pitch rate q, yaw rate r."""

INPUT_FOR_AXIS = ("lat", "lon", "ped")
"""Stick that drives each axis: lateral cyclic → roll, longitudinal → pitch, pedal → yaw."""

STICKS = ("lat", "lon", "col", "ped")
"""The four sticks in the order of every stick vector (``Flight.sticks``, the core's input ``u``) [-1, 1]."""

STICK_ROW = (0, 1, 3)
"""Row of :data:`STICKS` holding the stick of each axis (:data:`INPUT_FOR_AXIS`): lat → roll,
lon → pitch, ped → yaw. Index arrays with ``sticks[list(STICK_ROW)]`` (a tuple would index
several dimensions)."""

# A feature maps (rates[3, ...], cmd[3, ...], col[...]) -> array[...]. rates are
# p, q, r in rad/s; cmd are the servo-side commands for roll, pitch, yaw in [-1, 1]
# stick units; col is the collective stick in [-1, 1].
FeatureFn = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]

FEATURE_EXPRESSIONS: dict[str, str] = {
    "q*r": "q*r",
    "p*r": "p*r",
    "p*q": "p*q",
    "p": "p",
    "q": "q",
    "r": "r",
    "u_lat": "c0",
    "u_lon": "c1",
    "u_ped": "c2",
    "col": "col",
    "1": "1.0",
    "p|p|": "p*abs(p)",
    "q|q|": "q*abs(q)",
    "r|r|": "r*abs(r)",
    "u_lat*col": "c0*col",
    "u_lon*col": "c1*col",
    "u_ped*col": "c2*col",
}
"""Every feature as an arithmetic expression in ``p, q, r`` (body rates), ``c0, c1, c2``
(servo-side roll, pitch, yaw commands) and ``col`` (collective). This is the single
definition of the model's terms: the physics core compiles it into its right-hand
side, and :data:`FEATURES` into vectorised functions for the identifiers. Only
arithmetic and ``abs`` are used, so the same expression evaluates Python floats
and numpy arrays alike."""


def _feature_fn(expr: str) -> FeatureFn:
    f = eval(f"lambda p, q, r, c0, c1, c2, col: {expr}", {"abs": abs})  # noqa: S307 - our own constant table
    return lambda w, u, c: f(w[0], w[1], w[2], u[0], u[1], u[2], c)


FEATURES: dict[str, FeatureFn] = {name: _feature_fn(expr) for name, expr in FEATURE_EXPRESSIONS.items()}
"""Named features as functions of (rates[3, ...], cmd[3, ...], col[...]), vectorised over any trailing shape."""

FEATURE_NAMES: tuple[str, ...] = tuple(FEATURES)

RATE_DEPENDENCE: dict[str, frozenset] = {
    "q*r": frozenset({1, 2}), "p*r": frozenset({0, 2}), "p*q": frozenset({0, 1}),
    "p": frozenset({0}), "q": frozenset({1}), "r": frozenset({2}),
    "p|p|": frozenset({0}), "q|q|": frozenset({1}), "r|r|": frozenset({2}),
}
"""Which body rates (0 p, 1 q, 2 r) each feature reads; features not listed read only inputs."""


@dataclass(frozen=True)
class Term:
    """One parameter of the model and the feature it multiplies.

    Attributes
    ----------
    param : str
        Parameter name as in the paper (``"k2"``) or the catalogue (``"nld1"``).
    axis : int
        0 roll, 1 pitch, 2 yaw: which rate derivative the term adds to.
    feature : str
        Key of :data:`FEATURES`.
    sign : float
        +1 or -1, the sign written in front of the parameter in the equation.
    effect : str
        Physical effect the term belongs to (``"control"``, ``"damping"``,
        ``"offset"``, ``"cross_coupling"``, ``"gyroscopic"``,
        ``"collective_torque"``, ``"nonlinear_damping"``, ``"gain_scheduling"``).
    unit : str
        Unit of the parameter.
    description : str
        One line of physics, from the paper where it applies.
    """

    param: str
    axis: int
    feature: str
    sign: float
    effect: str
    unit: str
    description: str


def _t(param, axis, feature, sign, effect, unit, description):
    return Term(param, axis, feature, float(sign), effect, unit, description)


TERMS: dict[str, Term] = {
    t.param: t
    for t in (
        # Roll, eq. (18)-(19)
        _t("k1", 0, "q*r", +1, "gyroscopic", "1", "(Iyy-Izz)/Ixx: rigid-body gyroscopic coupling, eq. (19)"),
        _t("k2", 0, "u_lat", +1, "control", "rad/s^2", "roll torque per unit lateral cyclic (main rotor + flybar booster C1), eq. (19)"),
        _t("k3", 0, "p", -1, "damping", "1/s", "effective roll damping (rotor + flybar C2), eq. (19)"),
        _t("k4", 0, "q", +1, "cross_coupling", "1/s", "flybar cross-coupling C3 of pitch rate into roll, eq. (19)"),
        _t("kd1", 0, "1", +1, "offset", "rad/s^2", "constant roll torque offset (asymmetry, mean wind), eq. (18)"),
        # Pitch, eq. (21)-(22)
        _t("k5", 1, "p*r", +1, "gyroscopic", "1", "(Izz-Ixx)/Iyy: rigid-body gyroscopic coupling, eq. (22)"),
        _t("k6", 1, "u_lon", +1, "control", "rad/s^2", "pitch torque per unit longitudinal cyclic, eq. (22)"),
        _t("k7", 1, "q", -1, "damping", "1/s", "effective pitch damping, eq. (22)"),
        _t("k8", 1, "p", -1, "cross_coupling", "1/s", "flybar cross-coupling C3 of roll rate into pitch, eq. (22)"),
        _t("kd2", 1, "1", +1, "offset", "rad/s^2", "constant pitch torque offset, eq. (24)"),
        # Yaw, eq. (21), (23)
        _t("k9", 2, "p*q", +1, "gyroscopic", "1", "(Ixx-Iyy)/Izz: rigid-body gyroscopic coupling, eq. (23)"),
        _t("k10", 2, "u_ped", +1, "control", "rad/s^2", "tail-rotor thrust torque per unit pedal, eq. (23)"),
        _t("k11", 2, "r", -1, "damping", "1/s", "yaw damping incl. the electronic gyro gain Kg, eq. (15), (23)"),
        _t("k12", 2, "col", -1, "collective_torque", "rad/s^2", "main-rotor reaction torque Km per unit collective, eq. (17), (23)"),
        _t("kd3", 2, "1", +1, "offset", "rad/s^2", "constant yaw torque offset, eq. (24)"),
        # Catalogue of effects beyond the paper's minimal model (issue: diagnose)
        _t("ct1", 0, "col", +1, "collective_torque", "rad/s^2", "collective drives roll when the rotor disc is tilted (cyclic analogue of k12, Section 2.2)"),
        _t("ct2", 1, "col", +1, "collective_torque", "rad/s^2", "collective drives pitch when the rotor disc is tilted (cyclic analogue of k12, Section 2.2)"),
        _t("nld1", 0, "p|p|", -1, "nonlinear_damping", "1/rad", "roll damping growing with the square of the rate (profile drag)"),
        _t("nld2", 1, "q|q|", -1, "nonlinear_damping", "1/rad", "pitch damping growing with the square of the rate"),
        _t("nld3", 2, "r|r|", -1, "nonlinear_damping", "1/rad", "yaw damping growing with the square of the rate"),
        _t("gs1", 0, "u_lat*col", +1, "gain_scheduling", "rad/s^2", "lateral cyclic effectiveness changing with collective (rotor load), Section 4"),
        _t("gs2", 1, "u_lon*col", +1, "gain_scheduling", "rad/s^2", "longitudinal cyclic effectiveness changing with collective (rotor load), Section 4"),
        _t("gs3", 2, "u_ped*col", +1, "gain_scheduling", "rad/s^2", "pedal effectiveness changing with collective (tail load), Section 4"),
    )
}
"""Every parameter the package knows, keyed by name."""

BASE_PARAMS: tuple[str, ...] = (
    "k1", "k2", "k3", "k4", "kd1",
    "k5", "k6", "k7", "k8", "kd2",
    "k9", "k10", "k11", "k12", "kd3",
)
"""The paper's parameters of eqs. (18) and (21)."""

EXTRA_PARAMS: tuple[str, ...] = tuple(p for p in TERMS if p not in BASE_PARAMS)
"""Catalogue terms that a diagnosis (or a synthetic flight) may add."""

DECOUPLED: dict[int, tuple[str, ...]] = {
    0: ("k2", "k3", "kd1"),
    1: ("k6", "k7", "kd2"),
    2: ("k10", "k11", "k12", "kd3"),
}
"""Decoupled structure of Section 3.2 (k1 = k4 = 0 etc.; yaw keeps k12 as in eq. 70)."""

COUPLED: dict[int, tuple[str, ...]] = {
    0: ("k1", "k2", "k3", "k4", "kd1"),
    1: ("k5", "k6", "k7", "k8", "kd2"),
    2: ("k9", "k10", "k11", "k12", "kd3"),
}
"""Fully coupled structure of eqs. (18)-(24)."""


def terms_for_axis(axis: int, params: tuple[str, ...]) -> list[Term]:
    """Terms of ``params`` that act on ``axis``, in the order given."""
    return [TERMS[p] for p in params if TERMS[p].axis == axis]


def evaluate_features(names, rates, cmd, col) -> np.ndarray:
    """Evaluate named features, stacked along a new first axis.

    Parameters
    ----------
    names : sequence of str
        Keys of :data:`FEATURES`.
    rates : ndarray, shape (3, ...)
        Body rates p, q, r [rad/s].
    cmd : ndarray, shape (3, ...)
        Servo-side commands for roll, pitch, yaw [stick units, -1..1].
    col : ndarray, shape (...)
        Collective stick [-1..1].

    Returns
    -------
    ndarray, shape (len(names), ...)
    """
    shape = np.shape(rates[0])
    return np.stack([np.broadcast_to(FEATURES[n](rates, cmd, col), shape) for n in names])
