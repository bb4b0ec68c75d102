"""Refresh an identified model with new flights: parameter drift, the refreshed model, a larger wind library.

:func:`refresh_model` is what ``heli refresh MODEL_DIR NEW_FLIGHT...`` runs on a
directory written by ``heli identify``:

1. **Refuse duplicates.** A new flight whose file SHA-256 is already among the
   model's sources or the disturbance library's traces (or given twice) raises
   :class:`~identification.workflows.refresh_sources.DuplicateFlightError` before anything is written: its intervals
   would be counted twice and its wind replayed twice as often.
2. **Identify the new flights alone** with the model's own structure and settings
   (``model.json`` ``"structure"``, ``"identification"``, ``"filter"``,
   ``"added_terms"``), so that the comparison with the current model involves two
   independent data sets.
3. **Uncertainty** of both by the interval bootstrap
   (:func:`identification.integral.bootstrap.interval_bootstrap`). The current model's
   source flights are looked for by name and SHA-256 (``model.json`` provenance) in
   the model directory, beside the new flights and among ``previous_flights``; when
   all are at hand they are bootstrapped too (and refitted, to check they still
   give the current model). Otherwise the previous standard errors come from the
   bootstrap recorded in ``model.json`` by an earlier refresh, or else the new
   flights' bootstrap scaled by ``sqrt(n_new / n_old)`` intervals (the old interval
   count from the library's record of the source flights' durations; equal counts
   when unknown). The residual-based standard errors of the fit are never used:
   they are 4-6 times too small (see :mod:`identification.integral.bootstrap`).
4. **Drift and flags** (:mod:`identification.validation.parameter_drift`). Per parameter
   Δ = new − old; it is flagged when ``|Δ| > z·sqrt(se_old² + se_new²)`` (and
   ``|Δ| >= min_relative·|old|``), with
   ``z = Φ⁻¹(1 − α/(2m))`` for the ``m`` parameters compared (Bonferroni: a false
   flag anywhere in the table has probability about α when nothing changed).
5. **The refreshed model.** ``fit="auto"`` pools the previous and the new flights
   (eq. 35 over all intervals: the most data) when the previous flights are at hand
   and nothing is flagged; when a parameter changed, the old flights describe an
   aircraft that no longer exists, so the model is fitted on the new flights alone
   (as it is when the old flights are missing). ``"pooled"`` and ``"new"`` force
   the choice. The model is written by
   :func:`identification.workflows.identify.identify_and_report` (the replaced ``model.json``
   is kept under ``history/``, and so are the replaced ``report.md``, figures and
   previous refresh files; a figure only the replaced report showed is then removed from beside the new
   one), which identifies each *new* flight's wind with the
   refreshed model (eqs. 41-47) and appends the traces to the library as one new
   version (earlier versions untouched). The flights the model was validated on
   (``heli identify --validate``) validate the refreshed model again where their
   files are found; a lost one's scores are carried over, marked with the model
   they were computed on (:mod:`identification.workflows.refresh_validation`).
6. **Provenance.** ``model.json`` gets a ``"refresh"`` entry (previous model's
   SHA-256 and history file, its sources, the new sources, the fit decision, the
   flags and the written model's bootstrap standard errors, which the next refresh
   uses when these flights are gone); ``refresh.json`` and ``refresh.md``
   (:mod:`identification.reports.refresh`) hold the drift table.
"""

from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from heli_core.files import jsonable, keep_copy, sha256_of
from heli_core.terms import AXES
from model_store.model_dir import ModelDir
from model_store.model_file import MODEL_FILENAME

from ..integral.bootstrap import DEFAULT_REPLICATES, BootstrapResult, interval_bootstrap
from ..reports.refresh import refresh_markdown
from ..validation.parameter_drift import (
    compared_parameters,
    critical_z,
    drift_table,
    fisher_result,
    previous_std_errors,
)
from .refresh_result import RefreshResult
from .refresh_sources import RefreshError, check_new_flights, estimator_of, find_source_flights, identifier_settings

