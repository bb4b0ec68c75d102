"""Validate identified models against a flight: the paper's error tables and figures.

Section 3.2 of the paper judges a model by forward-simulating it with the
measured sticks and comparing the simulated body rates with the measured ones
(Figs. 9-14, Tables 1-2: mean absolute error, 90th percentile of the absolute
error, and the error relative to the largest measured rate), then by comparing
the attitude angles of eqs. (25)-(29) after subtracting the best piecewise-linear
function over 10 s pieces from both (Figs. 15-18). Section 3.4 repeats the
comparison with the identified disturbance fed to the model.

:func:`validate_models` runs that comparison for any number of models at once
and returns a :class:`ValidationResult` holding the histories, the statistics,
a JSON-ready dictionary and Markdown tables in the paper's layout; the
figures are drawn by :mod:`identification.reports.validation`
(:func:`~identification.reports.validation.plot_rate_fit`,
:func:`~identification.reports.validation.plot_attitude_fit`).

All statistics are reported in degrees (deg/s for rates), as in the paper;
every array going in is in radians (rad/s for rates).
"""

from __future__ import annotations

import warnings

from collections.abc import Mapping

import numpy as np

from heli_core.params import ModelParams
from heli_core.physics import QUAT, initial_state, simulate
from heli_core.quaternion import euler_from_quaternion
from heli_core.terms import AXES, STICK_ROW

from ..attitude import DETREND_PERIOD, detrended_angles
from ..errors import SimulationDivergedError
from ..flight import Flight
from ..percentile import PERCENTILE_METHOD
from .result import ValidationResult

# ---------------------------------------------------------------------- checks
def _as_histories(name: str, values, n: int | None = None) -> np.ndarray:
    """``values`` as a float array of shape (3, n), or a ValueError naming it."""
    a = np.asarray(values, dtype=float)
    if a.ndim != 2 or a.shape[0] != 3 or (n is not None and a.shape[1] != n):
        want = f"(3, {n})" if n is not None else "(3, n)"
        raise ValueError(f"{name} must have shape {want} (roll, pitch, yaw by sample), got {a.shape}")
    if a.shape[1] == 0:
        raise ValueError(f"{name} holds no samples")
    if not np.all(np.isfinite(a)):
        bad = ~np.isfinite(a)
        row, col = np.unravel_index(int(np.argmax(bad)), a.shape)
        raise ValueError(
            f"{name} has {int(bad.sum())} non-finite values, first on the {AXES[row]} axis at sample {col}"
        )
    return a


def _pair(name_a: str, a, name_b: str, b) -> tuple[np.ndarray, np.ndarray]:
    a = _as_histories(name_a, a)
    b = _as_histories(name_b, b, a.shape[1])
    return a, b


