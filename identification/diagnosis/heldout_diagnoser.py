"""Diagnose a model against a flight: locate the disagreement, name the missing effect, add it (issue 6).

The workflow of :class:`Diagnoser`:

1. **Locate.** Fit the current structure with the integral method (Section 2.5.2,
   Fig. 5) and score it on held-out windows by forward simulation
   (:mod:`identification.diagnosis.heldout`; Tables 1-2 of Section 3.2). The residuals —
   forward-simulation and integral (the equation error of eqs. 32-40) — go
   through the classic residual tests of :mod:`identification.diagnosis.residual_tests`
   (whiteness, cross-correlation with every input and state at both lags, error
   per frequency band, worst windows).
2. **Name.** Every effect of the catalogue (:mod:`identification.diagnosis.effects`) on
   every axis it acts on is a candidate: its terms added to the structure (or,
   for ``servo_delay``, the command/response alignment searched from -0.6 to
   +0.6 s, eq. 31), fitted on the training folds, scored on the held-out ones.
3. **Select.** Per axis, a candidate is significant when *both*

   * it lowers the held-out squared error by at least ``min_gain`` (default
     5 %; smaller gains are what wind-fitted parameters give a wrong term on
     flights without a missing effect), and
   * the per-window log ratios ``r_w = log(e_base,w / e_cand,w)`` have a mean
     greater than zero by a one-sided t-test at level ``alpha / m`` (Bonferroni
     over the ``m`` candidates tried on the axis in that round). The windows are
     simulated independently from measured states, so the wind and the sensor
     noise enter as the window-to-window scatter of ``r_w``: the test asks
     whether the improvement is larger than what they explain.

   The significant candidate with the largest gain wins; the runner-up (the next
   best candidate on that axis) and the margin (difference of gains, with the
   same paired test between the two) are reported, and a margin that is not
   significant is flagged.
4. **Add** the winners of all axes to the structure, re-score, and
5. **iterate** on the axes that changed until nothing significant remains.

Reliability. The verdict is ``undecided`` (with the evidence) rather than an
effect when the flight is shorter than ``min_duration`` or holds fewer than
``min_windows`` held-out windows, and an axis is left undecided when even the
best candidate explains less than ``min_r2`` of the held-out rate variance (the
response is then mostly wind, not the pilot's commands) or the axis cannot be
identified at all.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np
from scipy import stats

from heli_core.params import ModelParams
from heli_core.terms import AXES, INPUT_FOR_AXIS

from ..errors import IdentifiabilityError
from ..flight import Flight
from ..preprocess import lowpass_flight, without_folded_lines
from ..validation.forward_simulation import rate_error_stats
from .effects import CATALOGUE, MAX_ALIGNMENT, NONE, UNDECIDED, DiagnosisResult
from .heldout import HeldOut, Score, Spec
from .residual_tests import band_shares, cross_correlation, whiteness

ALPHA = 0.05
"""Family-wise significance level per axis and round (Bonferroni-divided among the candidates)."""
MIN_GAIN = 0.05
"""Smallest relative reduction of the held-out squared rate error accepted as a missing effect."""
MIN_DURATION = 60.0
"""Shortest flight a diagnosis decides on [s]."""
MIN_WINDOWS = 12
"""Fewest held-out windows a diagnosis decides on."""
MIN_R2 = 0.2
"""Smallest share of the held-out rate variance the best candidate must explain for an axis to be decidable."""
TEST_STEP = 0.1
"""Sample step of the residual tests [s] (the prefiltered signals hold nothing above about 4 Hz)."""
TEST_LAGS = 2.0
"""Largest lag of the residual tests [s]."""
COARSE_STEP, FINE_STEP = 0.05, 0.02
"""Grids of the alignment search [s]: coarse over ±MAX_ALIGNMENT on all the data, fine per fold."""


@dataclass
class Candidate:
    """One effect on one axis, fitted and scored on held-out data.

    Attributes
    ----------
    effect : str
    axis : int
    spec : Spec
        The structure with the effect added.
    score : Score
    gain : float
        Relative reduction of the held-out squared error on the axis.
    t : float
        t statistic of the mean per-window log ratio (baseline / candidate).
    p_value : float
        One-sided p-value of ``t``.
    """

    effect: str
    axis: int
    spec: Spec
    score: Score
    gain: float
    t: float
    p_value: float

    def row(self) -> dict:
        return {"effect": self.effect, "axis": AXES[self.axis], "gain": self.gain, "t": self.t,
                "p_value": self.p_value, "r2": float(self.score.r2()[self.axis])}


@dataclass
class Step:
    """One effect added to the model, with its evidence (a row of ``diagnosis.json``)."""

    round: int
    axis: str
    effect: str
    terms: tuple
    parameters: dict
    gap_before: dict
    gap_after: dict
    gain: float
    t: float
    p_value: float
    threshold_p: float
    runner_up: str | None
    runner_up_gain: float | None
    margin: float | None
    margin_p_value: float | None
    decisive: bool
    description: str

    def to_dict(self) -> dict:
        return dict(self.__dict__, terms=list(self.terms))


def paired_log_test(base, cand) -> tuple[float, float]:
    """One-sided paired test that ``cand`` has smaller per-window errors than ``base``.

    Parameters
    ----------
    base, cand : ndarray, shape (n_windows,)
        Mean squared errors per held-out window.

    Returns
    -------
    t : float
        Mean of ``log(base/cand)`` over its standard error.
    p_value : float
        Student-t upper tail with ``n_windows - 1`` degrees of freedom.
    """
    tiny = 1e-300
    r = np.log(np.maximum(base, tiny)) - np.log(np.maximum(cand, tiny))
    n = r.size
    sd = r.std(ddof=1) if n > 1 else 0.0
    if sd == 0.0:
        t = 0.0 if r.mean() == 0 else np.copysign(np.inf, r.mean())
    else:
        t = float(r.mean() / (sd / np.sqrt(n)))
    return float(t), float(stats.t.sf(t, max(n - 1, 1)))


def heldout_stats(score: Score) -> dict:
    """The paper's error statistics (Table 1: MAE, 90th percentile, relative to max) on held-out windows."""
    return rate_error_stats(score.measured.reshape(3, -1), score.simulated.reshape(3, -1))