REFRESH_SCHEMA = "heli-env/refresh"
REFRESH_SCHEMA_VERSION = 1
FIT_CHOICES = ("auto", "pooled", "new")
KEPT_FILES = ("report.md", "report.html", "refresh.md", "refresh.json")
"""Top-level files of a model directory a refresh replaces; copied to ``history/`` first (with the PNG figures)."""
REPRODUCE_RTOL = 1e-6
"""Relative agreement expected between ``model.json`` and a refit of its source flights."""


def _keep_in_history(root: Path) -> list[Path]:
    """Copy the files a refresh replaces to ``history/`` (see :func:`.files.keep_copy`); returns the copies."""
    files = [root / n for n in KEPT_FILES] + sorted(root.glob("*.png"))
    return [keep_copy(path) for path in files if path.is_file()]


def _report_figures(root: Path) -> set[str]:
    """The PNG files ``report.md`` of ``root`` shows (``![...](name.png)`` beside it); empty without a report."""
    import re

    report = root / "report.md"
    text = report.read_text(encoding="utf-8", errors="replace") if report.is_file() else ""
    return {m for m in re.findall(r"!\[[^\]]*\]\(([^)/\\]+\.png)\)", text)}


def _drop_stale_figures(root: Path, before: set[str]) -> list[Path]:
    """Remove the figures the replaced report showed (``before``) that the refreshed one does not — a flight's
    wind figures when fewer flights are identified, every figure of a run without plots —, each kept in
    ``history/`` first (:func:`_keep_in_history` copied them; copied again here if not); returns what went.
    Figures the report never linked are the user's and stay."""
    gone = []
    for name in sorted(before - _report_figures(root)):
        path = root / name
        if path.is_file():
            keep_copy(path)
            path.unlink()
            gone.append(path)
    return gone


# ------------------------------------------------------------------ the refresh
@dataclass(frozen=True)
class RefreshSettings:
    """How :func:`refresh_model` judges the drift and refits the model (module docstring).

    Attributes
    ----------
    previous_flights : sequence of path
        Where the current model's source flights are, if not in the model directory or beside the new flights.
    fit : {"auto", "pooled", "new"}
        Which flights the refreshed model is fitted on (module docstring, step 5).
    n_replicates : int
        Bootstrap replicates per data set.
    block : int
        Consecutive intervals per bootstrap block.
    seed : int
        Bootstrap seed (the same seed gives the same table).
    alpha : float
        Family-wise false-flag rate over the parameters compared, in (0, 1).
    min_relative : float
        Smallest relative change that may be flagged (0: any significant change).
    plots : bool
        Write the report's PNG figures.
    progress : bool, optional
        Progress bars (default: when there are several flights).
    backend : None, {"local", "ray"} or heli_core.backends.Backend
        Where the new flights' winds are identified, one task per flight
        (:func:`identification.workflows.identify.identify_and_report`); None: in this process.
    stage : callable, optional
        Called with a few words as each step that can take seconds starts (reading and fitting the new
        flights, their uncertainty, refitting the previous flights, the refreshed model's fit and winds,
        the figures), e.g. ``heli refresh``'s progress lines; None: nothing is said.
    segment : None, "auto", "all" or (t0, t1)
        The stretch of each new log read (:func:`identification.io.read_log`'s ``segment``); None: each as
        its reader's default. A stretch given is recorded in the new flights' sources, so that a later refresh
        reads them as this one did (the previous flights are always read as their sources record).
    controller_loop : float, optional
        The new flights' inputs stated as a flight controller's commands from a loop at this rate [Hz]
        (``heli refresh --controller-loop``, for CSVs that cannot say so; as ``heli identify``'s); recorded in their
        sources. The previous flights are stated as their sources record, whatever this says.
    gyro_filter : float, optional
        The new flights' gyro stated low-passed at this corner [Hz] before their controller read it and their log
        wrote it (``heli refresh --gyro-filter``, as ``heli identify``'s); recorded in their sources likewise.

    Raises
    ------
    RefreshError
        ``fit`` not one of :data:`FIT_CHOICES`, ``alpha`` outside (0, 1), a negative ``min_relative`` or a
        ``controller_loop`` or ``gyro_filter`` not above 0.
    """

    previous_flights: tuple = ()
    fit: str = "auto"
    n_replicates: int = DEFAULT_REPLICATES
    block: int = 1
    seed: int = 0
    alpha: float = 0.05
    min_relative: float = 0.0
    plots: bool = True
    progress: bool | None = None
    backend: object = None
    stage: object = None
    segment: object = None
    controller_loop: float | None = None
    gyro_filter: float | None = None

    def __post_init__(self):
        if self.fit not in FIT_CHOICES:
            raise RefreshError(f"fit must be one of {FIT_CHOICES}, got {self.fit!r}")
        if not 0.0 < self.alpha < 1.0:
            raise RefreshError(f"alpha must lie in (0, 1), got {self.alpha!r}")
        if not self.min_relative >= 0.0:
            raise RefreshError(f"min_relative must be >= 0, got {self.min_relative!r}")
        if self.controller_loop is not None and not self.controller_loop > 0:
            raise RefreshError(f"controller_loop must be a loop rate in Hz above 0, got {self.controller_loop!r}")
        if self.gyro_filter is not None and not self.gyro_filter > 0:
            raise RefreshError(f"gyro_filter must be a filter's corner in Hz above 0, got {self.gyro_filter!r}")


