"""Held-out forward-simulation scores: the cross-validation engine of the diagnosis.

A model *specification* (:class:`Spec`: which terms of :mod:`heli_core.terms`
each axis carries, and each axis' command/response time alignment) is fitted
with the integral method (Section 2.5.2, Fig. 5) on all of a flight but one
block, and forward-simulated on windows of the held-out block, each window
starting from the measured rates and attitude (the paper's validation of
Section 3.2, Tables 1-2, restarted per window so that errors of different
windows are independent). Every block is held out once (K-fold, contiguous
blocks in time). The result, per axis and window, is the mean squared
difference between simulated and measured rate — the held-out gap.

The simulation is the physics core's :func:`heli_core.discrete.discrete_step`
(eqs. 18, 21, 31, 25; exact for the linear part under a hold), with the sticks held at the mean of each sample pair (the pilot's
sticks move continuously; a hold of the left sample would add half a sample of
delay).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from heli_core.discrete import discrete_kernel
from heli_core.params import ModelParams
from heli_core.quaternion import quaternion_from_euler
from heli_core.terms import AXES, DECOUPLED, STICK_ROW, TERMS

from ..errors import IdentifiabilityError
from ..flight import MAX_PLAUSIBLE_RATE, Flight
from ..integral.method import IntegralIdentifier
from ..preprocess import shift_inputs


@dataclass(frozen=True)
class Spec:
    """A model structure to fit: terms per axis and time alignment per axis.

    Attributes
    ----------
    terms : tuple of 3 tuples of str
        Parameters fitted on roll, pitch, yaw (names of :data:`heli_core.terms.TERMS`).
    alignment : tuple of 3 float
        Command/response alignment per axis [s], applied as an exact time shift
        of the axis' stick (:func:`identification.preprocess.shift_inputs`): > 0 a
        transport delay (the servo's, eq. 31, or a log whose input leads),
        < 0 a log whose input lags the response. A shift is exact at every
        frequency, where the first-order Padé filter of eq. (31) is not beyond
        about 0.1 s at the sweeps' 3 Hz; the model file stores a positive
        alignment as the Padé servo delay the environment runs.
    """

    terms: tuple = tuple(DECOUPLED[a] for a in range(3))
    alignment: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        terms = tuple(tuple(str(p) for p in t) for t in self.terms)
        if len(terms) != 3:
            raise ValueError(f"Spec.terms needs one tuple per axis (roll, pitch, yaw), got {len(terms)}")
        for a, names in enumerate(terms):
            for p in names:
                if p not in TERMS or TERMS[p].axis != a:
                    raise ValueError(f"term {p!r} does not act on the {AXES[a]} axis")
        align = tuple(float(v) for v in self.alignment)
        if len(align) != 3 or not all(np.isfinite(align)):
            raise ValueError(f"Spec.alignment must be 3 finite seconds, got {self.alignment!r}")
        object.__setattr__(self, "terms", terms)
        object.__setattr__(self, "alignment", align)

    @classmethod
    def from_params(cls, params: ModelParams) -> "Spec":
        """The structure of an existing model: its non-zero terms, the decoupled ones always, its delays."""
        values = params.values()
        terms = tuple(tuple(dict.fromkeys(DECOUPLED[a] + tuple(p for p, v in values.items()
                                                               if v != 0.0 and TERMS[p].axis == a)))
                      for a in range(3))
        return cls(terms, params.taus)

    def with_terms(self, axis: int, names) -> "Spec":
        """This spec with ``names`` added on ``axis``."""
        terms = list(self.terms)
        terms[axis] = tuple(dict.fromkeys(terms[axis] + tuple(names)))
        return Spec(tuple(terms), self.alignment)

    def with_alignment(self, axis: int, seconds: float) -> "Spec":
        """This spec with the alignment of ``axis`` set to ``seconds``."""
        align = list(self.alignment)
        align[axis] = float(seconds)
        return Spec(self.terms, tuple(align))

    def identifier(self, **kwargs) -> IntegralIdentifier:
        """The integral-method estimator of this structure (inputs already aligned and prefiltered).

        It fits no Padé servo delay: the alignment is applied beforehand as a shift of the input.
        """
        return IntegralIdentifier(structure={a: self.terms[a] for a in range(3)}, prefilter=False, **kwargs)

    def to_dict(self) -> dict:
        return {"terms": {AXES[a]: list(self.terms[a]) for a in range(3)},
                "alignment_s": {AXES[a]: self.alignment[a] for a in range(3)}}


def simulate_windows(params: ModelParams, flight: Flight, starts, length: int) -> np.ndarray:
    """Forward-simulate windows of a flight, each from its measured state.

    Parameters
    ----------
    params : ModelParams
    flight : Flight
        Supplies the sticks, and the initial rates and attitude of each window.
    starts : array_like of int, shape (B,)
        First sample of each window.
    length : int
        Samples simulated after the start.

    Returns
    -------
    ndarray, shape (3, B, length)
        Simulated p, q, r [rad/s] at samples ``start+1 .. start+length``; NaN
        after a window's state blows up.
    """
    starts = np.asarray(starts, dtype=int)
    out = np.full((3, starts.size, length), np.nan)
    if starts.size == 0:
        return out
    if starts.min() < 0 or starts.max() + length >= flight.n + 1:
        raise ValueError(f"windows of {length} samples from {starts.min()}..{starts.max()} exceed {flight.n} samples")
    sticks = flight.sticks
    x0 = np.vstack([flight.rates[:, starts], sticks[list(STICK_ROW)][:, starts],
                    quaternion_from_euler(*flight.attitude[:, starts])]).T.tolist()
    idx = starts[:, None] + np.arange(length + 1)[None, :]  # (B, length+1)
    held = (0.5 * (sticks[:, idx[:, :-1]] + sticks[:, idx[:, 1:]])).transpose(1, 2, 0).tolist()  # (B, length, 4)
    zero = (0.0, 0.0, 0.0)
    dstep = discrete_kernel(params, float(flight.dt))[0]  # the physics core's discrete_step, looked up once
    for b in range(starts.size):
        # One trajectory in Python floats: the generated kernel runs a step in a few microseconds,
        # faster than numpy rows for the handful of windows of one fold.
        x = tuple(x0[b])
        rates = []
        try:
            for u in held[b]:
                x = dstep(x, u, zero)
                rates.append(x[:3])
        except (OverflowError, ZeroDivisionError, ValueError):
            pass
        if rates:
            out[:, b, : len(rates)] = np.array(rates).T
    return out


@dataclass
class Score:
    """Held-out forward-simulation result of one spec.

    Attributes
    ----------
    spec : Spec
    mse : ndarray, shape (3, n_windows)
        Mean squared rate error per axis and window [(rad/s)^2].
    simulated, measured : ndarray, shape (3, n_windows, length)
        Simulated and measured rates of every held-out window [rad/s].
    fold_params : list of ModelParams
        The model fitted without each fold.
    """

    spec: Spec
    mse: np.ndarray
    simulated: np.ndarray
    measured: np.ndarray
    fold_params: list = field(default_factory=list)

    @cached_property
    def residual(self) -> np.ndarray:
        """Measured minus simulated rates, shape (3, n_windows, length) [rad/s]."""
        return self.measured - self.simulated

    def r2(self) -> np.ndarray:
        """Share of the held-out rate variance the simulation explains, per axis."""
        m = self.measured.reshape(3, -1)
        ss = ((m - m.mean(axis=1, keepdims=True)) ** 2).sum(axis=1)
        return 1.0 - (self.residual.reshape(3, -1) ** 2).sum(axis=1) / np.where(ss > 0, ss, 1.0)

    def gain_over(self, other: "Score", axis: int) -> float:
        """Relative reduction of the held-out squared error on ``axis`` against ``other``."""
        return float(1.0 - self.mse[axis].sum() / other.mse[axis].sum())


class HeldOut:
    """K-fold held-out scoring of model specs on one flight.

    Parameters
    ----------
    flight : Flight
        The flight, already prefiltered as the identification wants it.
    folds : int
        Number of contiguous blocks, each held out once.
    window : float
        Length of the held-out simulation windows [s].
    guard : float
        Data left out of training on each side of a held-out block [s] (the
        prefilter's reach).
    interval : float
        Interval length of the integral method [s].

    Raises
    ------
    IdentifiabilityError
        Fewer windows than folds, or training blocks too short for the integral method.
    """

    def __init__(self, flight: Flight, folds: int = 5, window: float = 4.0, guard: float = 0.5,
                 interval: float = 1.0):
        self.flight = flight
        self.folds = int(folds)
        self.interval = float(interval)
        self.length = int(round(window * flight.sample_rate))
        n_windows = (flight.n - 1) // self.length
        if self.folds < 2 or n_windows < self.folds:
            raise IdentifiabilityError(
                f"a {flight.duration:.1f} s flight holds {n_windows} held-out windows of {window:g} s; "
                f"need at least {max(self.folds, 2)} for {self.folds}-fold cross-validation"
            )
        self.starts = np.arange(n_windows) * self.length
        self.fold_of = (np.arange(n_windows) * self.folds) // n_windows  # contiguous blocks of windows
        t = flight.time
        self._train = []
        for k in range(self.folds):
            w = np.flatnonzero(self.fold_of == k)
            lo, hi = t[self.starts[w[0]]] - guard, t[self.starts[w[-1]] + self.length] + guard
            self._train.append([(a, b) for a, b in ((t[0], lo), (hi, t[-1])) if b - a >= 2 * self.interval])
        self._last_aligned = (None, None)  # (shifts, flight): the last alignment scored, kept for its next fit

    @property
    def n_windows(self) -> int:
        return int(self.starts.size)

    def aligned(self, shifts) -> Flight:
        """The flight with its inputs shifted by ``shifts`` (:func:`~identification.preprocess.shift_inputs`).

        Only the last alignment is kept: the specs scored one after the other mostly share it, and a
        shifted copy of a long flight is large.
        """
        key = tuple(float(v) for v in shifts)
        if self._last_aligned[0] != key:
            self._last_aligned = (key, shift_inputs(self.flight, key))
        return self._last_aligned[1]

    def training(self, fold: int, flight: Flight) -> list[Flight]:
        """The training segments of ``fold`` in ``flight`` (everything but the held-out block and its guards)."""
        return [flight.segment(a, b) for a, b in self._train[fold]]

    @staticmethod
    def fit_whole(flight: Flight, spec: Spec, interval: float = 1.0) -> IntegralIdentifier:
        """Fit ``spec`` on a whole (prefiltered) flight, its inputs aligned first."""
        return spec.identifier(interval=interval).fit(shift_inputs(flight, spec.alignment))

    def fit(self, spec: Spec, fold: int | None = None, **kwargs) -> IntegralIdentifier:
        """Fit ``spec`` with the integral method on a fold's training data (``None``: the whole flight)."""
        flight = self.aligned(spec.alignment)
        data = flight if fold is None else self.training(fold, flight)
        return spec.identifier(interval=self.interval, **kwargs).fit(data)

    def score(self, spec: Spec, fold_specs=None) -> Score:
        """Fit on each fold's training data and forward-simulate its held-out windows.

        ``fold_specs`` (one Spec per fold) lets a parameter the fitter does not
        estimate, the time alignment, be chosen on each fold's training data too.
        """
        specs = list(fold_specs) if fold_specs is not None else [spec] * self.folds
        sim = np.empty((3, self.n_windows, self.length))
        params = []
        for k in range(self.folds):
            flight = self.aligned(specs[k].alignment)
            p = self.fit(specs[k], k).params_
            params.append(p)
            w = self.fold_of == k
            sim[:, w] = simulate_windows(p, flight, self.starts[w], self.length)
        idx = self.starts[:, None] + np.arange(1, self.length + 1)[None, :]
        meas = self.flight.rates[:, idx]
        # a model that blows up scores as if it sat at the largest plausible rate
        sim = np.clip(np.nan_to_num(sim, nan=MAX_PLAUSIBLE_RATE), -MAX_PLAUSIBLE_RATE, MAX_PLAUSIBLE_RATE)
        return Score(spec, ((sim - meas) ** 2).mean(axis=2), sim, meas, params)

    def alignment_r2(self, spec: Spec, axis: int, seconds, fold: int | None = None) -> np.ndarray:
        """Integral-fit R² of ``axis`` for each candidate alignment (the servo-delay search, eq. 31).

        Each alignment replaces the axis' alignment in ``spec``; the fit uses one
        iteration of Fig. 5 on the fold's training data (or the whole flight). The shifted flights
        of the search are not kept (:meth:`aligned`).
        """
        names = {axis: spec.terms[axis]}
        out = []
        for s in seconds:
            flight = shift_inputs(self.flight, spec.with_alignment(axis, s).alignment)
            data = flight if fold is None else self.training(fold, flight)
            ident = IntegralIdentifier(structure=names, prefilter=False, interval=self.interval,
                                       axes=(AXES[axis],), max_iter=1)
            try:
                out.append(ident.fit(data).axes_[AXES[axis]].r2)
            except IdentifiabilityError:
                out.append(-np.inf)
        return np.array(out)