# ---------------------------------------------------------------- statistics
def rate_error_stats(measured, modelled) -> dict[str, dict[str, float]]:
    """Error statistics of modelled body rates, Table 1 / Table 2.

    Parameters
    ----------
    measured : array_like, shape (3, n)
        Measured (usually low-pass filtered) p, q, r [rad/s].
    modelled : array_like, shape (3, n)
        Simulated p, q, r at the same samples [rad/s].

    Returns
    -------
    dict
        Per axis name (``"roll"``, ``"pitch"``, ``"yaw"``) a dict with

        ``mae_deg_s``
            Mean absolute error [deg/s].
        ``p90_deg_s``
            90th percentile of the absolute error [deg/s], interpolated as
            Matlab's ``prctile`` (:data:`identification.percentile.PERCENTILE_METHOD`).
        ``rel_max_pct``
            Mean absolute error relative to the largest absolute measured rate
            [%] (Table 1, "error relative to maximum"); NaN when the measured
            rate is identically zero.

    Raises
    ------
    ValueError
        Shapes other than (3, n) with equal n, or non-finite values.
    """
    measured, modelled = _pair("measured", measured, "modelled", modelled)
    err = np.degrees(np.abs(modelled - measured))
    mae = err.mean(axis=1)
    p90 = np.percentile(err, 90.0, axis=1, method=PERCENTILE_METHOD)
    peak = np.degrees(np.abs(measured).max(axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(peak > 0.0, 100.0 * mae / np.where(peak > 0.0, peak, 1.0), np.nan)
    return {
        axis: {"mae_deg_s": float(mae[i]), "p90_deg_s": float(p90[i]), "rel_max_pct": float(rel[i])}
        for i, axis in enumerate(AXES)
    }


def rate_fit_stats(measured, modelled) -> dict[str, dict[str, float]]:
    """How much of the measured rates a simulation explains, as MATLAB's ``compare`` reports it.

    Parameters
    ----------
    measured : array_like, shape (3, n)
        Measured p, q, r [rad/s].
    modelled : array_like, shape (3, n)
        Simulated p, q, r at the same samples [rad/s].

    Returns
    -------
    dict
        Per axis name a dict with

        ``fit_pct``
            The normalised root-mean-square fit ``100 (1 - ||y - y_sim|| / ||y - mean(y)||)`` [%]: 100 a
            perfect simulation, 0 no better than the measured mean, negative worse.
        ``r2``
            ``1 - ||y - y_sim||² / ||y - mean(y)||²``, which is ``1 - (1 - fit/100)²``.

        Both NaN on an axis whose measured rate does not vary.

    Raises
    ------
    ValueError
        Shapes other than (3, n) with equal n, or non-finite values.
    """
    measured, modelled = _pair("measured", measured, "modelled", modelled)
    err = np.linalg.norm(measured - modelled, axis=1)
    spread = np.linalg.norm(measured - measured.mean(axis=1, keepdims=True), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(spread > 0.0, err / np.where(spread > 0.0, spread, 1.0), np.nan)
    return {axis: {"fit_pct": float(100.0 * (1.0 - ratio[i])), "r2": float(1.0 - ratio[i] ** 2)}
            for i, axis in enumerate(AXES)}


def between_models_mae(a, b) -> dict[str, float]:
    """Mean absolute difference between two modelled rate histories, Table 2.

    Parameters
    ----------
    a, b : array_like, shape (3, n)
        Simulated p, q, r of two models at the same samples [rad/s].

    Returns
    -------
    dict of str to float
        Per axis name, the mean absolute difference [deg/s] (Table 2, "mean
        absolute error between models").
    """
    a, b = _pair("a", a, "b", b)
    mae = np.degrees(np.abs(a - b)).mean(axis=1)
    return {axis: float(mae[i]) for i, axis in enumerate(AXES)}


def attitude_error_stats(time, measured_att, modelled_att, period: float = DETREND_PERIOD) -> dict[str, dict]:
    """Error statistics of modelled attitude after the 10 s detrend, Section 3.2.

    Both angle histories are unwrapped and detrended with
    :func:`identification.attitude.detrend_piecewise`; the error is their
    difference (Fig. 15).

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times [s].
    measured_att : array_like, shape (3, n)
        Measured roll, pitch, yaw [rad].
    modelled_att : array_like, shape (3, n)
        Modelled roll, pitch, yaw from eqs. (25)-(29) [rad].
    period : float
        Length of the linear pieces of the detrend [s].

    Returns
    -------
    dict
        Per axis name a dict with ``mae_deg`` (mean absolute error [deg]) and
        ``std_deg`` (standard deviation of the error [deg]).

    Raises
    ------
    ValueError
        Shapes that do not match ``time``, non-finite values, or a
        non-positive ``period``.
    """
    time = np.asarray(time, dtype=float)
    if time.ndim != 1 or time.size < 2:
        raise ValueError(f"time must be 1-D with at least 2 samples, got shape {time.shape}")
    if not period > 0.0:
        raise ValueError(f"period must be a positive number of seconds, got {period!r}")
    measured_att = _as_histories("measured_att", measured_att, time.size)
    modelled_att = _as_histories("modelled_att", modelled_att, time.size)
    err = detrended_angles(time, modelled_att, period) - detrended_angles(time, measured_att, period)
    mae = np.abs(err).mean(axis=1)
    std = err.std(axis=1)
    return {axis: {"mae_deg": float(mae[i]), "std_deg": float(std[i])} for i, axis in enumerate(AXES)}


# ---------------------------------------------------------------- validation
DIVERGED_RATE = 100.0
"""A simulated body rate beyond this [rad/s] (about 16 revolutions per second) has diverged."""


RK4_STABLE_STEP = 2.785
"""The largest ``damping · dt`` of a decaying rate that a fixed-step classical RK4 step keeps bounded (its
stability region on the negative real axis ends at -2.785)."""

COUPLING = ("k1", "k4", "k5", "k8", "k9")
"""The paper's terms that feed one axis' rate from another's (eqs. 18, 21)."""


def _divergence_cause(params: ModelParams, dt: float) -> tuple[str, bool]:
    """Why a model's simulation left :data:`DIVERGED_RATE`, and whether a late input or a rate controller's
    log is a likely cause (not when the simulation step, not the model, is unstable)."""
    values = params.values()
    damping = dict(zip(AXES, ("k3", "k7", "k11")))
    unstable = [a for a, k in damping.items() if not values[k] > 0.0]
    if unstable:
        return (f"its damping is not positive on {', '.join(unstable)} ("
                + ", ".join(f"{damping[a]}={values[damping[a]]:.3g}" for a in unstable) + ")"), True
    stiff = [a for a, k in damping.items() if values[k] * dt > RK4_STABLE_STEP]
    if stiff:
        said = ", ".join(f"{damping[a]}={values[damping[a]]:.4g} 1/s (k·dt {values[damping[a]] * dt:.2f})"
                         for a in stiff)
        many = len(stiff) > 1
        return (f"its damping{'s' * many} {said} decay{'' if many else 's'} faster than the simulation's fixed "
                f"{dt:g} s step can follow (RK4 holds up to k·dt {RK4_STABLE_STEP:g}): the model's "
                f"ax{'es are' if many else 'is is'} stable, {'their' if many else 'its'} simulation at this step "
                "is not, and a damping this fast says the data did not place it (the maximum-likelihood search "
                "stops at 200 1/s)"), False
    added = [name for name, value in params.extra if value]
    if added:
        return f"its added terms ({', '.join(added)}) feed the rates back faster than the damping removes them", True
    coupled = [k for k in COUPLING if values[k]]
    if coupled:
        return (f"its coupling terms ({', '.join(f'{k}={values[k]:.3g}' for k in coupled)}) feed the axes into "
                "each other faster than the dampings remove it"), True
    return "its dampings are positive and it has no added or coupling terms: its inputs drive it there", True


def _check_bounded(label: str, params: ModelParams, time, rates) -> None:
    """Raise :class:`SimulationDivergedError` when a simulated rate history leaves ``DIVERGED_RATE``; the
    message names the cause the model shows (:func:`_divergence_cause`), and only the terms it has."""
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(rates) <= DIVERGED_RATE)  # NaN counts as diverged
    if not bad.any():
        return
    row, col = np.unravel_index(int(np.argmax(bad)), bad.shape)
    dt = float(np.median(np.diff(time))) if len(time) > 1 else 0.0
    why, input_causes = _divergence_cause(params, dt)
    likely = (" Likely causes: a servo delay or a late input column the model does not have, or a log of an "
              "aircraft flown by a rate controller (its recorded command is not an open-loop input)."
              if input_causes else "")
    raise SimulationDivergedError(
        f"model {label!r} diverges when simulated from the flight's sticks: the {AXES[row]} rate leaves "
        f"±{DIVERGED_RATE:g} rad/s at t={float(time[col]):.2f} s; {why}.{likely}")


def _disturbance_per_model(disturbance, models, n: int) -> dict[str, np.ndarray]:
    """:func:`validate_models`' ``disturbance`` as ``{label: (3, n) array}`` (labels without one left out)."""
    if isinstance(disturbance, Mapping):
        unknown = set(disturbance) - set(models)
        if unknown:
            raise ValueError(f"disturbance given for unknown model(s) {sorted(unknown)}; models: {list(models)}")
        return {lab: _as_histories(f"disturbance[{lab!r}]", d, n) for lab, d in disturbance.items()}
    if disturbance is not None:
        shared = _as_histories("disturbance", disturbance, n)
        return {lab: shared for lab in models}
    return {}


def validate_models(flight: Flight, models: dict[str, ModelParams], rates=None, torque=None, *,
                    disturbance=None) -> ValidationResult:
    """Forward-simulate models with the flight's sticks and compare them with the flight.

    Each model is simulated with :func:`heli_core.physics.simulate` (eqs. 18,
    21, 31 and the quaternion kinematics 25-26) from the measured initial rates
    and attitude, the servo states settled on the first sticks. Its rates are
    compared with the measured rates (Tables 1-2) and its attitude (eqs. 27-29)
    with the measured attitude after the 10 s detrend (Figs. 15-18).

    Parameters
    ----------
    flight : Flight
        The validation flight; its ``attitude`` is the measured attitude.
    models : dict of str to ModelParams
        Label -> model, e.g. ``{"decoupled": p1, "coupled": p2}``.
    rates : array_like, shape (3, n), optional
        Measured p, q, r to compare against [rad/s], e.g. low-pass filtered as in
        Fig. 8(b); default ``flight.rates``. The simulations start from its
        first sample.
    torque : array_like, shape (3, n), or dict of str to such arrays, optional
        Wind torque per inertia ``k·u_d`` on roll, pitch, yaw [rad/s^2] (eq. 42,
        Section 3.4), applied to every model, or per model label (a label
        missing from the dict is simulated without wind).
    disturbance : optional
        Deprecated name of ``torque``.

    Returns
    -------
    ValidationResult

    Raises
    ------
    ValueError
        No models, arrays whose shapes do not match the flight, or non-finite
        values.
    SimulationDivergedError
        A model whose simulated rates leave ±:data:`DIVERGED_RATE` (the message names
        the model, axis, time and likely cause).
    TypeError
        A model that is not a :class:`~heli_core.params.ModelParams`.
    """
    if not models:
        raise ValueError("models must name at least one ModelParams to validate, got none")
    for label, params in models.items():
        if not isinstance(params, ModelParams):
            raise TypeError(f"model {label!r} must be a ModelParams, got {type(params).__name__}")
    n = flight.n
    measured = flight.rates if rates is None else _as_histories("rates", rates, n)
    if disturbance is not None:
        warnings.warn("validate_models(disturbance=...) is deprecated: the argument is the wind torque k*u_d "
                      "[rad/s^2], pass it as torque=...", DeprecationWarning, stacklevel=2)
        torque = disturbance if torque is None else torque
    dist = _disturbance_per_model(torque, models, n)

    x0 = initial_state(rates=measured[:, 0], euler=flight.attitude[:, 0], sticks=flight.sticks[list(STICK_ROW), 0])
    simulated, sim_att, rate_stats, att_stats = {}, {}, {}, {}
    for label, params in models.items():
        state = simulate(params, flight.time, flight.sticks, torque=dist.get(label), x0=x0)
        _check_bounded(label, params, flight.time, state[:3])
        simulated[label] = state[:3]
        sim_att[label] = euler_from_quaternion(state[QUAT])
        rate_stats[label] = rate_error_stats(measured, simulated[label])
        att_stats[label] = attitude_error_stats(flight.time, flight.attitude, sim_att[label], DETREND_PERIOD)
    between = None
    if len(models) == 2:
        a, b = simulated.values()
        between = between_models_mae(a, b)
    return ValidationResult(
        time=flight.time,
        measured_rates=measured,
        simulated=simulated,
        simulated_attitude=sim_att,
        rate_stats=rate_stats,
        attitude_stats=att_stats,
        between=between,
        measured_attitude=flight.attitude,
        period=DETREND_PERIOD,
    )