def refresh_model(model_dir, new_flights, *, settings: RefreshSettings | None = None, wait: bool = True,
                  **options) -> RefreshResult:
    """Refresh the model in ``model_dir`` with new flights (module docstring).

    Parameters
    ----------
    model_dir : str or Path
        A directory written by ``heli identify`` (``model.json``, optionally ``disturbances/``).
    new_flights : sequence of path
        Canonical flight logs not yet in the model.
    settings : RefreshSettings, optional
        How the drift is judged and the model refitted; default :class:`RefreshSettings`'s.
    wait : bool
        Wait for another command writing ``model_dir`` (default, saying so), or raise
        :class:`~identification.errors.ModelDirBusyError`. The folder is locked from reading the current model
        to writing the refreshed one, and everything is written as one transaction
        (:class:`model_store.ModelDir`): after a crash it holds the model before or after the refresh.
    **options
        Fields of :class:`RefreshSettings` (``previous_flights``, ``fit``, ``n_replicates``, ``block``,
        ``seed``, ``alpha``, ``min_relative``, ``plots``, ``progress``, ``backend``, ``stage``, ``segment``),
        replacing those of ``settings``.

    Raises
    ------
    ModelFileError
        No readable ``model.json``.
    RefreshError
        A model of a structure or method refresh cannot re-identify, ``fit="pooled"`` without the
        previous flights, or an option out of range.
    DuplicateFlightError
        A new flight already in the model or library, or given twice.
    LibraryError
        The existing library is corrupt or incomplete (nothing is written).
    ModelDirBusyError
        Another command is writing ``model_dir`` and ``wait`` is false.
    FlightLogError, IdentifiabilityError
        A new flight cannot be read or identified.
    """
    settings = RefreshSettings(**options) if settings is None else replace(settings, **options)
    new_paths = [Path(p) for p in new_flights]
    if not new_paths:
        raise RefreshError("expected at least one new flight, got none")
    root = Path(model_dir)
    if root.suffix == ".json":
        root = root.parent
    ModelDir(root).load(library=False)  # a missing or corrupt model is named before anything is locked or made
    for p in new_paths:
        if not p.is_file():
            raise FileNotFoundError(f"new flight {str(p)!r} does not exist")
    shown = _report_figures(root)
    with ModelDir(root).transaction(wait=wait, what="refresh") as tx:
        result = _Refresh(tx, new_paths, settings).run()
    if result.run.figures:
        _say(settings, "drawing the report's figures")
        result.paths.update(result.run.draw_figures())
    _drop_stale_figures(root, shown)  # a figure of the model before would sit beside the new ones as if current
    return result


def _say(settings: RefreshSettings, text: str) -> None:
    """Tell ``settings.stage`` that a step starts (nothing without one)."""
    if settings.stage is not None:
        settings.stage(text)


