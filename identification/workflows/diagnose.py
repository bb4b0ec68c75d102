"""``heli diagnose``: run a diagnosis on a flight and write ``diagnosis.json``, ``diagnosis.md`` and, when an
effect was found, the new model version with this flight's wind (one transaction of the model folder).

:func:`diagnose_by_likelihood` (the default) runs
:class:`identification.diagnosis.likelihood_diagnoser.LikelihoodDiagnoser` and :func:`diagnose_and_report`
the held-out :class:`identification.diagnosis.heldout_diagnoser.Diagnoser`; both write through
:func:`write_diagnosis`. What the files say is the reports' (:mod:`identification.reports.likelihood_diagnosis`,
:mod:`identification.reports.diagnosis`); the model a found effect gives is fitted and judged here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from heli_core.config import check, configured, is_flag
from heli_core.files import write_text
from heli_core.params import ModelParams
from heli_core.terms import AXES
from model_store.model_dir import ModelDir
from model_store.model_file import model_document as new_model_document, verdict_of
from model_store.verdict import ModelVerdict

from ..diagnosis.effects import alignment_parts
from ..diagnosis.heldout_diagnoser import Diagnoser, heldout_stats
from ..diagnosis.likelihood_diagnoser import LikelihoodDiagnoser
from ..disturbance.equivalent_input import identify_disturbance
from ..errors import SimulationDivergedError
from ..flight import Flight
from ..integral.method import IntegralIdentifier
from ..likelihood.closed_loop import N_FLIGHTS, check_settings
from ..preprocess import shift_inputs
from ..reports.diagnosis import criterion_text as heldout_criterion
from ..reports.diagnosis import diagnosis_document as heldout_document
from ..reports.diagnosis import diagnosis_markdown as heldout_markdown
from ..reports.diagnosis import plot_residual_tests, plot_worst_windows
from ..reports.figures import PendingFigures
from ..reports.likelihood_diagnosis import criterion_text as likelihood_criterion
from ..reports.likelihood_diagnosis import diagnosis_document as likelihood_document
from ..reports.likelihood_diagnosis import diagnosis_markdown as likelihood_markdown
from ..reports.likelihood_diagnosis import plot_statistics
from ..reports.likelihood_diagnosis import written_model_check
from ..validation.forward_simulation import validate_models
from ..validation.model_verdict import judge_identifier
from .identify import identification_settings


@dataclass
class DiagnosisRun(PendingFigures):
    """What :func:`diagnose_and_report` or :func:`diagnose_by_likelihood` produced.

    Attributes
    ----------
    diagnoser : Diagnoser
        The fitted diagnosis.
    document : dict
        The content of ``diagnosis.json``.
    paths : dict of str to Path
        Files written.
    figures : list of callable
        Figures ``diagnosis.md`` links but :func:`diagnose_and_report` was asked to leave for later
        (``draw_figures=False``); each returns ``{key: path}``. :meth:`draw_figures` draws them.
    """

    diagnoser: Diagnoser
    document: dict
    paths: dict = field(default_factory=dict)
    figures: list = field(default_factory=list)


def diagnose_by_likelihood(flight: Flight, out_dir, *, model: ModelParams | None = None, model_document=None,
                           source: dict | None = None, plots: bool = True,
                           diagnoser: LikelihoodDiagnoser | None = None, wait: bool = True,
                           closed_loop: str | None = None) -> DiagnosisRun:
    """Diagnose ``flight`` by likelihood and write the outputs into ``out_dir`` (module docstring).

    When an effect is found, the new model, this flight's wind and the diagnosis files are written as one
    transaction of the model folder (:class:`model_store.ModelDir`): after a kill at any instant the folder
    reads as before or after. ``wait``: wait for another command writing ``out_dir`` (default), or raise
    :class:`~identification.errors.ModelDirBusyError`. The figure is drawn after the numbers are written.
    ``closed_loop`` ("auto" or "report"; None: not run): the model written is checked in the flight's closed loop
    first, as ``heli identify``'s is (:func:`check_written_model`).

    Raises
    ------
    ValueError
        ``closed_loop`` not None, "auto" or "report" (before any work).
    """
    check_settings(closed_loop, N_FLIGHTS)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    d = (diagnoser or LikelihoodDiagnoser()).fit(flight, model=model)
    if d.steps_ and closed_loop is not None:
        if callable(getattr(d, "progress", None)):
            d.progress("checking the model written in the flight's closed loop (as heli identify checks its own)")
        check_written_model(d, closed_loop)
    figure = out / "diagnosis_likelihood.png" if plots and d.rounds_ else None
    new_model = _likelihood_model(d, flight, model_document, source) if d.steps_ else None
    verdict = verdict_of(new_model[0]) if new_model is not None else None
    doc, paths = write_diagnosis(out, new_model, lambda model_path: likelihood_document(d, source, model_path, verdict),
                                 lambda doc: likelihood_markdown(d, figure, verdict), wait)
    if figure is not None and plot_statistics(d, figure) is not None:
        paths["likelihood_png"] = figure
    return DiagnosisRun(d, doc, paths)


def check_written_model(d: LikelihoodDiagnoser, mode: str):
    """Run ``heli identify``'s closed-loop check (:meth:`MaximumLikelihoodIdentifier.closed_loop_check`) on the
    diagnosis' final fit, the model it writes: where a pilot who sees the aircraft moved the sticks, the damping's
    bias his loop gives the likelihood is measured and, in mode "auto", removed, and a servo delay the loop makes
    is taken out. The diagnosis' effects were named on the fits as found; the check changes only the values the
    model written carries (``d.params_``, its holds, and a delay it removed from :attr:`timing_detected_`).

    A servo delay the diagnosis named was found by a search, as ``heli identify``'s are: the check's flights are
    fitted with it searched (profiled, ``delay="auto"``), so that its bias is measured and removed with the
    damping's (held at the value found, the pilot's loop kept its +50 % in the sluggish aircraft's 20 ms pitch
    delay, and with it the damping's bias), and the delay is tested in the delay-free loop as identify's are.
    Returns the check (also ``d.identifier_.closed_loop_``)."""
    ident = d.identifier_
    named = {s.axis for s in d.steps_ if s.effect == "servo_delay" and d.alignment_[AXES.index(s.axis)] > 0.0}
    given = ident.delay
    ident.delay = ["auto" if axis in named else v for axis, v in zip(AXES, ident._delays())]
    try:
        check = ident.closed_loop_check(mode)
    finally:
        ident.delay = given
    d.params_ = ident.params_
    d.hold_fractions_ = {axis: fit.input_hold for axis, fit in ident.axes_.items()}
    removed = {axis for axis, tested in check.delays.items() if tested.removed}
    d.timing_detected_ = {axis: v for axis, v in d.timing_detected_.items() if axis not in removed}
    return check


def _verdict(ident, params: ModelParams, aligned: Flight) -> ModelVerdict:
    """The verdict ``heli identify`` would give the diagnosed model: the same judge, the integral method on the
    same flight beside it, and its simulation from the (aligned) flight's sticks, whose divergence
    ``heli identify`` refuses."""
    try:
        validate_models(aligned, {"diagnosed": params})
        diverged = None
    except SimulationDivergedError as e:
        diverged = str(e).split(": ", 1)[-1].split(";")[0]  # "the roll rate leaves ±100 rad/s at t=... s"
    # the integral method beside it on the flight as the diagnosis fitted it (its late sticks advanced): on the
    # T-REX hover, fitted on the log as written, it gave k2 = -10.5 and called the aligned model unusable
    return judge_identifier(ident, IntegralIdentifier(structure="decoupled").fit(aligned), diverged)


def _likelihood_model(d: LikelihoodDiagnoser, flight: Flight, model_document, source):
    """The model with the added effects (its ``model.json`` document) and this flight's wind."""
    delays, log_shift = alignment_parts(d.alignment_)
    ident = d.identifier_
    diagnosis = {
        "method": "likelihood",
        "added": [{"round": s.round, "axis": s.axis, "effect": s.effect, "parameters": s.parameters, "lr": s.lr,
                   "threshold": s.threshold} for s in d.steps_],
        "input_alignment_s": {a: log_shift[i] for i, a in enumerate(AXES)},
        "timing_detected_s": dict(d.timing_detected_),
        "note": "A positive alignment is the servo delay of eq. (31) (first-order Padé). input_alignment_s < 0: "
                "the log's input column lags the response; advance it by this much "
                "(identification.preprocess.shift_inputs) before comparing this model with the log. "
                "timing_detected_s: servo delays shorter than two samples, kept in the model (servo_delay_s) "
                "as heli identify's --delay detect keeps them, not named as an effect.",
        "criterion": likelihood_criterion(d),
    }
    sources = [s.to_dict() for s in (model_document.sources if model_document is not None else ())] + (
        [source] if source else [])
    settings = identification_settings(ident)
    settings["method"] += " after heli diagnose"
    aligned = shift_inputs(flight, log_shift) if min(log_shift) < 0 else flight
    document = new_model_document(d.params_, structure="custom", sample_rate=flight.sample_rate,
                                  identification=settings, fit_statistics={"axes": ident.summary(), **(
                                      {"closed_loop": check.describe()}
                                      if (check := written_model_check(d)) is not None else {})},
                                  sources=sources, extra={"diagnosis": diagnosis},
                                  verdict=_verdict(ident, d.params_, aligned))
    return document, identify_disturbance(aligned, d.params_, wind_torque=ident.wind_torque(0))


