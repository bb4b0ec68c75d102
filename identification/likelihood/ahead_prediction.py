"""Multi-step prediction of the wind-state model, in the fit and on segments the fit never saw.

The one-step prediction error is what the likelihood of
:mod:`identification.likelihood.estimator` minimises, and on a log that was low-pass filtered
before it was written (nothing above a few Hz, :mod:`identification.log_band`) it is
near zero for any model: the next sample of a smooth signal is its last one. What a
user relies on is the model's prediction further ahead: from the Kalman-filtered state
at sample ``k`` (rate and gust states), the rate ``h`` samples later with the sticks
known and the gust decaying as its Gauss-Markov model says (:func:`ahead_r2`, 0.5 s by
default in the reports). :func:`heldout_ahead_r2` scores it on segments not used for
the fit: the flight is cut into ``folds`` contiguous blocks, the model is fitted on the
others (as separate flights sharing the parameters, each with its own offset) and
predicts the held-out block from its own filter, the model's mean offset in place of
the block's.

A prediction whose error grows without bound (a model with negative damping, an
unstable filter) has no R²: it is reported as *diverged*, never as a number like -10^42
(:mod:`identification.likelihood.ahead_score`: the horizon and the score as the reports give them).
"""

from __future__ import annotations

import inspect
import math

import numpy as np

from heli_core.deprecation import module_getattr
from heli_core.terms import AXES

from ..flight import Flight
from .ahead_score import AHEAD_S, is_diverged
from .axis_likelihood import AxisLikelihood
from .axis_search import BURN_IN
from .state_space import lti_apply



def ahead_r2(like: AxisLikelihood, x, theta, horizon: int) -> float:
    """R² of the model's prediction ``horizon`` samples ahead from the Kalman-filtered state (every flight of
    ``like``), or NaN when the prediction diverged (:func:`~.ahead_score.is_diverged`).

    ``x_{k+h|k} = Ad^h (x_{k|k} - F_k) + F_{k+h}`` with ``F`` the response from rest
    to the known inputs: the gust estimate decays as the wind model says.
    """
    num, den = _ahead_sums(like, x, theta, horizon)
    return _r2(num, den)


def _ahead_sums(like: AxisLikelihood, x, theta, horizon: int) -> tuple[float, float]:
    """The squared ``horizon``-ahead prediction errors and the squared deviations of the rate from its mean,
    each summed over the flights of ``like`` after the burn-in (:func:`ahead_r2` is ``1 - num / den``)."""
    d = like.data
    Ad, g0, g1, L, _ = like.predictor(x)
    m = Ad.shape[0]
    eye = np.eye(m)
    Phi = Ad - np.outer(Ad @ L, eye[0])
    row = np.linalg.matrix_power(Ad, horizon)[0]
    num = den = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        for y, X in zip(d.y, d.regressors):
            u = theta @ X
            un = np.append(u[1:], u[-1])
            n = y.size
            pred = lti_apply(Phi, np.column_stack([Ad @ L, g0, g1]), eye, np.zeros((m, 3)), np.vstack([y, u, un]))
            filt = pred + np.outer(L, y - pred[0])
            F = lti_apply(Ad, np.column_stack([g0, g1]), eye, np.zeros((m, 2)), np.vstack([u, un]))
            p = row @ (filt[:, :n - horizon] - F[:, :n - horizon]) + F[0, horizon:]
            target = y[horizon:]
            keep = slice(d.burn, None)
            num += float(np.sum((target - p)[keep] ** 2))
            den += float(np.sum((target[keep] - target[keep].mean()) ** 2))
    return num, den


def blocked_ahead_r2(problem, tau: float, x0, kind: str, nfev: int, horizon: int, lag: float = 0.0) -> float:
    """The ``horizon``-ahead prediction R² of one axis' structure on data the fit did not see: each of the
    flights of ``problem`` (an :class:`~identification.likelihood.axis_search.AxisProblem` over contiguous
    blocks of one flight, sticks already aligned) predicted by the structure fitted on the others, the errors
    pooled over the blocks; NaN when a prediction diverged.

    Each fit is searched from ``x0`` (the structure's fit on the whole flight) with ``nfev`` evaluations, the
    wind model ``kind``, servo delay ``tau``, servo lag ``lag`` and the problem's input hold held; the held-out
    block's offset is the mean of the fitted blocks' (it was not fitted on it), as in :func:`heldout_ahead_r2`.
    """
    blocks = list(problem.flights)
    num = den = 0.0
    for i, block in enumerate(blocks):
        train = problem.on([b for j, b in enumerate(blocks) if j != i])
        _, x, kind_i, _ = train.best(tau, x0, (kind,), nfev, lag=lag)
        data = train.data(tau, kind_i, lag)
        like = AxisLikelihood(data)
        _, theta, _ = like.solve_linear(x)
        fitted = dict(zip(data.names, theta))
        offsets = [v for n, v in fitted.items() if "@" in n]
        held = problem.on([block]).data(tau, kind_i, lag)
        theta_held = np.array([np.mean(offsets) if "@" in n else fitted[n] for n in held.names])
        b_num, b_den = _ahead_sums(AxisLikelihood(held), x, theta_held, horizon)
        num, den = num + b_num, den + b_den
    return _r2(num, den)


def _r2(num: float, den: float) -> float:
    """``1 - num / den`` from :func:`_ahead_sums`' sums, or NaN for a diverged prediction."""
    r2 = 1.0 - num / (den or 1.0)
    return math.nan if is_diverged(r2) else r2


