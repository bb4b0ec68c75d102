"""What closed the loop: a linear model of the pilot (or flight controller) fitted to one axis' logged sticks.

The closed-loop check (:mod:`identification.likelihood.closed_loop`) flies the identified model again with
the loop the flight had. Its pilot is the simplest law that reproduces what the sticks did with the
aircraft's state: per axis and flight, at a reaction delay ``d``::

    u[k] = c0 + c_angle * angle[k-d] + c_rate * rate[k-d] + c_noise * noise[k-d] + c_int * integral[k-d] + r[k]

``rate`` is the smoother's estimate of the body rate, ``noise`` the gyro's reading less it (its white
noise, as far as the smoother can tell), ``angle`` the log's attitude, ``integral`` its running integral (a
pilot who trims by feel, a PID) and ``r`` the rest (the pilot's sweeps and jitter: replayed as they were).
The coefficients are two-stage least squares with the smoother's gusts as instruments (:func:`fit_pilot`);
one reaction delay serves every axis of a flight (one pilot, :func:`reaction_delay`). Which of the two rate
columns the sticks follow tells who flew:
a human sees the aircraft, not the gyro, so his sticks carry none of the gyro's noise (``c_noise`` about 0),
while a flight controller's rate loop reads the gyro, noise and all (``c_noise`` about ``c_rate``). Only a
pilot who sees the aircraft puts into the sticks what the gyro did not measure (docs/method.md, "Where it
does not hold"), so only then is the check flown.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

MAX_REACTION = 0.6
"""Longest reaction delay searched [s] (a human's is 0.1-0.3 s; a flight controller's a sample or two)."""

SENSOR_SHARE = 0.25
"""Share of the gyro's noise in the sticks' rate feedback, ``|c_noise| / (|c_noise| + |c_rate|)``, above which
the loop is taken to close on the logged gyro (measured on two flights each of nine aircraft-and-cell pairs:
0.00-0.06 for the bench's human pilots, 0.39-0.57 for its flight controller, whose rate loop reads rate and
noise alike, so that ``c_noise`` is about ``c_rate``)."""


@dataclass(frozen=True, eq=False)
class PilotModel:
    """The linear pilot of one axis and flight (module docstring).

    Attributes
    ----------
    delay : int
        Reaction delay [samples] (>= 1).
    coefficients : ndarray, shape (5,)
        ``(c0, c_angle, c_rate, c_noise, c_int)`` [stick, stick/rad, stick/(rad/s), stick/(rad/s), stick/(rad s)].
    rest : ndarray, shape (n,)
        ``r``: the sticks less the feedback (the first ``delay`` samples less ``c0`` alone).
    explained : float
        Share of the sticks' variance the feedback explains (R^2).
    angle_mean : float
        The angle the feedback is about (the flight's mean) [rad].
    """

    delay: int
    coefficients: np.ndarray
    rest: np.ndarray
    explained: float
    angle_mean: float = 0.0

    @property
    def sensor_share(self) -> float:
        """``|c_noise| / (|c_noise| + |c_rate|)``: 0 for sticks that follow the aircraft, about 1/2 or more for
        sticks that follow the gyro as logged."""
        c_rate, c_noise = abs(self.coefficients[2]), abs(self.coefficients[3])
        return float(c_noise / (c_noise + c_rate)) if c_noise + c_rate > 0 else 0.0

    @property
    def flies_on(self) -> str:
        """``"aircraft"`` (a pilot who sees it) or ``"sensors"`` (a loop closed on the logged gyro)."""
        return "sensors" if self.sensor_share > SENSOR_SHARE else "aircraft"

    def describe(self, dt: float) -> dict:
        """JSON-ready: delay [s], coefficients, R^2, share and verdict."""
        c0, ca, cr, cn, ci = (float(c) for c in self.coefficients)
        return {"reaction_delay_s": self.delay * dt, "offset": c0, "angle_gain": ca, "rate_gain": cr,
                "gyro_noise_gain": cn, "integral_gain": ci, "explained": self.explained,
                "sensor_share": self.sensor_share, "flies_on": self.flies_on}


INSTRUMENT_TIMES = (0.05, 0.2, 0.5, 1.5, 5.0, 20.0)
"""Time constants of the low-passed gusts that serve as the pilot's instruments [s] (:func:`fit_pilot`)."""


@dataclass(frozen=True, eq=False)
class AxisSignals:
    """What one axis of one flight gives the pilot's fit, each (n,): the stick, the log's angle [rad]
    (unwrapped), the smoother's rate and the gyro [rad/s], and the smoother's gust torque [rad/s^2] (the
    instruments' source)."""

    stick: np.ndarray
    angle: np.ndarray
    rate: np.ndarray
    gyro: np.ndarray
    gust: np.ndarray
    dt: float

    @cached_property
    def regressors(self) -> np.ndarray:
        """(n, 5): 1, the angle about its mean, the rate, the gyro's noise, the angle's integral."""
        angle = self.angle - self.angle.mean()
        return np.column_stack([np.ones(angle.size), angle, self.rate, self.gyro - self.rate,
                                np.cumsum(angle) * self.dt])

    @cached_property
    def instrument_columns(self) -> np.ndarray:
        """(n, 2 + len(INSTRUMENT_TIMES)): 1, the gust low-passed at :data:`INSTRUMENT_TIMES` (what drives the
        angle and rate, at the time scales they answer on) and the gyro's noise."""
        from scipy import signal

        cols = [np.ones(self.gust.size)]
        for tau in INSTRUMENT_TIMES:
            a = float(np.exp(-self.dt / tau))
            cols.append(signal.lfilter([1.0 - a], [1.0, -a], self.gust))
        cols.append(self.gyro - self.rate)
        return np.column_stack(cols)

    def columns(self, d: int) -> np.ndarray:
        """The regressors ``d`` samples before each stick, from the ``d``-th on."""
        return self.regressors[: self.stick.size - d]

    def instruments(self, d: int) -> np.ndarray:
        """The instruments ``d`` samples before each stick, from the ``d``-th on."""
        return self.instrument_columns[: self.stick.size - d]


def reaction_delay(axes: list, max_reaction: float = MAX_REACTION) -> int:
    """The one reaction delay [samples] of a flight's pilot, from one sample to ``max_reaction`` seconds: the
    delay at which the motion the gusts caused explains the sticks best, summed over the flight's ``axes``
    (:class:`AxisSignals`; the second stage of :func:`fit_pilot`, relative to each stick's variance). Not
    least squares on the motion itself: an agile aircraft's rate follows its own stick within a sample or two,
    and least squares took that response for a pilot reacting in 10 ms (a 42 % bias "found" where there was
    none)."""
    dt = axes[0].dt
    longest = max(1, min(int(round(max_reaction / dt)), axes[0].stick.size // 4))
    scores = [sum(_second_stage(sig, d)[1] for sig in axes) for d in range(1, longest + 1)]
    return int(np.argmin(scores)) + 1


def _second_stage(sig: AxisSignals, d: int) -> tuple[np.ndarray, float]:
    """Two-stage least squares at delay ``d``: the coefficients and the second stage's residual variance
    relative to the stick's (normal equations: a few columns, thousands of rows, a delay at a time)."""
    X, Z, u = sig.columns(d), sig.instruments(d), sig.stick[d:]
    X_fit = Z @ np.linalg.lstsq(Z.T @ Z, Z.T @ X, rcond=None)[0]  # the first stage
    coef = np.linalg.lstsq(X_fit.T @ X_fit, X_fit.T @ u, rcond=None)[0]
    resid = u - X_fit @ coef
    return coef, float(np.var(resid)) / max(float(np.var(u)), 1e-300)


def fit_pilot(sig: AxisSignals, d: int) -> PilotModel:
    """Fit the pilot of one axis (module docstring) at the reaction delay ``d`` [samples].

    The pilot's own inputs (his sweeps) move the aircraft too, so the angle and rate are correlated with the
    rest ``r``, and least squares takes part of the sweeps' own correlation for feedback (on the bench a
    pilot 50 % too strong, and a closed-loop check that overstated the bias by a third). The coefficients
    are therefore two-stage least squares with the smoother's gust torque, low-passed at the time scales the
    aircraft answers on, as instruments (uncorrelated with the sweeps): the pilot's response to the
    aircraft's motion as the gusts drive it, which is what the closed-loop check needs of him.
    """
    coef, _ = _second_stage(sig, d)
    u = sig.stick[d:]
    resid = u - sig.columns(d) @ coef
    rest = np.empty_like(sig.stick)
    rest[d:] = resid
    rest[:d] = sig.stick[:d] - coef[0]
    total = float(np.var(u))
    explained = 1.0 - float(np.var(resid)) / total if total > 0 else 0.0
    return PilotModel(int(d), np.asarray(coef, dtype=float), rest, float(explained), float(sig.angle.mean()))