@dataclass(frozen=True)
class DiagnosisConfig:
    """How :func:`diagnose_and_report` diagnoses and writes (all but the flight, the folder and the model).

    ``diagnose_and_report(flight, out_dir, config)`` runs it; keyword settings replace its fields
    (``diagnose_and_report(flight, out_dir, config, plots=False)``).

    Attributes
    ----------
    diagnoser : Diagnoser, optional
        The diagnosis' settings (default :class:`Diagnoser` with ``progress``).
    progress : bool
        Progress bar over the candidate search (of the default diagnoser).
    plots : bool
        Draw the figures.
    draw_figures : bool
        With ``plots``: draw the figures before returning (default), or leave them to
        :meth:`DiagnosisRun.draw_figures` (``diagnosis.md`` links them either way).
    wait : bool
        When an effect was found: wait for another command writing ``out_dir`` (default), or raise
        :class:`~identification.errors.ModelDirBusyError`.

    Raises
    ------
    ValueError
        A diagnoser that is not a :class:`Diagnoser`, or a switch that is not True or False (the message names it).
    """

    diagnoser: Diagnoser | None = None
    progress: bool = False
    plots: bool = True
    draw_figures: bool = True
    wait: bool = True

    def __post_init__(self):
        check(self.diagnoser is None or isinstance(self.diagnoser, Diagnoser), "diagnoser", "a Diagnoser or None",
              self.diagnoser)
        for name in ("progress", "plots", "draw_figures", "wait"):
            check(is_flag(getattr(self, name)), name, "True or False", getattr(self, name))


