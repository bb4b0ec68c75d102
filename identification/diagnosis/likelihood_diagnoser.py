"""Diagnosis by likelihood: which physical effect the model misses, from the innovations of the wind-state model.

:class:`LikelihoodDiagnoser` is the maximum-likelihood counterpart of
:class:`identification.diagnosis.heldout_diagnoser.Diagnoser`. Per axis it fits the current structure
with the filter-error estimator (:mod:`identification.likelihood.estimator`: a slow and a fast
stochastic gust, white gyro noise, the linear parameters projected out), then every
candidate of the catalogue (:mod:`identification.diagnosis.effects`) on that axis: its terms
added (cross-coupling k4·q, gyroscopic k1·q·r, collective torque, quadratic damping
p|p|, gain scheduling u·δo) or, for ``servo_delay``, the command/response alignment
profiled from ``-MAX_ALIGNMENT`` to +0.5 s (a positive value is the Padé servo delay
of eq. 31, a negative one a log whose input column lags the response), and, behind a servo
delay found, ``servo_lag``, the servo's first-order lag (eq. 31 with the lag in ``d1``; a lag
shows first as a delay, which the lag then shortens). Each candidate
is scored by the likelihood-ratio statistic ``LR = 2 (NLL_base - NLL_candidate)``
and accepted when ``LR`` exceeds the chi-square quantile of its number of added
parameters at ``1 - alpha/m`` (Bonferroni over the ``m`` candidates tried on the axis)
**and** when ``LR`` per added parameter is at least ``min_lr_per_parameter`` (terms) or
``min_lr_alignment`` (the alignment and the servo lag, where the model is misspecified in small timing
ways the chi-square law does not know; both floors calibrated on flights without a
missing effect), **and** when the fitted terms are physical (:data:`identification.diagnosis.effects.PHYSICAL_BOUNDS`:
an inertia ratio within [-1, 1], a positive quadratic damping; an alignment not pinned
at the edge of its search). Because the gust is a
state of the model, a pilot who fights it does not bias the comparison: the
innovations are white whether the loop is open or closed.

The best accepted candidate per axis is added, the axes that changed are fitted
again, and the search repeats until nothing more is accepted (at most ``max_rounds``).
Each step reports the statistic, the runner-up and its statistic, and the one-step,
0.5 s-ahead and simulation (sticks only) R² before and after. Each axis also reports
how much of its stick the past attitude and rate explain (the share closed by the
pilot or a flight controller); the estimator is consistent either way, and the
report says so instead of reading feedback as a physical effect.

The verdict is ``undecided`` when the flight is shorter than ``min_duration``.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats
from threadpoolctl import threadpool_limits

from heli_core.params import ModelParams
from heli_core.terms import AXES, DECOUPLED, RATE_DEPENDENCE, STICK_ROW, TERMS

from ..excitation import on_static_input, static_collective
from ..flight import Flight
from ..likelihood.axis_pool import check_workers, in_worker, map_axes
from ..likelihood.axis_search import BURN_IN
from ..likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier
from ..likelihood.input_hold import check_hold
from ..likelihood.state_space import WIND_MODELS
from ..preprocess import shift_inputs
from .axis_scores import NFEV, RESOLUTION_SAMPLES, AxisScore, FlightScorer, fresh_start, predicts_worse
from .effects import CATALOGUE, NONE, SERVO_DELAY, SERVO_LAG, UNDECIDED, DiagnosisResult

ALPHA = 0.01
"""Family-wise level of the likelihood-ratio test per axis and round (Bonferroni over the candidates)."""
MIN_LR_PER_PARAMETER = 12.0
"""Smallest likelihood-ratio statistic per added term accepted. On effect-free flights the term candidates'
statistics follow the chi-square law of one degree of freedom per term (70 flights of 180 s over every bench
cell: the median of a flight's largest of its ~14 term statistics 3.5, chi-square's 4.3), and a flight's largest
reached 10.2 and 10.5 (two 2 Hz Dryden flights of 20, each naming a wrong effect at the earlier floor of 10:
10 % of the cell, above the issue's 5 %). At 12 a flight of 14 chi-square statistics names a wrong term with
probability 0.7 %. A hidden effect's statistic grows with the flight's length: on 300 s flights of fresh seeds
the weakest of the study scored 12.8 (collective torque) and 14.0 (5x quadratic damping), every case named 6/6,
and 0 of 50 effect-free flights named a wrong term; on 180 s flights some axes of those effects scored 10.3-12,
which this floor no longer names (docs/diagnosis.md; ``scripts/likelihood_diagnosis_study.py --null-cells``
prints the statistics)."""
MIN_LR_ALIGNMENT = 20.0
"""Smallest likelihood-ratio statistic of the alignment candidate (servo delay / input shift). Timing is where
the model is misspecified in small ways the chi-square law does not know (a hold between samples, a digital
controller's sample of lag): on effect-free flights its statistic reaches 12.2, hence the higher floor."""
MIN_DURATION = 60.0
"""Shortest flight a diagnosis decides on [s]."""


@dataclass
class LikelihoodStep:
    """One accepted effect: the statistic, the runner-up and the R² before and after."""

    round: int
    axis: str
    effect: str
    parameters: dict
    lr: float
    threshold: float
    runner_up: str | None
    runner_up_lr: float | None
    r2_before: dict
    r2_after: dict

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def closed_loop_share(flight: Flight, axis: int, lags=(0.1, 0.2, 0.3, 0.5)) -> float:
    """Share of an axis' stick variance explained by the attitude and rate seen ``lags`` seconds before.

    A pilot or a flight controller holding the attitude makes the stick a function of
    the past response; sweeps and jitter are what it does not explain.
    """
    fs = flight.sample_rate
    k = [int(round(s * fs)) for s in lags]
    kmax = max(k)
    stick = flight.sticks[STICK_ROW[axis]][kmax:]
    cols = [np.ones(stick.size)]
    for lag in k:
        cols.append(flight.attitude[axis][kmax - lag:flight.n - lag])
        cols.append(flight.rates[axis][kmax - lag:flight.n - lag])
    X = np.array(cols).T
    coef = np.linalg.lstsq(X, stick, rcond=None)[0]
    resid = stick - X @ coef
    var = float(np.var(stick))
    return float(1.0 - np.var(resid) / var) if var > 0 else 0.0


def _starting_structure(model: ModelParams | None) -> tuple[dict, list, list]:
    """Per axis the terms the diagnosis starts from (the paper's decoupled model, or ``model``'s nonzero
    terms), the alignments (``model``'s servo delays) and the servo lags (``model``'s)."""
    structure = {a: tuple(DECOUPLED[a]) for a in range(3)}
    if model is None:
        return structure, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    values = model.values()
    for a in range(3):
        structure[a] = tuple(p for p, v in values.items() if TERMS[p].axis == a and (v != 0.0 or p in DECOUPLED[a]))
    return structure, list(model.taus), list(model.lags)


BASE_TIMING_SAMPLES = 1.5
"""A servo delay the hold's fit detects (as ``heli identify`` does) shorter than this many samples starts the
base of the candidates (:meth:`LikelihoodDiagnoser._decide_hold`): the log's convention reaches a sample of
stamping and half a sample of hold, and no delay that short is named (:data:`~.axis_scores.RESOLUTION_SAMPLES`,
2). Between 1.5 and 2 samples the alignment candidate decides, as before: with a bound of 2 samples a true 20 ms
pitch delay at 100 Hz, detected at 19.6-19.7 ms, was no longer named on 2 of the 4 bench flights that named it;
the final fit keeps such a delay where it is not named (:meth:`LikelihoodDiagnoser._final_fit`)."""


def _row(rnd: int, axis: str, effect: str, k: int, sc: AxisScore, lr: float, threshold: float, accepted: bool,
         why: str | None, **extra) -> dict:
    """One candidate's row of a round (:attr:`LikelihoodDiagnoser.rounds_`, the report's table)."""
    return {"round": rnd, "axis": axis, "effect": effect, "lr": float(lr), "threshold": threshold, "n_parameters": k,
            "alignment_s": sc.alignment, "lag_s": sc.lag, "accepted": accepted, **extra, "implausible": why}


class LikelihoodDiagnoser(DiagnosisResult):
    """Name the physical effect a model misses by the likelihood of the wind-state model (module docstring).

    Parameters
    ----------
    alpha : float
        Family-wise level per axis and round, Bonferroni-divided among the candidates.
    min_lr_per_parameter : float
        Floor on the likelihood-ratio statistic per added term.
    min_lr_alignment : float
        Floor on the likelihood-ratio statistic of the alignment (servo delay / input shift) candidate.
    max_rounds : int
        Largest number of add-and-refit rounds.
    min_duration : float
        Shortest flight decided on [s].
    input_hold : "auto", "linear", "zoh" or float in [0, 1]
        Sticks between samples (see :class:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier`);
        ``"auto"`` decides the log's hold once, fitted with every other parameter on the structure with every
        candidate's terms in (:meth:`_decide_hold`), and holds it for the base and the candidates alike, so
        that a hold is never read as an effect nor an effect as a hold.
    axes : sequence of str
        Axes diagnosed.
    progress : callable or None
        Called with a few words as each step of the fit starts (``"round 1, roll: trying cross_coupling"``),
        e.g. to show progress; None (default) shows nothing.
    workers : int or None
        Processes the axes are fitted and their candidates scored in, side by side
        (:mod:`identification.likelihood.axis_pool`; the result is the same bit for bit): None (default) the
        cores other work leaves idle, or ``HELI_WORKERS``; 1 one after another.

    Attributes
    ----------
    verdict_ : str
        ``"none"``, ``"undecided"`` or ``"found"``.
    effects_found_ : list of (str, str)
        (effect, axis) added.
    steps_ : list of LikelihoodStep
    rounds_ : list of list of dict
        Every candidate's statistic per round.
    closed_loop_ : dict of str to float
        Per axis, the share of the stick explained by the past attitude and rate.
    flight_ : Flight
        The flight as diagnosed (vibration lines removed), which the report reads.
    baseline_ : dict of str to AxisScore
    final_ : dict of str to AxisScore
    params_ : ModelParams
        The final model (terms added, delays as servo delays), fitted on the flight.
    alignment_ : tuple of 3 float
        Final alignment per axis [s] (> 0 servo delay, < 0 input shift of the log).
    timing_detected_ : dict of str to float
        Axes whose servo delay [s], shorter than the timing resolution, was detected as ``heli identify`` detects
        it and kept without a named effect: in the base of the candidates (:meth:`_decide_hold`) or in the final
        fit (:meth:`_final_fit`). The model's timing, not a diagnosis.
    input_hold_ : str or float
        The hold used (with ``"auto"``, the fraction decided).
    hold_decision_ : dict or None
        With ``"auto"``: the decision (:func:`identification.likelihood.input_hold.decide_hold`).
    hold_fractions_ : dict of str to float
        Per diagnosed axis, the final model's hold fraction (0 held over the sample, 1 interpolated).
    evidence_ : dict
    fit_time_ : float
    """

    def __init__(self, alpha: float = ALPHA, min_lr_per_parameter: float = MIN_LR_PER_PARAMETER,
                 max_rounds: int = 3, min_duration: float = MIN_DURATION, input_hold: str = "auto", axes=AXES,
                 min_lr_alignment: float = MIN_LR_ALIGNMENT, progress=None, workers=None):
        self.alpha = alpha
        self.min_lr_per_parameter = min_lr_per_parameter
        self.min_lr_alignment = min_lr_alignment
        self.max_rounds = max_rounds
        self.min_duration = min_duration
        self.input_hold = input_hold
        self.axes = axes
        self.progress = progress
        self.workers = workers

    def _say(self, text: str) -> None:
        if self.progress is not None and not in_worker():  # a worker's axis: the caller's line stands
            self.progress(text)

    def _check(self):
        if not 0.0 < self.alpha < 1.0:
            raise ValueError(f"alpha must lie in (0, 1), got {self.alpha!r}")
        for name in ("min_lr_per_parameter", "min_lr_alignment"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if not (isinstance(self.max_rounds, (int, np.integer)) and self.max_rounds >= 1):
            raise ValueError(f"max_rounds must be a whole number >= 1, got {self.max_rounds!r}")
        check_hold(self.input_hold)
        check_workers(self.workers)
        bad = [a for a in self.axes if a not in AXES]
        if bad or not self.axes:
            raise ValueError(f"axes must be a non-empty subset of {AXES}, got {self.axes!r}")

    # ------------------------------------------------------------------ fitting pieces
    # ------------------------------------------------------------------ fit
    def fit(self, flight: Flight, model: ModelParams | None = None) -> "LikelihoodDiagnoser":
        """Diagnose ``model``'s structure (default: the paper's decoupled model) against ``flight``."""
        t0 = _time.perf_counter()
        self._check()
        with threadpool_limits(limits=1, user_api="blas"):  # small matrices, long 1-D filters
            self._fit(flight, model)
        self.fit_time_ = _time.perf_counter() - t0
        return self

    def _fit(self, flight: Flight, model: ModelParams | None):
        self.steps_, self.rounds_, self.effects_found_ = [], [], []
        self.evidence_ = {}
        self.input_hold_ = self.input_hold
        self.hold_fractions_ = {}
        self.hold_decision_ = None
        self.timing_detected_ = {}
        ident = MaximumLikelihoodIdentifier(input_hold=self.input_hold_, workers=self.workers)
        cleaned, _ = ident._clean(flight)
        self.flight_ = cleaned
        fs = flight.sample_rate
        self._scores = FlightScorer(ident, cleaned, int(round(BURN_IN * fs)), fs)
        structure, alignment, lags = _starting_structure(model)
        collective = static_collective(cleaned)
        self._static = collective is not None
        self.untestable_ = {}
        if self._static:  # a collective that never moves: its terms are the offset or the gain again
            structure = {a: tuple(p for p in names if not on_static_input(p, True)) for a, names in structure.items()}
            for name, effect in CATALOGUE.items():
                if any(on_static_input(p, True) for a in range(3) for p in effect.terms_on(a)):
                    self.untestable_[name] = (f"the collective does not vary in this flight (std {round(collective, 6):g}): "
                                              "its terms are the offset or the control gain under another name")
        self.closed_loop_ = {AXES[a]: closed_loop_share(flight, a) for a in range(3)}
        if flight.duration < self.min_duration:
            self.verdict_ = UNDECIDED
            self.evidence_ = {"reason": f"flight of {flight.duration:.1f} s is shorter than {self.min_duration:g} s"}
            self.baseline_ = self.final_ = {}
            self.params_ = model or ModelParams()
            self.alignment_, self.lags_ = tuple(alignment), tuple(lags)
            return
        if self.input_hold == "auto":
            self._say("deciding how the sticks move between samples, every candidate term in")
            alignment = self._decide_hold(cleaned, structure, alignment, lags)
        self._say(f"fitting the starting structure on {', '.join(self.axes)}")
        current = self._baseline(cleaned, structure, alignment, lags)
        self.baseline_ = dict(current)
        todo = list(self.axes)
        for rnd in range(1, self.max_rounds + 1):
            rows = []
            todo = self._round(rnd, todo, current, rows)
            self.rounds_.append(rows)
            if not todo:
                break
        self.final_ = current
        named = {a for e, a in self.effects_found_ if e in (SERVO_DELAY, SERVO_LAG)}  # its timing is the effect's
        self.timing_detected_ = {**{a: v for a, v in self.timing_detected_.items() if a not in named},
                                 **{a: float(current[a].alignment) for a in self._timing_taken() if a not in named}}
        self.alignment_ = tuple(current[a].alignment if a in current else alignment[i] for i, a in enumerate(AXES))
        self.lags_ = tuple(current[a].lag if a in current else lags[i] for i, a in enumerate(AXES))
        self._say("fitting the final structure")
        self._final_fit(cleaned, current)
        self.verdict_ = "found" if self.steps_ else NONE

    def _fit_structure(self, cleaned: Flight, structure: dict, alignment, lags, axes, hold,
                       timing: dict | None = None) -> MaximumLikelihoodIdentifier:
        """``structure`` fitted in full by maximum likelihood on the cleaned flight at ``alignment`` (positive:
        servo delays; negative: the sticks advanced) and servo ``lags``, the input's ``hold`` as given; or, with
        ``timing`` (the estimator's ``delay`` and ``servo_lag`` settings), at the timing they find."""
        timing = timing or {"delay": [max(v, 0.0) for v in alignment], "servo_lag": list(lags)}
        est = MaximumLikelihoodIdentifier(structure=structure, axes=axes, input_hold=hold,
                                          remove_vibration=False,  # cleaned already
                                          workers=self.workers, **timing)
        shifts = [min(v, 0.0) for v in alignment]
        est._fit([shift_inputs(cleaned, shifts) if min(shifts) < 0 else cleaned])
        return est

    def _decide_hold(self, cleaned: Flight, structure: dict, alignment: list, lags: list) -> None:
        """The log's hold decided once (:func:`identification.likelihood.input_hold.decide_hold`) on the structure with
        every testable candidate term added, then held for the base and every candidate alike. Estimated on
        the base alone, a missing effect moved it (a hidden quadratic damping drew a pilot's interpolated
        sticks to fractions 0.33-0.45, and its pitch statistic below the floor); with the effect's terms in,
        nothing is missing for it to stand in for. The timing likewise: a servo's delay or lag left out drew the
        hold to the held stick (half a sample later), on a 40 ms lag flight to 0 where the sticks were
        interpolated, and a quadratic damping or gain scheduling then took up what the lag and hold left; so
        where the starting model has no servo timing, the log's is detected as ``heli identify`` does
        (:data:`~identification.likelihood.estimator.CLI_TIMING`; only the hold is kept: the timing is the
        candidates' to name; the delay detected without its lag left the hold at 0 on that flight).

        Returns the alignments the base starts from: the starting model's, and on an axis where that fit
        detected a servo delay shorter than :data:`BASE_TIMING_SAMPLES` without a lag, that delay
        (:attr:`timing_detected_`). Such a delay cannot be named (it cannot be told from the log's convention),
        and left out of the base something else stood in for it: a 12.5 ms yaw servo behind 20 ms ones on roll and
        pitch (the catalogue's delays x 0.25) was named quadratic damping on 5 of 5 flights, and the model
        written had its dampings 42-52 % RMS low."""
        full = {a: tuple(dict.fromkeys(structure[a] + tuple(
                    p for name, effect in CATALOGUE.items() if name not in self.untestable_
                    for p in effect.terms_on(a)))) for a in range(3)}
        timing = None if any(alignment) or any(lags) else CLI_TIMING
        est = self._fit_structure(cleaned, full, alignment, lags, self.axes, "auto", timing)
        self.input_hold_ = float(est.hold_decision_["fraction"])
        self.hold_decision_ = est.hold_decision_
        self._scores.ident = MaximumLikelihoodIdentifier(input_hold=self.input_hold_, workers=self.workers)
        if timing is None:
            return alignment
        self.timing_detected_ = {axis: float(fit.delay) for axis, fit in est.axes_.items()
                                 if 0.0 < fit.delay < BASE_TIMING_SAMPLES / cleaned.sample_rate and fit.lag == 0.0}
        return [self.timing_detected_.get(axis, v) for axis, v in zip(AXES, alignment)]

    def _baseline(self, cleaned: Flight, structure: dict, alignment: list, lags: list) -> dict:
        """Each diagnosed axis' starting structure fitted in full, scored by the candidates' likelihood."""
        start = self._fit_structure(cleaned, structure, alignment, lags, self.axes, self.input_hold_)
        current = {}
        for axis in self.axes:
            a = AXES.index(axis)
            fit = start.axes_[axis]  # the same likelihood as the candidates': evaluated here, on the same data
            current[axis] = self._scores.score(a, structure[a], alignment[a], fit.state, (fit.wind["model"],), 0,
                                               lag=lags[a])
        return current

    def _round(self, rnd: int, todo: list, current: dict, rows: list) -> list:
        """One round on the axes of ``todo``, side by side (:mod:`identification.likelihood.axis_pool`: an axis'
        candidates depend on its own fit only), merged in the axes' order. Returns the axes that changed."""

        def one(axis):
            n_steps, n_found = len(self.steps_), len(self.effects_found_)
            mine, own_rows = dict(current), []
            changed = self._round_on_axis(rnd, axis, mine, own_rows)
            out = changed, mine[axis], own_rows, self.steps_[n_steps:], self.effects_found_[n_found:]
            del self.steps_[n_steps:], self.effects_found_[n_found:]  # merged below, as a worker's would be
            return out

        waiting = list(todo)

        def finished(axis):
            waiting.remove(axis)
            if waiting:
                self._say(f"round {rnd}: {axis} done, every candidate on {', '.join(waiting)}")

        if len(todo) > 1:
            self._say(f"round {rnd}: every candidate on {', '.join(todo)}")
        changed = []
        for axis, (moved, score, own_rows, steps, found) in zip(todo, map_axes(one, todo, self.workers, finished)):
            current[axis] = score
            rows += own_rows
            self.steps_ += steps
            self.effects_found_ += found
            if moved:
                changed.append(axis)
        return changed

    def _round_on_axis(self, rnd: int, axis: str, current: dict, rows: list) -> bool:
        """One round on one axis: every candidate scored into ``rows``, the best accepted one added to
        ``current``. True when the axis changed."""
        a = AXES.index(axis)
        base = current[axis]
        # the base searched with the candidates' budget too, so that a candidate gains only by its terms;
        # a servo delay found earlier is searched again with the rest (and with every candidate)
        # and from the fresh start the alignment candidate also gets (else that start alone could
        # win it a likelihood ratio), with every gust model (switching models alone cannot win LR)
        free_tau = any((e, axis) in self.effects_found_ for e in (SERVO_DELAY, SERVO_LAG))
        self._say(f"round {rnd}, {axis}: refitting the base")
        tries = [base] + [self._scores.score(a, base.names, base.alignment, start, WIND_MODELS, 3 * NFEV, free_tau,
                                             base.lag) for start in (base.x, fresh_start(base.x))]
        base = current[axis] = self._scores.describe(a, min(tries, key=lambda sc: sc.nll))
        cands = self._candidates(a, axis, base, free_tau, rnd)
        log_timed = self._log_timed(axis, base, free_tau)
        found = self._log_timing(cands) if log_timed else None
        timing = None if found is None else found[2]
        if found is not None:  # the log's timing, fitted: every candidate scored again from it
            name, k, sc, lr = found
            rows.append(_row(rnd, axis, name, k, sc, lr, self.threshold(len(cands), k, alignment=True), False,
                             f"the delay {1e3 * sc.alignment:.1f} ms is shorter than {RESOLUTION_SAMPLES} samples, "
                             "the log's timing, not a servo: the base takes it and every candidate is scored "
                             "again from it", base_timing=True))
            self._say(f"round {rnd}, {axis}: the log's timing {1e3 * sc.alignment:.1f} ms in the base, every "
                      "candidate again")
            base = current[axis] = self._scores.describe(a, timing)
            cands = self._candidates(a, axis, base, free_tau, rnd, alignment=timing)
        m = max(len(cands), 1)
        scored = []
        delay = next((sc for name, _, sc, _ in cands if name == SERVO_DELAY), None)
        for name, k, sc, lr in cands:
            if timing is not None and name == SERVO_DELAY:
                continue  # the base's own timing (its row above), the lag's reference below
            lagged = CATALOGUE[name].is_servo_lag
            thr = self.threshold(m, k, alignment=CATALOGUE[name].is_alignment or lagged)
            behind = delay if lagged else None  # a lag counts what it adds to the round's delay candidate
            # a servo's timing is read from nought where the base's is the log's (a delay of two samples in all
            # is named, however near the log's timing was): a 20 ms yaw servo detected at 14.9 ms, its candidate
            # at 20.1 ms, was refused as a 5 ms move, and the model written kept 14.9 ms (k11 -19 %)
            origin = replace(base, alignment=0.0) if log_timed and (lagged or CATALOGUE[name].is_alignment) else base
            why = self._scores.implausible(a, origin, sc, lagged, behind, self.min_lr_alignment)
            if why is None:  # an unphysical fit is reported, never accepted nor runner-up
                scored.append((lr / thr, name, k, sc, lr, thr))
            rows.append(_row(rnd, axis, name, k, sc, lr, thr, bool(lr > thr and why is None), why))
        scored.sort(key=lambda r: -r[0])
        after = None
        while scored and scored[0][0] > 1.0:
            self._say(f"round {rnd}, {axis}: checking {scored[0][1]}'s prediction")
            after = self._scores.describe(a, scored[0][3])
            of_rates = any(TERMS[p].feature in RATE_DEPENDENCE for p in scored[0][3].names if p not in base.names)
            worse = predicts_worse(base.r2, after.r2, of_rates)
            if worse is None:
                self._say(f"round {rnd}, {axis}: checking {scored[0][1]} on held-out blocks")
                self._scores.heldout(a, base)
                self._scores.heldout(a, after)
                if after.r2["heldout_0.5s"] is not None:
                    worse = predicts_worse(base.r2, after.r2, of_rates, "heldout_0.5s", " on held-out blocks")
            if worse is None:
                break
            row = next(r for r in rows if r["effect"] == scored[0][1] and r["axis"] == axis)
            row["accepted"], row["implausible"] = False, worse
            scored.pop(0)
            after = None
        if after is None:
            return False
        _, name, k, sc, lr, thr = scored[0]
        runner = scored[1] if len(scored) > 1 else None
        added = {p: v for p, v in after.params.items() if p not in base.names}
        if name == SERVO_DELAY:
            added = {"alignment_s": after.alignment}
        elif name == SERVO_LAG:
            added = {"lag_s": after.lag, "alignment_s": after.alignment}
        self.steps_.append(LikelihoodStep(rnd, axis, name, added, float(lr), thr, runner[1] if runner else None,
                                          float(runner[4]) if runner else None, dict(base.r2), dict(after.r2)))
        self.effects_found_.append((name, axis))
        current[axis] = after
        return True

    def _log_timed(self, axis: str, base: AxisScore, free_tau: bool) -> bool:
        """Whether the base's timing on ``axis`` is the log's (nought, the delay the hold's fit detected, or one
        :meth:`_log_timing` took), not a servo's (one named, or the starting model's)."""
        return not free_tau and (base.alignment == 0.0 or axis in self.timing_detected_ or axis in self._timing_taken())

    def _timing_taken(self) -> set:
        """The axes whose base took the log's timing (:meth:`_log_timing`) in the rounds so far."""
        return {r["axis"] for rows in self.rounds_ for r in rows if r.get("base_timing")}

    def _log_timing(self, cands: list) -> tuple | None:
        """On an axis whose base carries the log's timing (:meth:`_log_timed`), the alignment candidate of
        ``cands`` (its ``(effect, added parameters, score, LR)``) where it is that timing, better placed: a positive
        delay shorter than the timing resolution in all (never named, :data:`~.axis_scores.RESOLUTION_SAMPLES`)
        that the likelihood prefers past the alignment's threshold.
        Left at the base's detected timing, the difference went to a term: a 20 ms yaw servo detected at
        13.5 ms gave a 18.8 ms candidate LR 86, and quadratic damping LR 13.3 (above its floor of 12) where, from
        18.8 ms, it scored 1.4."""
        found = next((c for c in cands if c[0] == SERVO_DELAY), None)
        if found is None:
            return None
        _, k, sc, lr = found
        resolution = RESOLUTION_SAMPLES / self.flight_.sample_rate
        if not 0.0 < sc.alignment < resolution or lr <= self.threshold(len(cands), k, alignment=True):
            return None
        return found

    def _candidates(self, a: int, axis: str, base: AxisScore, free_tau: bool, rnd: int = 0,
                    alignment: AxisScore | None = None) -> list:
        """``(effect, added parameters, score, LR)`` of every catalogue candidate on an axis (``alignment``: the
        alignment candidate's score, when it is known already: the base's own timing, :meth:`_log_timing`)."""
        cands, delay = [], None
        for name, effect in CATALOGUE.items():
            if effect.is_alignment or effect.is_servo_lag:
                if (name, axis) in self.effects_found_:
                    continue  # found in an earlier round: refined in the final fit, not added twice
                start = base
                if effect.is_servo_lag and base.alignment <= 0.0:
                    # a lag shows first as a delay: tried behind this round's delay where that one is positive
                    # but shorter than the timing resolution (a 30 ms lag on a fast yaw, sticks held: 15 ms)
                    ok = delay is not None and delay.alignment > 0.0 and self._scores.below_resolution(base, delay)
                    if not ok:
                        continue
                    start = delay
                self._say(f"round {rnd}, {axis}: trying {name}")
                sc = ((alignment or self._scores.alignment_candidate(a, base)) if effect.is_alignment
                      else self._scores.lag_candidate(a, start))
                delay = sc if effect.is_alignment else delay
                k = 1 if start is base else 2  # behind a delay not yet added: the delay and the lag
            else:
                add = tuple(p for p in effect.terms_on(a) if p not in base.names)
                if not add or name in self.untestable_:
                    continue
                self._say(f"round {rnd}, {axis}: trying {name}")
                sc = self._scores.score(a, base.names + add, base.alignment, base.x, (base.kind,), NFEV, free_tau,
                                        base.lag)
                k = len(add)
            cands.append((name, k, sc, 2.0 * (base.nll - sc.nll)))
        return cands

    def _final_fit(self, cleaned: Flight, current: dict):
        """The final structure fitted in full (every search to convergence) on the aligned flight; a delay
        found stays as found (searching it again would change the structure's meaning).

        An axis with no timing of its own (none named, none in the starting model) has its servo delay
        detected as ``heli identify`` detects it (``delay="detect"``) and kept where it is shorter than the
        timing resolution (:data:`~.axis_scores.RESOLUTION_SAMPLES`): such a delay is not named, since it cannot
        be told from the log's convention, but left out of the model written it biases the damping (a 12.5 ms
        yaw servo: k11 28 % low where ``heli identify`` had it 5 % high). A longer delay, or a stick logged
        late, is the alignment candidate's to name: where it was not named (the T-REX's yaw, refused because
        it predicts worse), the axis is fitted at the log's timing. The delays kept are
        :attr:`timing_detected_`."""
        structure = {AXES.index(a): sc.names for a, sc in current.items()}
        open_axes = [a for i, a in enumerate(AXES) if a in current and self.alignment_[i] == 0.0
                     and self.lags_[i] == 0.0]
        delays = [CLI_TIMING["delay"] if a in open_axes else max(v, 0.0) for a, v in zip(AXES, self.alignment_)]
        final = self._fit_structure(cleaned, structure, self.alignment_, self.lags_, tuple(current),
                                    self.input_hold_, {"delay": delays, "servo_lag": list(self.lags_)})
        resolution = RESOLUTION_SAMPLES / cleaned.sample_rate
        unnamed = [a for a in open_axes if final.axes_[a].input_shift < 0.0 or final.axes_[a].delay >= resolution]
        if unnamed:  # the candidates' to name, and they did not: the log's timing
            delays = [0.0 if a in unnamed else v for a, v in zip(AXES, delays)]
            final = self._fit_structure(cleaned, structure, self.alignment_, self.lags_, tuple(current),
                                        self.input_hold_, {"delay": delays, "servo_lag": list(self.lags_)})
        found = {a: float(final.axes_[a].delay) for a in open_axes if final.axes_[a].delay > 0.0}
        self.timing_detected_ = {**self.timing_detected_, **found}
        self.alignment_ = tuple(found.get(a, v) for a, v in zip(AXES, self.alignment_))
        self.identifier_ = final
        self.params_ = final.params_
        self.hold_fractions_ = {axis: fit.input_hold for axis, fit in final.axes_.items()}

    def threshold(self, m: int, k: int, alignment: bool = False) -> float:
        """Acceptance threshold of a candidate adding ``k`` parameters among ``m`` tried on the axis (the
        alignment candidate has its own floor)."""
        floor = self.min_lr_alignment if alignment else self.min_lr_per_parameter
        return max(float(stats.chi2.ppf(1.0 - self.alpha / m, k)), floor * k)

    def summary(self) -> dict:
        """JSON-ready verdict, steps, candidates per round, closed-loop shares and R² per axis."""
        return self._summary_head() | {
            "rounds": self.rounds_,
            "closed_loop_share": self.closed_loop_,
            "input_hold": self.input_hold_,
            "hold_fractions": self.hold_fractions_,
            "hold_decision": self.hold_decision_,
            "untestable": getattr(self, "untestable_", {}),
            "alignment_s": dict(zip(AXES, self.alignment_)),
            "servo_lag_s": dict(zip(AXES, self.lags_)),
            "timing_detected": self.timing_detected_,
            "r2_before": {a: s.r2 for a, s in self.baseline_.items()},
            "r2_after": {a: s.r2 for a, s in self.final_.items()},
            "evidence": self.evidence_,
            "criterion": {"alpha": self.alpha, "min_lr_per_parameter": self.min_lr_per_parameter,
                          "min_lr_alignment": self.min_lr_alignment,
                          "rule": "LR = 2 (NLL_base - NLL_candidate) > max(chi2_k(1 - alpha/m), "
                                  "min_lr_per_parameter * k) (min_lr_alignment for the alignment), and the "
                                  "fitted terms within their physical bounds"},
            "fit_time_s": self.fit_time_,
        }

