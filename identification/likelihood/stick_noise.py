"""Stick noise the aircraft did not feel: a log that samples commands which changed between its samples.

A flight controller or a radio link that updates its commands faster than the log records them, with noise on
them (a link's jitter, a loop reacting to a noisy gyro at its own rate), leaves logged sticks that are point
samples of a command that moved between them. Each logged value then carries an error the aircraft did not feel
over its sample: an input measured with an error (errors in variables), and regressed on, such sticks bias the
gains and dampings low. On the bench (docs/method.md, "A world faster than its log") a link four times faster
than its log with a command noise of 0.01 left the agile aircraft's yaw gain k10 8 % low; the same fit on each
sample's true mean over its interval is within 0.5 %. No estimate from the log's samples alone recovers that
mean (what moved between them is not in the log), so the tool says so rather than mending it.

:func:`check_stick_noise` is the test. It fits the model again on sticks each pulled :data:`SHRINK` of the way to
the mean of its two neighbours (:func:`neighbour_shrunk`: what the aircraft felt of a command that held the
logged value for a quarter of its sample) and on the sticks as logged, with every other setting the fit decided
(hold, delay, lag, wind model), and compares their likelihoods per axis. Where the aircraft felt the sticks as
logged (held at the log's rate, or a hand moving smoothly) the shrunk sticks explain the rates worse or no
better; where the logged sticks carry noise the aircraft did not feel, they explain them better by far more than
a parameter's worth (Schwarz's :data:`~identification.likelihood.input_hold.HOLD_BIC` ``* ln n``).
``scripts/stick_noise_study.py`` measures both kinds.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from heli_core.terms import AXES, TERMS

from .input_hold import HOLD_BIC

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
        Per axis, the relative change [%] of each gain and damping fitted on the shrunk sticks over the logged
        ones (the direction the bias lies in; the fit on shrunk sticks is not its cure).
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


def _moved(logged: dict, shrunk: dict) -> dict:
    """Relative change [%] of the gains and dampings (the kd offsets' relative moves mean little)."""
    out = {}
    for axis, fit in logged.items():
        other = shrunk[axis].params
        out[axis] = {name: 100.0 * (other[name] - value) / abs(value) for name, value in fit.params.items()
                     if name in other and name in TERMS and not name.startswith("kd") and value != 0}
    return out


def check_stick_noise(ident) -> StickNoiseCheck:
    """Fit the fitted maximum-likelihood estimator ``ident``'s model again on its flights as logged and with
    neighbour-shrunk sticks (module docstring), every decision of its fit held, and compare per axis.

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
    estimator = type(ident)
    flights = list(ident.flights_)
    logged = estimator(**_settings(ident)).fit(flights).axes_
    shrunk_flights = [replace(f, sticks=neighbour_shrunk(f.sticks)) for f in flights]
    shrunk = estimator(**_settings(ident)).fit(shrunk_flights).axes_
    lr = {axis: float(logged[axis].nll - shrunk[axis].nll) for axis in logged}
    thresholds = {axis: HOLD_BIC * float(np.log(logged[axis].n_samples)) for axis in logged}
    return StickNoiseCheck(lr, thresholds, _moved(logged, shrunk))
