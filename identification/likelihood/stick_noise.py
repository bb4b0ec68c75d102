"""Stick noise the aircraft did not feel: a log that samples commands which changed between its samples.

A radio link or a flight controller that updates its commands faster than the log records them, with noise on
them (a link's jitter, a receiver's noise), leaves logged sticks that are point samples of a command that moved
between them. Each logged value then carries an error the aircraft did not feel over its sample: an input measured
with an error (errors in variables), and regressed on, such sticks bias the gains and dampings low. On the bench
(docs/method.md, "Sticks that moved between the log's samples") a link four times faster than its log with a
command noise of 0.01 left the agile aircraft's yaw gain k10 8 % low; the same fit on each sample's true mean over
its interval is within 0.8 %. No estimate from the log's samples alone recovers that mean (what moved between them
is not in the log), so the tool says so rather than mending it. (A flight controller's loop faster than its log
is a case apart: its correction inside each sample reads as damping, 17-45 % high on the bench, and this test
names it on some flights only; the same section of the docs.)

:func:`check_stick_noise` is the test. At the fit's optimum (its damping, gust model, hold, delay and lag) it
evaluates the likelihood of each axis again on sticks each pulled :data:`SHRINK` of the way to the mean of its two
neighbours (:func:`neighbour_shrunk`: what the aircraft felt of a command that held the logged value for a quarter
of its sample), the linear parameters (gains, offsets) solved again, and compares it with the sticks' as logged.
Where the aircraft felt the sticks as logged (held at the log's rate, or a hand moving smoothly) the shrunk sticks
explain the rates worse or no better; where the logged sticks carry noise the aircraft did not feel, better by far
more than a parameter's worth (Schwarz's :data:`~identification.likelihood.input_hold.HOLD_BIC` ``* ln n``). Two
evaluations of the likelihood per axis, no search: on the bench the ratio is within 4 of a full refit's (190 against
194 where it names an axis, -0.6 against -0.8 where not). :func:`refit_on_shrunk` is the full refit, for the
studies (``scripts/stick_noise_study.py`` measures both kinds of log).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from heli_core.terms import AXES, TERMS

from .axis_likelihood import AxisLikelihood
from .axis_search import BURN_IN
from .input_hold import HOLD_BIC
from .state_space import concentrated_nll

SHRINK = 0.75
"""How far each stick sample is pulled to the mean of its neighbours in the test: the share of its sample a
command held the logged value for is ``1 - SHRINK`` (a link four times as fast as the log)."""


def neighbour_shrunk(sticks: np.ndarray, shrink: float = SHRINK) -> np.ndarray:
    """``sticks`` (channels, n) with every inner sample pulled ``shrink`` of the way to the mean of its two
    neighbours (the first and last sample unchanged): ``u_k - shrink * (u_k - (u_{k-1} + u_{k+1}) / 2)``.

    A constant or a straight line is unchanged; a sample-to-sample alternation is scaled by ``1 - 2 shrink``.
    """
    u = np.asarray(sticks, dtype=float)
    out = u.copy()
    out[..., 1:-1] = u[..., 1:-1] - shrink * (u[..., 1:-1] - 0.5 * (u[..., :-2] + u[..., 2:]))
    return out


@dataclass(frozen=True)
class StickNoiseCheck:
    """What :func:`check_stick_noise` found.

    Attributes
    ----------
    lr : dict of str to float
        Per axis, the negative log-likelihood the shrunk sticks gain over the logged ones (positive: the aircraft
        moved more as if it felt the neighbours' mean).
    thresholds : dict of str to float
        Per axis, the gain that names the axis (:data:`HOLD_BIC` ``* ln n``, n the axis' samples).
    moved : dict of str to dict
        Per axis, the relative change [%] of each gain (the linear parameters but the offsets) solved on the shrunk
        sticks over the logged ones, at the same optimum: the direction the bias lies in (the shrunk sticks are
        not its cure).
    shrink : float
        :data:`SHRINK` as used.
    """

    lr: dict
    thresholds: dict
    moved: dict = field(default_factory=dict)
    shrink: float = SHRINK

    @property
    def axes(self) -> tuple:
        """The axes whose logged sticks carry noise the aircraft did not feel."""
        return tuple(axis for axis in self.lr if self.lr[axis] > self.thresholds[axis])

    def describe(self) -> dict:
        """Plain figures for model.json."""
        return {"shrink": self.shrink, "axes": list(self.axes),
                "lr": {a: round(v, 1) for a, v in self.lr.items()},
                "thresholds": {a: round(v, 1) for a, v in self.thresholds.items()},
                "moved_percent": {a: {k: round(v, 1) for k, v in m.items()} for a, m in self.moved.items()}}


def _settings(ident) -> dict:
    """The fitted estimator's settings with every decision it took fixed: the terms it kept, the hold decided,
    each axis' delay and lag, no vibration removal (its flights are already cleaned), no closed-loop check."""
    decision = getattr(ident, "hold_decision_", None)
    hold = decision["fraction"] if decision else ident.input_hold
    fits = ident.axes_
    if isinstance(hold, str) and hold == "auto":  # no decision for the log: the first axis' own estimate
        hold = next(iter(fits.values())).input_hold
    structure = {AXES.index(a): tuple(name for name in fit.params if name in TERMS) for a, fit in fits.items()}
    return dict(structure=structure, extra_terms=(), input_hold=hold,
                delay=[fits[a].delay if a in fits else 0.0 for a in AXES],
                servo_lag=[fits[a].lag if a in fits else 0.0 for a in AXES],
                wind_model=ident.wind_model, remove_vibration=False, axes=tuple(fits), max_nfev=ident.max_nfev,
                select_terms=False, closed_loop=None, workers=ident.workers)


def _at_optimum(ident, a: int, fit, flights: list, burn: int) -> tuple[float, dict]:
    """Axis ``a``'s negative log-likelihood over ``flights`` at ``fit``'s optimum, the linear parameters solved
    again, and those parameters but the offsets (as :meth:`~.axis_search.AxisProblem.result` counts them)."""
    like = AxisLikelihood(ident._fitted_data(a, fit, flights, burn))
    e, theta, _ = like.solve_linear(fit.state)
    nll = concentrated_nll(0.5 * float(e @ e), e.size)
    return float(nll), {name: float(t) for name, t in zip(like.data.names, theta) if "@" not in name}


def check_stick_noise(ident) -> StickNoiseCheck:
    """The likelihood of the fitted maximum-likelihood estimator ``ident``'s model on its flights' sticks as
    logged and neighbour-shrunk, at its optimum, per axis (module docstring).

    Returns
    -------
    StickNoiseCheck

    Raises
    ------
    ValueError
        ``ident`` has not been fitted.
    """
    if not hasattr(ident, "axes_"):
        raise ValueError("check_stick_noise needs a fitted MaximumLikelihoodIdentifier; call fit first")
    flights = list(ident.flights_)
    shrunk = [replace(f, sticks=neighbour_shrunk(f.sticks)) for f in flights]
    burn = int(round(BURN_IN * flights[0].sample_rate))
    lr, thresholds, moved = {}, {}, {}
    for axis, fit in ident.axes_.items():
        a = AXES.index(axis)
        (logged, before), (felt, after) = (_at_optimum(ident, a, fit, f, burn) for f in (flights, shrunk))
        lr[axis] = logged - felt
        thresholds[axis] = HOLD_BIC * float(np.log(fit.n_samples))
        moved[axis] = {name: 100.0 * (after[name] - value) / abs(value) for name, value in before.items()
                       if name in TERMS and not name.startswith("kd") and value != 0}
    return StickNoiseCheck(lr, thresholds, moved)


def refit_on_shrunk(ident):
    """``ident``'s model fitted again on its flights with neighbour-shrunk sticks, every decision of its fit held
    (:func:`_settings`): a new fitted estimator of ``ident``'s type (the studies' measure of how far the shrunk
    sticks move the dampings too)."""
    flights = [replace(f, sticks=neighbour_shrunk(f.sticks)) for f in ident.flights_]
    return type(ident)(**_settings(ident)).fit(flights)