def heldout_ahead_r2(identifier, flight: Flight, folds: int = 4, horizon_s: float = AHEAD_S) -> dict:
    """Per axis, the ``horizon_s``-ahead prediction R² on each of ``folds`` contiguous blocks of ``flight``,
    each predicted by the model fitted on the other blocks.

    Parameters
    ----------
    identifier : MaximumLikelihoodIdentifier
        An estimator with the settings to use (it is cloned per fold, never refitted in place).
    flight : Flight
        The flight as the identifier would take it (aligned, resampled).
    folds : int
        Number of blocks (each at least 20 s).
    horizon_s : float
        Prediction horizon [s].

    Returns
    -------
    dict
        ``{axis: [r2 of block 1, ...]}`` with NaN for a diverged prediction (:func:`~.ahead_score.format_r2`).

    Raises
    ------
    ValueError
        Fewer than 2 folds, or blocks shorter than 20 s.
    """
    if folds < 2 or flight.duration / folds < 20.0:
        raise ValueError(f"need at least 2 folds of 20 s each; got {folds} folds of a {flight.duration:.1f} s flight")
    edges = np.linspace(flight.time[0], flight.time[-1], folds + 1)
    blocks = [flight.segment(edges[i], edges[i + 1]) for i in range(folds)]
    horizon, burn = _samples(horizon_s, flight.sample_rate)
    out = {axis: [] for axis in identifier.axes}
    for i, block in enumerate(blocks):
        fitted = _clone(identifier).fit([b for j, b in enumerate(blocks) if j != i])
        cleaned = [fitted._clean(fitted.aligned(block))[0]]
        for axis, fit in fitted.axes_.items():  # the block's offset is the model's: it was not fitted on it
            out[axis].append(_axis_r2(fitted, axis, fit, cleaned, burn, horizon))
    return out


def _samples(horizon_s: float, sample_rate: float) -> tuple[int, int]:
    """The prediction horizon (at least one sample) and the likelihood's burn-in, in samples of the flight."""
    return max(1, int(round(horizon_s * sample_rate))), int(round(BURN_IN * sample_rate))


def _clone(identifier):
    """A new, unfitted estimator with ``identifier``'s settings (scikit-learn's ``clone``)."""
    names = inspect.signature(type(identifier)).parameters
    return type(identifier)(**{k: getattr(identifier, k) for k in names})


def _axis_r2(identifier, axis: str, fit, cleaned: list, burn: int, horizon: int, own_offsets: bool = False) -> float:
    """The ``horizon``-ahead R² of one axis of a fitted identifier on ``cleaned`` flights (aligned, vibration
    removed); each flight's offset its own fitted one (``own_offsets``, the flights it was fitted on) or the
    model's, the mean of the fitted flights' (flights it did not see)."""
    data = identifier._fitted_data(AXES.index(axis), fit, cleaned, burn)
    theta = np.array([fit.flight_offsets[int(n.split("@")[1])] if own_offsets and "@" in n
                      else fit.params[n.split("@")[0]] for n in data.names])
    return ahead_r2(AxisLikelihood(data), fit.state, theta, horizon)


def fitted_ahead_r2(identifier, flights, horizon_s: float = AHEAD_S) -> dict:
    """Per axis, the ``horizon_s``-ahead prediction R² of a fitted maximum-likelihood identifier on the flights
    it was fitted on, each flight with its own offset (:func:`ahead_r2`).

    Unlike the share of the rate the sticks explain alone (the fit's ``r2``, low on a correct model when the wind
    dominates the axis) and the one-step prediction's (near 1 for any model at a high sample rate), it says
    whether the model predicts the rate: a correct model in strong wind scores high, a model of noise low.

    Parameters
    ----------
    identifier : MaximumLikelihoodIdentifier
        Fitted.
    flights : sequence of Flight
        The flights it was fitted on, as given to ``fit``.
    horizon_s : float
        Prediction horizon [s].

    Returns
    -------
    dict
        ``{axis: r2}``, NaN for a diverged prediction (:func:`~.ahead_score.format_r2`).
    """
    flights = [flights] if isinstance(flights, Flight) else list(flights)
    horizon, burn = _samples(horizon_s, flights[0].sample_rate)
    cleaned = [identifier._clean(identifier.aligned(f))[0] for f in flights]
    return {axis: _axis_r2(identifier, axis, fit, cleaned, burn, horizon, own_offsets=True)
            for axis, fit in identifier.axes_.items()}


def flight_ahead_r2(identifier, flight: Flight, horizon_s: float = AHEAD_S) -> dict:
    """Per axis, the ``horizon_s``-ahead prediction R² of a fitted maximum-likelihood identifier on a flight it
    was not fitted on (``heli identify --validate``).

    Its offset is the model's, the mean of the fitted flights' (the flight's own was not fitted).

    Parameters
    ----------
    identifier : MaximumLikelihoodIdentifier
        Fitted.
    flight : Flight
        Another flight of the aircraft, prepared as the fit prepared its own (sticks aligned by the
        identifier's shifts, vibration lines removed: :func:`identification.validation.other_flights.as_fitted`).
    horizon_s : float
        Prediction horizon [s].

    Returns
    -------
    dict
        ``{axis: r2}``, NaN for a diverged prediction (:func:`~.ahead_score.format_r2`).
    """
    horizon, burn = _samples(horizon_s, flight.sample_rate)
    return {axis: _axis_r2(identifier, axis, fit, [flight], burn, horizon) for axis, fit in identifier.axes_.items()}


__getattr__ = module_getattr(__name__)