class Diagnoser(DiagnosisResult):
    """Find the physical effect a model misses in a flight, add it, and show the gap shrink.

    Parameters
    ----------
    folds : int
        Contiguous blocks of the cross-validation.
    window : float
        Held-out simulation window [s].
    interval : float
        Interval of the integral method [s].
    alpha : float
        Family-wise significance level per axis and round.
    min_gain : float
        Smallest relative held-out improvement accepted (0..1).
    max_rounds : int
        Rounds of add-and-rescore.
    effects : sequence of str, optional
        Catalogue effects to consider (default: all of :data:`identification.diagnosis.effects.CATALOGUE` but
        ``servo_lag``, which the integral method cannot fit: it has no servo filter).
    prefilter : bool
        Zero-phase FIR low-pass of Section 3.1 before everything, the gyro's folded vibration lines removed first
        (:func:`identification.preprocess.without_folded_lines`, as the integral method's fit does).
    min_duration, min_windows, min_r2 : float, int, float
        Reliability limits (module docstring).
    progress : bool
        Progress bar over the candidates (on a terminal only).

    Attributes
    ----------
    verdict_ : str
        ``"none"``, ``"undecided"`` or ``"found"``.
    steps_ : list of Step
        Effects added, in order.
    effects_found_ : list of (str, str)
        (effect, axis) of every step.
    evidence_ : dict
        Why the verdict: durations, windows, per-axis decidability.
    baseline_spec_, spec_ : Spec
        Structure before and after.
    baseline_score_, final_score_ : Score
        Held-out results before and after.
    rounds_ : list of list of dict
        Every candidate's row, per round.
    params_ : ModelParams
        The final structure re-identified on the whole flight.
    identifier_ : IntegralIdentifier
        That fit (its ``axes_`` hold the integral residuals).
    baseline_identifier_ : IntegralIdentifier
    residual_tests_ : dict
        ``{"before": ..., "after": ...}`` per axis (:meth:`residual_report`).
    flight_ : Flight
        The prefiltered flight.
    """

    def __init__(self, folds: int = 5, window: float = 4.0, interval: float = 1.0, alpha: float = ALPHA,
                 min_gain: float = MIN_GAIN, max_rounds: int = 4, effects=None, prefilter: bool = True,
                 min_duration: float = MIN_DURATION, min_windows: int = MIN_WINDOWS, min_r2: float = MIN_R2,
                 progress: bool = False):
        self.folds = folds
        self.window = window
        self.interval = interval
        self.alpha = alpha
        self.min_gain = min_gain
        self.max_rounds = max_rounds
        self.effects = effects
        self.prefilter = prefilter
        self.min_duration = min_duration
        self.min_windows = min_windows
        self.min_r2 = min_r2
        self.progress = progress

    # ---------------------------------------------------------------- checks
    def _check_settings(self):
        checks = {
            "folds": isinstance(self.folds, (int, np.integer)) and self.folds >= 2,
            "window": 0 < self.window < np.inf, "interval": 0 < self.interval < np.inf,
            "alpha": 0 < self.alpha < 1, "min_gain": 0 <= self.min_gain < 1,
            "max_rounds": isinstance(self.max_rounds, (int, np.integer)) and self.max_rounds >= 1,
            "min_r2": self.min_r2 < 1, "min_windows": self.min_windows >= self.folds,
        }
        for name, ok in checks.items():
            if not ok:
                raise ValueError(f"Diagnoser.{name} out of range: {getattr(self, name)!r}")
        fittable = [n for n, e in CATALOGUE.items() if not e.is_servo_lag]
        names = fittable if self.effects is None else list(self.effects)
        unknown = [n for n in names if n not in CATALOGUE]
        if unknown:
            raise ValueError(f"unknown effect(s) {unknown}; the catalogue holds {', '.join(CATALOGUE)}")
        lagged = [n for n in names if CATALOGUE[n].is_servo_lag]
        if lagged:
            raise ValueError(f"the held-out diagnosis cannot test {lagged[0]!r}: the integral method has no servo "
                             "filter; the likelihood diagnosis (LikelihoodDiagnoser, heli diagnose's default) tests it")
        return names

    # ------------------------------------------------------------ candidates
    def _alignment_specs(self, held: HeldOut, spec: Spec, axis: int) -> tuple[Spec, list[Spec]]:
        """Servo-delay candidate: the alignment of ``axis`` searched coarse on all data, fine per fold.

        Each fold is scored with the alignment found on its own training data; the
        alignment reported (and added to the model) is the median over the folds.
        """
        coarse = np.round(np.arange(-MAX_ALIGNMENT, MAX_ALIGNMENT + 1e-9, COARSE_STEP), 6)
        centre = float(coarse[int(np.argmax(held.alignment_r2(spec, axis, coarse)))])
        fine = np.round(np.arange(centre - 2 * FINE_STEP, centre + 2 * FINE_STEP + 1e-9, FINE_STEP), 6)
        fine = fine[np.abs(fine) <= MAX_ALIGNMENT + 1e-9]
        chosen = [float(fine[int(np.argmax(held.alignment_r2(spec, axis, fine, k)))]) for k in range(held.folds)]
        return spec.with_alignment(axis, float(np.median(chosen))), [spec.with_alignment(axis, s) for s in chosen]

    def _candidates(self, spec: Spec, axes, names) -> list[tuple[str, int]]:
        out = []
        for a in axes:
            for name in names:
                eff = CATALOGUE[name]
                if eff.is_alignment:
                    if a not in self._aligned:
                        out.append((name, a))
                elif eff.terms_on(a) and not set(eff.terms_on(a)) <= set(spec.terms[a]):
                    out.append((name, a))
        return out

    def _evaluate(self, held: HeldOut, spec: Spec, base: Score, effect: str, axis: int) -> Candidate | None:
        eff = CATALOGUE[effect]
        try:
            if eff.is_alignment:
                cand_spec, fold_specs = self._alignment_specs(held, spec, axis)
                score = held.score(cand_spec, fold_specs)
            else:
                cand_spec = spec.with_terms(axis, eff.terms_on(axis))
                score = held.score(cand_spec)
        except IdentifiabilityError:
            return None  # the effect cannot be fitted from these data (e.g. collinear): not a candidate
        t, p = paired_log_test(base.mse[axis], score.mse[axis])
        return Candidate(effect, axis, cand_spec, score, score.gain_over(base, axis), t, p)

    # ------------------------------------------------------------------- fit
    def fit(self, flight: Flight, model: ModelParams | None = None) -> "Diagnoser":
        """Run the diagnosis on a flight.

        Parameters
        ----------
        flight : Flight
        model : ModelParams, optional
            The model to diagnose; its structure (non-zero terms, servo delays)
            is the starting point and is re-fitted on this flight. Default: the
            paper's decoupled model (Section 3.2).

        Raises
        ------
        IdentifiabilityError
            The starting structure cannot be identified from the flight at all
            (an axis never excited, a flight shorter than two intervals).
        """
        names = self._check_settings()
        if not isinstance(flight, Flight):
            raise TypeError(f"flight must be a Flight, got {type(flight).__name__}")
        if model is not None and not isinstance(model, ModelParams):
            raise TypeError(f"model must be a ModelParams or None, got {type(model).__name__}")
        fl = lowpass_flight(without_folded_lines(flight)[0]) if self.prefilter else flight
        self.flight_ = fl
        spec = Spec.from_params(model) if model is not None else Spec()
        self.baseline_spec_ = spec
        self.baseline_identifier_ = HeldOut.fit_whole(fl, spec, self.interval)
        n_windows = int((fl.n - 1) // int(round(self.window * fl.sample_rate)))
        self.evidence_ = {"duration_s": fl.duration, "min_duration_s": self.min_duration,
                          "held_out_windows": n_windows, "min_windows": self.min_windows,
                          "window_s": self.window, "folds": self.folds}
        self.steps_, self.rounds_ = [], []
        self._aligned = set()  # axes whose alignment a step has set (searched once)
        too_short = fl.duration < self.min_duration or n_windows < self.min_windows
        if too_short or n_windows < self.folds:
            self.evidence_["reason"] = (
                f"flight too short to decide: {fl.duration:.1f} s and {n_windows} held-out windows of "
                f"{self.window:g} s; a diagnosis needs at least {self.min_duration:g} s and {self.min_windows} "
                "windows so that a missing effect can be told from wind and noise"
            )
            self.verdict_ = UNDECIDED
            self.spec_ = spec
            self.held_ = None
            self.baseline_score_ = self.final_score_ = None
            self._finish(self.baseline_identifier_)
            return self
        held = HeldOut(fl, self.folds, self.window, interval=self.interval)
        self.held_ = held
        self.baseline_score_ = held.score(spec)
        spec, score, whole_fit, best_r2, undecided = self._search(held, spec, names)
        self._conclude(spec, score, best_r2, undecided)
        self._finish(whole_fit)
        return self

    def _search(self, held: HeldOut, spec: Spec, names) -> tuple:
        """Rounds of add-and-rescore (steps 2-5 of the module docstring), recording :attr:`steps_` and
        :attr:`rounds_`.

        Returns
        -------
        (Spec, Score, IntegralIdentifier, ndarray (3,), dict)
            The final structure, its held-out score and its whole-flight fit; the best held-out R² per axis of
            any candidate; the axes found too poorly excited to decide.
        """
        base = self.baseline_score_
        axes = list(range(3))
        best_r2 = base.r2().copy()
        undecided = {}
        whole_fit = self.baseline_identifier_  # the whole-flight fit of ``spec``, kept as the spec grows
        for rnd in range(1, self.max_rounds + 1):
            todo = self._candidates(spec, axes, names)
            if not todo:
                break
            cands = self._score_candidates(held, spec, base, todo, rnd, best_r2)
            self.rounds_.append([c.row() for c in cands])
            winners = self._winners(cands, axes, best_r2, undecided)
            if not winners:
                break
            new_spec = self._with_winners(spec, winners)
            whole_fit = HeldOut.fit_whole(self.flight_, new_spec, self.interval)
            for best, runner, threshold in winners:
                self.steps_.append(self._step(rnd, best, runner, threshold, base, whole_fit.params_))
            spec = new_spec
            base = held.score(spec)
            axes = sorted({best.axis for best, _, _ in winners})
        return spec, base, whole_fit, best_r2, undecided

    def _score_candidates(self, held: HeldOut, spec: Spec, base: Score, todo, rnd: int, best_r2) -> list[Candidate]:
        """Every (effect, axis) of ``todo`` fitted and scored; raises ``best_r2`` (3,) to the best seen."""
        from tqdm import tqdm

        cands = []
        for effect, a in tqdm(todo, desc=f"diagnose round {rnd}", unit="candidate", leave=False,
                              disable=not self.progress or not sys.stderr.isatty()):
            c = self._evaluate(held, spec, base, effect, a)
            if c is not None:
                cands.append(c)
                best_r2[a] = max(best_r2[a], c.score.r2()[a])
        return cands

    def _winners(self, cands: list[Candidate], axes, best_r2, undecided: dict) -> list[tuple]:
        """Per axis, the significant candidate of the largest gain with its runner-up and p threshold
        (step 3); an axis whose best model explains too little is put in ``undecided`` instead."""
        winners = []
        for a in axes:
            on_axis = sorted((c for c in cands if c.axis == a), key=lambda c: -c.gain)
            if not on_axis:
                continue
            threshold = self.alpha / len(on_axis)
            best = on_axis[0]
            if best.gain < self.min_gain or best.p_value > threshold:
                continue
            if best_r2[a] < self.min_r2:
                undecided[AXES[a]] = self._poor_excitation(a, best, best_r2[a])
                continue
            runner = on_axis[1] if len(on_axis) > 1 else None
            winners.append((best, runner, threshold))
        return winners

    def _with_winners(self, spec: Spec, winners: list[tuple]) -> Spec:
        """``spec`` with every winner's effect added (step 4)."""
        for best, _, _ in winners:
            a = best.axis
            if CATALOGUE[best.effect].is_alignment:
                self._aligned.add(a)
            spec = (spec.with_alignment(a, best.spec.alignment[a]) if CATALOGUE[best.effect].is_alignment
                    else spec.with_terms(a, CATALOGUE[best.effect].terms_on(a)))
        return spec

    def _conclude(self, spec: Spec, score: Score, best_r2, undecided: dict) -> None:
        """Set the verdict, the final structure and score, and the evidence of the undecided axes."""
        for a in range(3):
            if best_r2[a] < self.min_r2 and AXES[a] not in undecided:
                undecided[AXES[a]] = self._poor_excitation(a, None, best_r2[a])
        self.evidence_["held_out_r2_best"] = {AXES[a]: float(best_r2[a]) for a in range(3)}
        self.evidence_["undecided_axes"] = undecided
        self.spec_ = spec
        self.final_score_ = score
        if self.steps_:
            self.verdict_ = "found"
        elif undecided:
            self.verdict_ = UNDECIDED
            self.evidence_["reason"] = "; ".join(f"{k}: {v['reason']}" for k, v in undecided.items())
        else:
            self.verdict_ = NONE

    def _poor_excitation(self, axis: int, cand: Candidate | None, r2: float) -> dict:
        stick = self.flight_.sticks[("lat", "lon", "col", "ped").index(INPUT_FOR_AXIS[axis])]
        out = {"held_out_r2_best": float(r2), "min_r2": self.min_r2,
               "stick_std": float(np.std(stick)),
               "reason": (f"too poorly excited to decide: the best model explains {100 * r2:.0f} % of the held-out "
                          f"{AXES[axis]}-rate variance (need {100 * self.min_r2:.0f} %); the "
                          f"{INPUT_FOR_AXIS[axis]} stick varies by {np.std(stick):.3f} (std), so the response is "
                          "mostly wind")}
        if cand is not None:
            out["suppressed"] = cand.row()
        return out

    def _step(self, rnd, best: Candidate, runner: Candidate | None, threshold, base: Score, whole: ModelParams) -> Step:
        a = best.axis
        eff = CATALOGUE[best.effect]
        if eff.is_alignment:
            s = best.spec.alignment[a]
            terms = (f"tau_{AXES[a]}",) if s >= 0 else (f"input_alignment_{AXES[a]}",)
            params = {terms[0]: s}
        else:
            terms = eff.terms_on(a)
            params = {p: whole.get(p) for p in terms}
        before, after = heldout_stats(base)[AXES[a]], heldout_stats(best.score)[AXES[a]]
        margin = margin_p = None
        if runner is not None:
            margin = best.gain - runner.gain
            margin_p = paired_log_test(runner.score.mse[a], best.score.mse[a])[1]
        return Step(rnd, AXES[a], best.effect, terms, params, before, after, best.gain, best.t, best.p_value,
                    threshold, runner.effect if runner else None, runner.gain if runner else None, margin, margin_p,
                    bool(margin_p is not None and margin_p <= self.alpha), eff.description)

    def _finish(self, identifier):
        """Keep ``identifier``, the final spec's fit on the whole flight, and test its residuals."""
        self.identifier_ = identifier
        self.params_ = self.identifier_.params_
        self.effects_found_ = [(s.effect, s.axis) for s in self.steps_]
        self.residual_tests_ = {
            "before": self.residual_report(self.baseline_identifier_, self.baseline_score_),
            "after": self.residual_report(self.identifier_, self.final_score_),
        }

    # ------------------------------------------------------------- residuals
    def residual_report(self, identifier, score: Score | None) -> dict:
        """Residual tests per axis: integral residual and (when scored) held-out forward-simulation residual."""
        fl = self.flight_
        dec = max(1, int(round(TEST_STEP * fl.sample_rate)))
        lags = max(1, int(round(TEST_LAGS / (dec * fl.dt))))
        signals = {"lat": fl.sticks[0], "lon": fl.sticks[1], "col": fl.sticks[2], "ped": fl.sticks[3],
                   "p": fl.rates[0], "q": fl.rates[1], "r": fl.rates[2], "phi": fl.attitude[0],
                   "theta": fl.attitude[1]}
        out = {}
        for a, axis in enumerate(AXES):
            entry = {}
            fit = identifier.axes_.get(axis)
            if fit is not None and fit.residual is not None:
                res = fit.residual
                n_int, N = res.shape
                cols = np.arange(dec - 1, N, dec)
                pts = np.concatenate([np.zeros((n_int, 1)), res[:, cols]], axis=1)
                incr = np.diff(pts, axis=1).ravel()  # equation error integrated over each TEST_STEP
                at = (np.arange(n_int)[:, None] * N + cols[None, :] - dec // 2).ravel()
                at = np.clip(at, 0, fl.n - 1)
                entry["integral"] = self._tests(incr, {k: v[at] for k, v in signals.items()}, lags, dec * fl.dt)
            if score is not None:
                e = score.residual[a][:, dec - 1::dec].ravel()
                at = (self.held_.starts[:, None] + np.arange(dec, score.residual.shape[2] + 1, dec)[None, :]).ravel()
                entry["simulation"] = self._tests(e, {k: v[at] for k, v in signals.items()}, lags, dec * fl.dt)
                entry["simulation"]["bands"] = band_shares(score.residual[a].ravel(), score.measured[a].ravel(),
                                                           fl.sample_rate)
                mse = score.mse[a]
                worst = np.argsort(mse)[::-1][:3]
                entry["simulation"]["worst_windows"] = [
                    {"t_start_s": float(fl.time[self.held_.starts[w]]),
                     "t_end_s": float(fl.time[self.held_.starts[w] + self.held_.length]),
                     "rms_deg_s": float(np.degrees(np.sqrt(mse[w]))),
                     "busiest_stick": self._busiest(self.held_.starts[w])} for w in worst]
                entry["simulation"]["heldout_stats"] = heldout_stats(score)[axis]
            out[axis] = entry
        return out

    def _busiest(self, start: int) -> str:
        seg = self.flight_.sticks[:, start:start + self.held_.length]
        return ("lat", "lon", "col", "ped")[int(np.argmax(seg.std(axis=1)))]

    @staticmethod
    def _tests(residual, signals, lags, step) -> dict:
        w = whiteness(residual, lags)
        cc = cross_correlation(residual, signals, lags)
        return {"whiteness": w.to_dict(), "cross_correlation": cc.summary(step),
                "correlated_with": cc.significant(), "n": int(np.size(residual)), "step_s": step,
                "_acf": w, "_ccf": cc}

    # ------------------------------------------------------------------- use
    def summary(self) -> dict:
        """JSON-ready result (without the plots' raw series)."""
        return self._summary_head() | {"evidence": self.evidence_}