def _at_model_rate(flight, model_hz):
    """``flight`` thinned to the rate its model was fitted at (``model_hz``, :mod:`identification.fit_rate`: a log
    whose gyro was low-passed before it was logged is fitted at a fraction of its rate), where its own rate is a
    whole multiple of it; else as read (the estimator then says what it can of a log at another rate)."""
    from ..fit_rate import every_for, nth, thinned

    if not model_hz or flight.sample_rate < 1.5 * model_hz:
        return flight
    try:
        every = every_for(flight.sample_rate, model_hz)
    except ValueError:
        return flight
    return thinned(flight, every).with_metadata(  # the model's rate: chosen for a filtered gyro, or stated
        fit_rate=f"fitted at the model's {model_hz:g} Hz, every {nth(every)} sample of the {flight.sample_rate:g} Hz "
        "log", fit_rate_by="model")


def _read_flights(paths, desc: str, show: bool, segments=None, loops=None, model_hz=None, filters=None) -> list:
    """Read ``paths`` with a bar only on a terminal (``disable=None``: tqdm's own check; off one, a failing
    read's error would land on the bar's line), closed on an error too; each as the stretch ``segments`` gives
    for it (``(t0, t1)``: the one its model recorded) or None (the file as it reads by default), its inputs
    stated as a flight controller's from a loop at the rate ``loops`` gives for it and its gyro low-passed at the
    corner ``filters`` gives (None: as its file states them), at the model's rate ``model_hz``
    (:func:`_at_model_rate`)."""
    from tqdm import tqdm

    from ..io import read_log
    from ..validation.fit_warnings import stated_controller

    segments = list(segments) if segments is not None else [None] * len(paths)
    loops = list(loops) if loops is not None else [None] * len(paths)
    filters = list(filters) if filters is not None else [None] * len(paths)
    with tqdm(list(zip(paths, segments)), desc=desc, unit="flight", disable=None if show else True) as bar:
        flights = [read_log(p, segment=seg) for p, seg in bar]
    return [_at_model_rate(stated_controller(flight, loop, corner), model_hz)
            for flight, loop, corner in zip(flights, loops, filters)]


@dataclass
class _Previous:
    """The current model's side of the drift table: its source flights and their uncertainty (step 3)."""

    found: list
    missing: list
    flights: list
    bootstrap: BootstrapResult | None
    std_errors: dict
    source: str
    ci: dict | None
    notes: list