def diagnose_and_report(flight: Flight, out_dir, config: DiagnosisConfig | None = None, *,
                        model: ModelParams | None = None, model_document=None, source: dict | None = None,
                        **settings) -> DiagnosisRun:
    """Diagnose ``flight`` and write the outputs into ``out_dir``.

    Parameters
    ----------
    flight : Flight
        The raw flight (the diagnoser prefilters it).
    out_dir : str or Path
    config : DiagnosisConfig, optional
        How it is diagnosed and written (default ``DiagnosisConfig()``), described there.
    model : ModelParams, optional
        The model whose structure is diagnosed (default: the paper's decoupled model).
    model_document : ModelDocument, optional
        Its ``model.json`` document (its sources carried into the new version's provenance).
    source : dict, optional
        Provenance of the flight file (``{"file": ..., "sha256": ...}``).
    **settings
        :class:`DiagnosisConfig` fields replacing the config's (``plots=False, wait=False, ...``).

    When an effect was found, the new model, its wind and the diagnosis files are written as one
    transaction (:class:`model_store.ModelDir`).

    Raises
    ------
    TypeError
        ``config`` is not a DiagnosisConfig, or a keyword is not one of its fields.
    """
    cfg = configured(DiagnosisConfig, config, settings, "diagnosis")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    d = (cfg.diagnoser or Diagnoser(progress=cfg.progress)).fit(flight, model=model)
    figures, pending = {}, []
    if cfg.plots and d.baseline_score_ is not None:
        figures = {"residual tests": out / "diagnosis_residuals.png",
                   "worst held-out windows, before and after": out / "diagnosis_windows.png"}
        pending.append(partial(_figures, d, out))
    new_model = _heldout_model(d, flight, model_document, source) if d.steps_ else None
    doc, paths = write_diagnosis(out, new_model, lambda model_path: heldout_document(d, source, model_path),
                                 lambda doc: heldout_markdown(d, doc, figures), cfg.wait)
    run = DiagnosisRun(d, doc, paths, pending)
    if cfg.draw_figures:
        run.draw_figures()
    return run


