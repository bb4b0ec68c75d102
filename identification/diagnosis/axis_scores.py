"""What the likelihood diagnosis scores on one axis of the flight: a structure at an alignment (its likelihood),
how well it predicts (one step, 0.5 s ahead, on held-out blocks, sticks only) and whether its fitted terms can
be physical.

:class:`identification.diagnosis.likelihood_diagnoser.LikelihoodDiagnoser` decides which candidate of the
catalogue to add, round by round; every number it decides on is an :class:`AxisScore` of the
:class:`FlightScorer` of its flight, which searches the structure's likelihood
(:class:`~identification.likelihood.axis_search.AxisProblem`) at the diagnosis' budget.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from heli_core.terms import TERMS

from ..flight import Flight
from ..likelihood.ahead_prediction import ahead_r2, blocked_ahead_r2
from ..likelihood.ahead_score import AHEAD_S
from ..likelihood.axis_likelihood import MIN_SERVO_DELAY, AxisLikelihood
from ..likelihood.axis_search import MAX_DELAY, MAX_SHIFT, AxisProblem
from ..likelihood.estimator import MIN_PROFILE_DAMPING, NOMINAL_DAMPING, MaximumLikelihoodIdentifier
from ..likelihood.servo_lag import LAG_GRID, bracketed_minimum
from ..likelihood.state_space import HOLD_INDEX, WIND_MODELS, concentrated_nll
from ..preprocess import shift_inputs
from .effects import MAX_ALIGNMENT, implausible

ALIGNMENT_GRID = np.round(np.arange(-MAX_ALIGNMENT, 0.5001, 0.025), 4)
"""Alignments the ``servo_delay`` candidate profiles [s]; the best is refined to 1 ms."""

MAX_GAIN_RATIO = 3.0
"""Largest factor a fitted gain scheduling may change the control gain by over the flight's collective range
(a rotor's control power grows with its load, not several-fold within one flight)."""

AHEAD_R2_TOLERANCE = (0.002, 0.05)
"""A candidate that lowers the 0.5 s-ahead prediction R² by more than this is not accepted: a term that
raises the one-step likelihood while the model predicts worse fits the noise or the wind, not the aircraft.
The first for candidates driven by the inputs (an alignment, the collective), whose multi-step prediction is
exact; the second for terms of the measured rates (coupling, gyroscopic, quadratic damping), which the
predictor takes as known inputs rather than propagating them: its R² then moves for reasons of its own (a
true quadratic damping lowered it by 0.037 on a 180 s flight), and only a large drop is read (the T-REX
hover's roll: 0.52 to 0.42)."""

AHEAD_R2_SHARE = 0.25
"""Nor is a candidate that costs more than this share of the base's 0.5 s-ahead R² (where that is the smaller
drop): on an axis the model hardly predicts, a fixed tolerance is no check at all (the T-REX hover's yaw, base
0.058 held out, lost 0.044 of it to a quadratic damping, within the 0.05 of a rate term). Where the base
predicts more than 0.2 (every bench flight) the tolerances above decide alone."""

EDGE_S = 0.01
"""An alignment within this of the searched range's edge [s] is a boundary hit, not a found value."""

RESOLUTION_SAMPLES = 2
"""Smallest alignment change read as a servo delay or an input shift, in samples. Below it the timing is the
log's convention: where each stick is stamped (start or end of its sample, one sample), whether it is held
or interpolated (half a sample), and a flight controller's sample of computation, which a tight loop turns
into a likelihood: on effect-free flights of the autopilot bench cell the alignment found was 10-14 ms at
100 Hz with a statistic of 30-135, against 50-80 ms for the servo delays of the study."""

LAG_SPAN = 2.0
"""The servo-lag candidate profiles lags up to this many times the axis' delay (plus 10 ms): a lag of ``T``
alone was found as a delay of about 0.75 ``T`` (a 40 ms lag, 31 ms)."""

LAG_SCAN_NFEV = 6
"""Likelihood evaluations of each of the servo-lag candidate's profile points (warm-started from the base)."""

NFEV = 12
"""Likelihood searches' evaluation budget per candidate (warm-started from the axis' current fit; each
Jacobian costs one evaluation per nonlinear parameter more)."""

HELDOUT_BLOCKS = 3
"""Contiguous blocks a candidate about to be accepted is checked on, each predicted by the structure fitted on
the others (:func:`~identification.likelihood.ahead_prediction.blocked_ahead_r2`); blocks shorter than
:data:`MIN_BLOCK_S` are not cut, and the check is then left out (the step's ``"heldout_0.5s"`` R² None)."""

MIN_BLOCK_S = 20.0
"""Shortest held-out block [s]."""


@dataclass
class AxisScore:
    """One fitted structure on one axis: its likelihood and how well it predicts."""

    names: tuple
    alignment: float
    nll: float
    x: np.ndarray
    kind: str
    params: dict = field(default_factory=dict)
    r2: dict = field(default_factory=dict)
    lag: float = 0.0


def fresh_start(x) -> np.ndarray:
    """A second start for a search: the damping and hold fraction of ``x`` with the wind model's default
    starting values."""
    return np.array([max(float(x[0]), 0.5), np.log(4.0), np.log(0.3), np.log(100.0), np.log(100.0),
                     float(x[HOLD_INDEX])])


def predicts_worse(before: dict, after: dict, of_rates: bool = False, key: str = "ahead_0.5s",
                    where: str = "") -> str | None:
    """Why a candidate's model predicts worse than the base ``AHEAD_S`` ahead, or None; ``of_rates``: the
    candidate adds terms of the measured rates (:data:`AHEAD_R2_TOLERANCE`, :data:`AHEAD_R2_SHARE`); ``key``
    the R² compared (in the fit, or ``"heldout_0.5s"`` on blocks the fit did not see, ``where`` saying so)."""
    b, c = before.get(key), after.get(key)
    if c is None or not np.isfinite(c):
        return f"its {AHEAD_S:g} s-ahead prediction{where} diverges"
    if b is not None and np.isfinite(b) and c < b - min(AHEAD_R2_TOLERANCE[int(of_rates)],
                                                        AHEAD_R2_SHARE * max(b, 0.0)):
        return f"it lowers the {AHEAD_S:g} s-ahead prediction R²{where} from {b:.3f} to {c:.3f}"
    return None


class FlightScorer:
    """The likelihood scores of structures on the axes of one flight (module docstring).

    Parameters
    ----------
    ident : MaximumLikelihoodIdentifier
        The estimator whose input hold the searches hold (the log's, once decided).
    flight : Flight
        The flight, its vibration lines removed.
    burn : int
        Samples left out of the likelihood at the start.
    fs : float
        The flight's sample rate [Hz].
    """

    def __init__(self, ident: MaximumLikelihoodIdentifier, flight: Flight, burn: int, fs: float):
        self.ident = ident
        self.flight = flight
        self.burn = burn
        self.fs = fs
        self._shift_cache = {}

    def problem(self, a, names, flights) -> AxisProblem:
        """Axis ``a``'s likelihood with the terms ``names`` over ``flights``, its damping searched."""
        return self.ident.axis_problem(a, names, flights, self.burn, free_damping=True)

    def data(self, a, names, alignment, kind, lag=0.0):
        flight = self.shifted(a, alignment)
        tau = max(alignment, 0.0)
        return self.problem(a, names, [flight]).data(tau, kind, lag)

    def shifted(self, a, alignment) -> Flight:
        if alignment >= 0:
            return self.flight
        key = (a, round(alignment, 6))
        if key not in self._shift_cache:
            shifts = [0.0, 0.0, 0.0]
            shifts[a] = alignment
            self._shift_cache[key] = shift_inputs(self.flight, shifts)
        return self._shift_cache[key]

    def score(self, a, names, alignment, x0, kinds, nfev, free_tau=False, lag=0.0) -> AxisScore:
        """The likelihood of a structure, alignment and servo ``lag``: searched from ``x0`` (``nfev``
        evaluations; with ``free_tau`` a positive alignment, the servo delay, is searched too), or at ``x0``
        itself with only the linear parameters solved when ``nfev`` is 0."""
        flight = self.flight if free_tau else self.shifted(a, alignment)
        n = flight.n - self.burn
        if nfev == 0:
            like = AxisLikelihood(self.data(a, names, alignment, kinds[0], lag))
            e = like.residual(np.asarray(x0))
            cost, x, kind = 0.5 * float(e @ e), np.asarray(x0), kinds[0]
        else:
            start = alignment if free_tau else max(alignment, 0.0)
            cost, x, kind, tau = self.problem(a, names, [flight]).best(start, x0, kinds, nfev, free_tau, lag)
            if free_tau:  # within the band where no delay is modelled (0.1 ms) the alignment is none: not a
                alignment = 0.0 if abs(tau) <= MIN_SERVO_DELAY else tau  # shift of the log's input, nor a delay
        nll = concentrated_nll(cost, n)
        return AxisScore(tuple(names), float(alignment), float(nll), np.asarray(x), kind, lag=float(lag))

    def describe(self, a, score: AxisScore) -> AxisScore:
        """Parameters and R² (one step, 0.5 s ahead, sticks-only simulation) of a score."""
        data = self.data(a, score.names, score.alignment, score.kind, score.lag)
        like = AxisLikelihood(data)
        e, theta, S = like.solve_linear(score.x)
        problem = self.problem(a, score.names, [self.shifted(a, score.alignment)])
        fit = problem.result(like, np.array(score.x), (e, theta, S), max(score.alignment, 0.0), score.kind)
        score.params = dict(fit.params)
        score.r2 = {"one_step": fit.prediction_r2,
                    "ahead_0.5s": ahead_r2(like, np.array(score.x), theta, int(round(AHEAD_S * self.fs))),
                    "simulation": fit.r2}
        return score

    def heldout(self, a, score: AxisScore) -> None:
        """Add to ``score.r2`` its ``AHEAD_S``-ahead R² on :data:`HELDOUT_BLOCKS` blocks of the flight, each
        predicted by the structure fitted on the others (``"heldout_0.5s"``; None when the flight is too short
        to cut, the check then left out)."""
        if "heldout_0.5s" in score.r2:
            return
        flight = self.shifted(a, score.alignment)
        if flight.duration / HELDOUT_BLOCKS < MIN_BLOCK_S:
            score.r2["heldout_0.5s"] = None
            return
        edges = np.linspace(flight.time[0], flight.time[-1], HELDOUT_BLOCKS + 1)
        blocks = [flight.segment(edges[i], edges[i + 1]) for i in range(HELDOUT_BLOCKS)]
        with np.errstate(all="ignore"):
            score.r2["heldout_0.5s"] = blocked_ahead_r2(
                self.problem(a, score.names, blocks), max(score.alignment, 0.0), score.x, score.kind, NFEV,
                int(round(AHEAD_S * self.fs)), score.lag)

    def alignment_candidate(self, a, base: AxisScore) -> AxisScore:
        """The best alignment: a scan with the wind and damping held (linear parameters solved), then a
        bounded search around the best with every parameter free."""
        kinds = (base.kind,)
        held = np.array(base.x, dtype=float)
        if held[0] < MIN_PROFILE_DAMPING:  # as the identifier's profile: an unstable base ranks nothing
            held[0] = NOMINAL_DAMPING
        scan = [self.score(a, base.names, float(s), held, kinds, 0, lag=base.lag) for s in ALIGNMENT_GRID
                if abs(s - base.alignment) > 1e-9]
        best = min(scan, key=lambda sc: sc.nll)
        # the scan held the undelayed fit's damping and wind, which a large alignment makes wrong: the
        # alignment (a servo delay, or a shift of the log's input) is then searched with the rest, from the
        # base fit and from a fresh start (the likelihood in the alignment is multimodal), and with every
        # gust model, the best by Akaike as in the identifier: a delay changes which one fits (held at the
        # undelayed choice, a 50 ms yaw delay came out 46 ms, 76 in NLL short, and a quadratic damping
        # made up the difference). The base of each round gets the same choice.
        tries = [self.score(a, base.names, best.alignment, start, WIND_MODELS, 3 * NFEV, True, base.lag)
                 for start in (base.x, fresh_start(base.x))]
        return min(tries, key=lambda sc: sc.nll)

    def lag_candidate(self, a, base: AxisScore) -> AxisScore:
        """The best servo lag behind the axis' servo delay (the candidate is the base itself where no delay was
        found: at low frequency a lag of ``T`` is a delay of about ``T``, so a lag shows first as a delay, and an
        input column that lags the log has no servo). The lags of
        :data:`~identification.likelihood.servo_lag.LAG_GRID` up to :data:`LAG_SPAN` times the delay are
        profiled by short searches (:data:`LAG_SCAN_NFEV` evaluations, the delay searched with the lag from the
        delay found, as :func:`~identification.likelihood.servo_lag.profile_lag` does: a scan with the damping
        held ranked a 40 ms lag below 15 ms, and a delay started at 0 stuck there), the best refined between its
        neighbours (:func:`~identification.likelihood.servo_lag.bracketed_minimum`) and searched with every gust
        model from the base fit and from a fresh start. Where the best is the last lag profiled, the profile
        goes on up :data:`~identification.likelihood.servo_lag.LAG_GRID` until it is not (or the grid ends,
        where the lag is refused as at the edge): a lag never stops at the span's own top."""
        delay = base.alignment
        if delay <= 0.0:
            return base
        grid = [lag for lag in LAG_GRID if lag <= LAG_SPAN * delay + 0.01] or [LAG_GRID[0]]

        def nll(lag):
            return self.score(a, base.names, delay, base.x, (base.kind,), LAG_SCAN_NFEV, True, float(lag)).nll

        profile = [(0.0, base.nll)] + [(lag, nll(lag)) for lag in grid]  # grid: LAG_GRID's first points
        while min(profile, key=lambda p: p[1]) is profile[-1] and len(profile) <= len(LAG_GRID):
            lag = LAG_GRID[len(profile) - 1]  # the best is the last profiled: the next lag up the grid
            profile.append((lag, nll(lag)))
        lag, _ = bracketed_minimum(nll, profile)
        if lag <= 0.0:
            return base
        tries = [self.score(a, base.names, delay, x0, WIND_MODELS, 3 * NFEV, True, lag)
                 for x0 in (base.x, fresh_start(base.x))]
        return min(tries, key=lambda sc: sc.nll)

    def below_resolution(self, base: AxisScore, sc: AxisScore) -> bool:
        """Whether ``sc`` moves the timing of ``base`` by less than :data:`RESOLUTION_SAMPLES`."""
        return abs(sc.alignment - base.alignment) < RESOLUTION_SAMPLES / self.fs

    def implausible(self, a, base: AxisScore, sc: AxisScore, servo_lag: bool = False,
                    behind: AxisScore | None = None, min_lr: float = 0.0) -> str | None:
        """Why a candidate's fitted added terms (its lag with ``servo_lag``, judged over the round's delay candidate
        ``behind`` with ``min_lr`` the floor of its statistic over that delay) cannot be physical
        (:func:`identification.diagnosis.effects.implausible`)."""
        if servo_lag:
            return self._lag_implausible(base, sc, behind, min_lr)
        added = [p for p in sc.names if p not in base.names]
        if not added:  # the alignment candidate: a value pinned at the edge of the search was not found
            edge = MAX_DELAY if sc.alignment > 0 else -MAX_SHIFT
            if abs(sc.alignment - edge) < EDGE_S:
                return (f"alignment {sc.alignment:+.3f} s at the edge of the searched range "
                        f"[{-MAX_SHIFT:g}, {MAX_DELAY:g}] s: no delay or input shift within it explains the data")
            if self.below_resolution(base, sc):
                return (f"alignment {sc.alignment:+.4f} s moves the timing by less than {RESOLUTION_SAMPLES} samples "
                        f"({1e3 * RESOLUTION_SAMPLES / self.fs:.0f} ms), below a log's timing resolution (a stick "
                        "stamped at the start or the end of its sample, held or interpolated, a flight controller's "
                        "sample of computation): not read as a servo delay")
            return None
        data = self.data(a, sc.names, sc.alignment, sc.kind)
        _, theta, _ = AxisLikelihood(data).solve_linear(np.asarray(sc.x))
        values = {nm: float(v) for nm, v in zip(data.names, theta)}
        return implausible({nm: v for nm, v in values.items() if nm in added}) or \
            self._scheduled_gain_implausible(values, added)

    def _lag_implausible(self, base: AxisScore, sc: AxisScore, behind: AxisScore | None,
                         min_lr: float) -> str | None:
        """Why a servo-lag candidate was not found: none beyond the base's, a lag at the top of the grid, a fit
        that moved the input earlier, or a lag that adds less than ``min_lr`` to the round's delay candidate
        ``behind`` (the lag's search moves the delay too, so its statistic over the base holds the delay's move:
        a 0.4 ms lag scored the LR 86 of a 13 -> 18 ms delay's move. Where that delay is shorter than the timing
        resolution it is the log's convention, :data:`RESOLUTION_SAMPLES`, which a lag must not dress up; where
        it is longer, the delay alone explains the data; a supported lag stands behind either)."""
        if sc.lag <= base.lag:
            return "no servo lag improves the fit"
        over = 2.0 * (behind.nll - sc.nll) if behind is not None else np.inf
        if over < min_lr:
            where = ("below the log's timing resolution it stands behind: that timing is the log's convention, not a "
                     "servo" if self.below_resolution(base, behind) else "found without it: the delay alone explains "
                     "the data")
            return f"it adds LR {over:.1f} (needs {min_lr:g}) to the {1e3 * behind.alignment:.1f} ms delay {where}"
        if sc.alignment < 0.0:
            return (f"its fit moved the input {-sc.alignment:.3f} s earlier, where the log's input column lags: no "
                    "servo is left to lag")
        if sc.lag >= LAG_GRID[-1] - 1e-9:
            return (f"servo lag {sc.lag:.3f} s at the top of the searched range (up to {LAG_GRID[-1]:g} s): no "
                    "first-order servo within it explains the data")
        return None

    def _scheduled_gain_implausible(self, values: dict, added) -> str | None:
        """Why a fitted gain scheduling cannot be physical: the control gain it gives changes sign, or by more
        than :data:`MAX_GAIN_RATIO`, over the flight's collective range."""
        for gs in (p for p in added if TERMS[p].effect == "gain_scheduling"):
            gain = next((p for p in values if TERMS.get(p) is not None and TERMS[p].effect == "control"
                         and TERMS[p].axis == TERMS[gs].axis), None)
            if gain is None:
                continue
            col = self.flight.sticks[2]
            lo, hi = float(np.min(col)), float(np.max(col))
            ends = [TERMS[gain].sign * values[gain] + TERMS[gs].sign * values[gs] * c for c in (lo, hi)]
            if ends[0] * ends[1] <= 0.0:
                return (f"{gs} = {values[gs]:.3g} makes the control gain change sign over the flight's collective "
                        f"[{lo:.3g}, {hi:.3g}] ({ends[0]:.3g} to {ends[1]:.3g}): not a rotor's load")
            ratio = max(abs(ends[0]), abs(ends[1])) / min(abs(ends[0]), abs(ends[1]))
            if ratio > MAX_GAIN_RATIO:
                return (f"{gs} = {values[gs]:.3g} changes the control gain {ratio:.1f}-fold over the flight's "
                        f"collective [{lo:.3g}, {hi:.3g}], more than x{MAX_GAIN_RATIO:g}: not a rotor's load")
        return None