class _Refresh:
    """One refresh of :func:`refresh_model` inside its transaction ``tx``: read, compute, stage the files.

    The model directory is read once here; :meth:`run` takes the steps of the module docstring.
    """

    def __init__(self, tx, new_paths, settings: RefreshSettings):
        self.tx, self.new_paths, self.settings = tx, new_paths, settings
        self.model_path = tx.root / MODEL_FILENAME
        if tx.base.document is None:
            tx.dir.load(library=False)  # raises the reader's error
        self.doc = tx.base.document
        self.structure, self.kw = identifier_settings(self.doc, str(self.model_path))
        self.estimator = estimator_of(self.doc, str(self.model_path))
        stated = [name for name, v in (("a controller loop", settings.controller_loop),
                                       ("a gyro filter", settings.gyro_filter)) if v is not None]
        if stated and self.estimator != "ml":  # as heli identify refuses them
            raise RefreshError(f"{self.model_path}: {' and '.join(stated)} {'is' if len(stated) == 1 else 'are'} flown "
                               "by the maximum-likelihood estimator's check only; this model was identified by the "
                               f"{self.estimator} method")
        self.old_sources = self.doc.sources
        self.show = (len(new_paths) > 1) if settings.progress is None else settings.progress
        self.seeds = np.random.SeedSequence(settings.seed).spawn(3)

    def identifier(self):
        """An unfitted identifier of the model's method, structure and settings."""
        from .identify import make_identifier

        # the drift table compares the same parameters on both sides: no term selection there
        return make_identifier(self.estimator, self.structure,
                               **{k: v for k, v in self.kw.items() if k != "select_terms"})

    def uncertainty(self, fitted, flights, seq, desc: str) -> BootstrapResult:
        """Standard errors of a fit: Fisher information (maximum likelihood) or the interval bootstrap."""
        if self.estimator == "ml":
            return fisher_result(fitted, compared_parameters(fitted, self.estimator))
        s = self.settings
        _say(s, f"{desc}: {s.n_replicates} replicates")
        return interval_bootstrap(flights, fitted, s.n_replicates, s.block, seq, progress=bool(self.show), desc=desc)

    def fitted(self, paths, what: str, why: str, segments=None, loops=None, filters=None):
        """(flights, the model's identifier fitted on them), the step announced with ``why``; ``segments``,
        ``loops`` and ``filters``: the stretch of each log, the controller loop of its inputs and its gyro filter its
        model recorded (:func:`_read_flights`)."""
        n = len(paths)
        _say(self.settings, f"reading and fitting {n} {what} flight{'s' if n != 1 else ''} "
                            f"({'maximum likelihood' if self.estimator == 'ml' else 'integral method'}) {why}")
        flights = _read_flights(paths, f"reading {what} flights", self.show, segments, loops, self.doc.sample_rate,
                                filters)
        return flights, self.identifier().fit(flights)

    def run(self) -> RefreshResult:
        """Steps 1-6 of the module docstring; the files are staged in the transaction."""
        s = self.settings
        digests = [sha256_of(p) for p in self.new_paths]
        check_new_flights(self.new_paths, digests, self.old_sources, self.tx.base.entries)
        flights, new_ident = self.fitted(self.new_paths, "new", "for the drift table",
                                         [s.segment] * len(self.new_paths), [s.controller_loop] * len(self.new_paths),
                                         [s.gyro_filter] * len(self.new_paths))
        boot_new = self.uncertainty(new_ident, flights, self.seeds[0], "bootstrap (new flights)")
        names = list(boot_new.names)
        previous = self.previous(names, boot_new)
        z_crit = critical_z(s.alpha, len(names))
        drift = drift_table(self.tx.base.params.values(), boot_new, previous.std_errors, previous.source,
                            previous.ci, z_crit, s.min_relative)
        flagged = [r.name for r in drift if r.flagged]
        mode, reason = self.choose_fit(previous, flagged)
        fit_flights = flights + (previous.flights if mode == "pooled" else [])
        boot_model, model_fit = boot_new, new_ident
        if mode == "pooled":
            if self.estimator != "integral":
                _say(s, f"fitting the {len(fit_flights)} pooled flights for the refreshed model's uncertainty")
            pooled = self.identifier() if self.estimator == "integral" else self.identifier().fit(fit_flights)
            boot_model = self.uncertainty(pooled, fit_flights, self.seeds[2], "bootstrap (refreshed model)")
            model_fit = pooled if self.estimator != "integral" else None
        criterion = {"alpha": s.alpha, "z": z_crit, "n_parameters": len(names), "min_relative": s.min_relative,
                     "rule": "|new - old| > z * sqrt(se_old^2 + se_new^2), z = Phi^-1(1 - alpha / (2 m))"
                     + (" and |new - old| >= min_relative * |old|" if s.min_relative > 0 else "")}
        read = [f"{Path(p).name}: {w}" for p, f in zip(self.new_paths, flights)  # what reading a new flight changed
                for w in f.metadata.get("import_warnings") or ()]
        result = RefreshResult(drift, criterion, mode, reason, {"found": previous.found, "missing": previous.missing},
                               boot_new, previous.bootstrap, boot_model, None, None, {}, read + previous.notes)
        self.stage(result, fit_flights, digests, flights, new_ident, self.as_written(model_fit))
        return result

    def as_written(self, fitted) -> dict:
        """``fitted`` (fitted on the refreshed model's flights, or None) by structure where it is the fit
        :func:`~identification.workflows.identify.identify_and_report` would make of them, so that it is not made
        twice: the drift table's identifier leaves out the term selection a coupled ML model is written with."""
        same = self.estimator == "integral" or self.structure == "decoupled" and not self.kw.get("select_terms")
        return {self.structure: fitted} if fitted is not None and same else {}

    def previous(self, names, boot_new: BootstrapResult) -> _Previous:
        """The current model's uncertainty: its flights refitted and bootstrapped when all are at hand, else
        what ``model.json`` recorded or the new flights' scaled (module docstring, step 3)."""
        search = [self.tx.root] + list(dict.fromkeys(p.resolve().parent for p in self.new_paths))
        found, missing = find_source_flights(self.old_sources, search, self.settings.previous_flights)
        if not (self.old_sources and not missing):
            se_old, se_source, note = previous_std_errors(self.doc, names, boot_new, self.tx.base.entries,
                                                          self.old_sources, self.estimator)
            return _Previous(found, missing, [], None, se_old, se_source, None, [note] if note else [])
        old_flights, old_ident = self.fitted([f["path"] for f in found], "previous", "for the current model's "
                                             "uncertainty", [f.get("segment") for f in found],
                                             [f.get("controller_loop_hz") for f in found],
                                             [f.get("gyro_filter_hz") for f in found])
        boot_old = self.uncertainty(old_ident, old_flights, self.seeds[1], "bootstrap (previous flights)")
        old_params = self.tx.base.params
        diff = max((abs(old_ident.params_.get(k) - old_params.get(k)) / max(abs(old_params.get(k)), 1e-12)
                    for k in names), default=0.0)
        notes = []
        if diff > REPRODUCE_RTOL:
            notes.append(f"refitting the previous flights gives parameters up to {diff:.2g} (relative) away from "
                         "model.json; the table compares against model.json and takes its uncertainty from the refit")
        return _Previous(found, missing, old_flights, boot_old, dict(boot_old.std_errors),
                         "bootstrap" if self.estimator == "integral" else "Fisher", dict(boot_old.ci), notes)

    def choose_fit(self, previous: _Previous, flagged) -> tuple[str, str]:
        """Which flights the refreshed model is fitted on, and why (module docstring, step 5)."""
        fit, missing = self.settings.fit, previous.missing
        have_old = bool(self.old_sources) and not missing
        if fit == "pooled" and not have_old:
            raise RefreshError(
                "fit='pooled' needs the previous model's flights; not found: "
                + ", ".join(f"{m.get('file')} (SHA-256 {str(m.get('sha256'))[:12]}…)" for m in missing)
                + (" (model.json records no sources)" if not self.old_sources else "")
                + "; pass them with --previous-flights or refresh with --fit new"
            )
        if fit == "pooled":
            return "pooled", "pooled on request (--fit pooled)"
        if fit == "new":
            return "new", "new flights alone on request (--fit new)"
        if not have_old:
            return "new", ("new flights alone: the previous flights are not at hand ("
                           + ", ".join(str(m.get("file")) for m in missing) + " missing)"
                           if self.old_sources else "new flights alone: model.json records no source flights")
        if flagged:
            return "new", ("new flights alone: " + ", ".join(flagged) + " changed significantly, so the previous "
                           "flights no longer describe this aircraft")
        return "pooled", "pooled previous and new flights: no parameter changed significantly"

    def stage(self, result: RefreshResult, fit_flights, digests, flights, new_ident, fitted: dict) -> None:
        """Step 6: keep the files a refresh replaces in ``history/``, identify and report the refreshed model
        with the new flights' winds as a library version
        (:func:`identification.workflows.identify.identify_and_report`),
        and write ``refresh.json`` and ``refresh.md``; all is committed when the transaction ends (``fitted``:
        :meth:`as_written`'s identifiers, not fitted again). Sets ``result.run``, ``result.library_version`` and
        ``result.paths``."""
        from .identify import identify_and_report, segment_read, source_entry

        tx, s = self.tx, self.settings
        pooled = result.fit == "pooled"
        kept = _keep_in_history(tx.root)
        old_digest = tx.base.model_sha256
        new_sources = [source_entry(p, sha, segment_read(s.segment, f), s.controller_loop, s.gyro_filter)
                       for p, sha, f in zip(self.new_paths, digests, flights)]
        created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        record = {
            "created": created,
            "previous_model": {"sha256": old_digest, "kept_as": f"history/model-{old_digest[:12]}.json",
                               "sources": [s.to_dict() for s in self.old_sources]},
            "new_sources": new_sources,
            "fit": result.fit, "reason": result.reason, "flagged": result.flagged,
            "drift_file": "refresh.json",
            "bootstrap": result.bootstrap_model.to_dict(),
        }
        fit_paths = [str(p) for p in self.new_paths] + (
            [f["path"] for f in result.previous_flights["found"]] if pooled else [])
        checked = self.validation(list(digests) + ([f["sha256"] for f in result.previous_flights["found"]]
                                                   if pooled else []), fit_flights[0].sample_rate)
        result.notes += checked.notes
        run = identify_and_report(
            fit_flights, tx.root, coupled=self.structure == "coupled",
            sources=new_sources + ([s.to_dict() for s in self.old_sources] if pooled else []), identifier_kwargs=self.kw,
            flight_paths=fit_paths, plots=s.plots, disturbances=True, progress=self.show,
            wind_flights=range(len(flights)), model_extra={"refresh": record}, backend=s.backend,
            method=self.estimator, transaction=tx, draw_figures=False,
            stage=None if s.stage is None else (lambda text: s.stage(f"refreshed model: {text}")),
            validate_flights=checked.flights, validate_names=checked.names, validate_paths=checked.paths,
            carried_validation=checked.carried, fitted=fitted,
        )
        result.run, result.library_version = run, run.library_version
        doc_out = self.document(result, record, flights, new_ident, kept)
        paths = dict(run.paths)
        paths["refresh_json"] = tx.write_report("refresh.json",
                                                json.dumps(jsonable(doc_out), indent=2, allow_nan=False) + "\n")
        paths["refresh_md"] = tx.write_report("refresh.md", refresh_markdown(result, doc_out))
        result.paths = paths

    def validation(self, fitted_sha256, sample_rate: float):
        """The earlier model's ``--validate`` flights for the refreshed one (fitted on ``fitted_sha256``):
        validated again where found, else carried over marked
        (:func:`identification.workflows.refresh_validation.kept_validation`)."""
        from .refresh_validation import kept_validation

        search = [self.tx.root, *dict.fromkeys(Path(p).resolve().parent for p in self.new_paths), Path.cwd()]
        return kept_validation(self.doc.validation_flights, self.tx.base.model_sha256, search, self.settings.previous_flights or (),
                               fitted_sha256, sample_rate)

    def document(self, result: RefreshResult, record: dict, flights, new_ident, kept) -> dict:
        """``refresh.json``: the drift table with what it compared, the decision and the library's new version."""
        tx, run = self.tx, result.run
        old_params = tx.base.params
        taus = {"previous": dict(zip(AXES, old_params.taus)), "new flights": dict(zip(AXES, new_ident.params_.taus)),
                "refreshed": dict(zip(AXES, run.params.taus))}
        return {
            "schema": REFRESH_SCHEMA, "schema_version": REFRESH_SCHEMA_VERSION, "created": record["created"],
            "model_dir": str(tx.root), "structure": self.structure,
            "previous_model": record["previous_model"],
            "new_flights": [s | {"duration_s": f.duration} for s, f in zip(record["new_sources"], flights)],
            "previous_flights": result.previous_flights,
            "criterion": result.criterion,
            "bootstrap_seed": self.settings.seed,
            "drift": [r.to_dict() for r in result.drift],
            "flagged": result.flagged,
            "servo_delay_s": taus,
            "fit": result.fit, "reason": result.reason,
            "refreshed_parameters": {k: run.params.get(k) for k in result.bootstrap_new.names},
            "estimator": self.estimator,
            "flight_offsets": ({a: {"new flights": list(f.flight_offsets)} for a, f in new_ident.axes_.items()}
                               if self.estimator == "ml" else None),
            "bootstrap": {"new": result.bootstrap_new.to_dict(),
                          "previous": result.bootstrap_old.to_dict() if result.bootstrap_old else None,
                          "refreshed": result.bootstrap_model.to_dict()},
            "library": {"previous_version": tx.base.library_version, "version": run.library_version,
                        "added": [p.source for p in run.disturbances]},
            "model_sha256": tx.model_sha256,
            "kept_in_history": [str(p.relative_to(tx.root)) for p in kept],
            "notes": result.notes,
        }