def write_diagnosis(out: Path, new_model, document_of, markdown_of, wait: bool = True) -> tuple[dict, dict]:
    """Write ``diagnosis.json`` and ``diagnosis.md`` into ``out``; with ``new_model`` (a ``model.json``
    document and the flight's wind profile) also the new model and its trace, all as one transaction of the
    model folder (:class:`model_store.ModelDir`). Both diagnosis methods write through here.

    ``document_of(model_path)`` builds the diagnosis document (``model_path`` None when no model is
    written), ``markdown_of(document)`` the report. Returns ``(document, paths)``.
    """
    def text(doc):
        return json.dumps(doc, indent=2, allow_nan=False) + "\n"

    if new_model is None:
        doc = document_of(None)
        return doc, {"json": write_text(out / "diagnosis.json", text(doc)),
                     "markdown": write_text(out / "diagnosis.md", markdown_of(doc))}
    document, profile = new_model
    with ModelDir(out).transaction(wait=wait, what="diagnose") as tx:
        model_path = tx.write_model_document(document)
        tx.add_traces([profile])
        doc = document_of(model_path)
        paths = {"model": model_path, "library": out / "disturbances",
                 "json": tx.write_report("diagnosis.json", text(doc)),
                 "markdown": tx.write_report("diagnosis.md", markdown_of(doc))}
    return doc, paths


def _figures(d: Diagnoser, out: Path) -> dict:
    return {"residuals_png": plot_residual_tests(d, out / "diagnosis_residuals.png"),
            "windows_png": plot_worst_windows(d, out / "diagnosis_windows.png")}


def _heldout_model(d: Diagnoser, flight: Flight, model_document, source):
    """The re-identified model with the added effects (its ``model.json`` document) and this flight's wind."""
    ident = d.identifier_
    delays, log_shift = alignment_parts(d.spec_.alignment)
    params = d.params_.with_values(**{f"tau_{a}": delays[i] for i, a in enumerate(AXES) if delays[i] > 0})
    diagnosis = {
        "added": [{"round": s.round, "axis": s.axis, "effect": s.effect, "terms": list(s.terms),
                   "parameters": s.parameters} for s in d.steps_],
        "input_alignment_s": {a: log_shift[i] for i, a in enumerate(AXES)},
        "note": "A positive alignment found by the diagnosis (an exact transport delay) is stored as the servo "
                "delay of eq. (31), a first-order Padé approximation. input_alignment_s < 0: the log's input "
                "column lags the response; advance it by this much (identification.preprocess.shift_inputs) before "
                "comparing this model with the log; the aircraft model itself needs no term for it.",
        "criterion": heldout_criterion(d),
    }
    sources = [s.to_dict() for s in (model_document.sources if model_document is not None else ())] + (
        [source] if source else [])
    document = new_model_document(
        params, structure="custom", sample_rate=d.flight_.sample_rate,
        filter_settings=d.flight_.metadata.get("prefilter"),
        identification={"method": "integral (Fig. 5) after heli diagnose", "interval": d.interval,
                        "structure": d.spec_.to_dict(), "alpha": d.alpha},
        fit_statistics={"axes": ident.summary(), "heldout_after": heldout_stats(d.final_score_)},
        sources=sources, extra={"diagnosis": diagnosis},
    )
    return document, identify_disturbance(shift_inputs(flight, log_shift), params)
