"""Refresh an identified model with new flights: parameter drift, the refreshed model, a larger wind library.

:func:`refresh_model` is what ``heli refresh MODEL_DIR NEW_FLIGHT...`` runs on a
directory written by ``heli identify``:

1. **Refuse duplicates.** A new flight whose file SHA-256 is already among the
   model's sources or the disturbance library's traces (or given twice) raises
   :class:`DuplicateFlightError` before anything is written: its intervals would
   be counted twice and its wind replayed twice as often.
2. **Identify the new flights alone** with the model's own structure and settings
   (``model.json`` ``"structure"``, ``"identification"``, ``"filter"``,
   ``"added_terms"``), so that the comparison with the current model involves two
   independent data sets.
3. **Uncertainty** of both by the interval bootstrap
   (:func:`identification.bootstrap.interval_bootstrap`). The current model's
   source flights are looked for by name and SHA-256 (``model.json`` provenance) in
   the model directory, beside the new flights and among ``previous_flights``; when
   all are at hand they are bootstrapped too (and refitted, to check they still
   give the current model). Otherwise the previous standard errors come from the
   bootstrap recorded in ``model.json`` by an earlier refresh, or else the new
   flights' bootstrap scaled by ``sqrt(n_new / n_old)`` intervals (the old interval
   count from the library's record of the source flights' durations; equal counts
   when unknown). The residual-based standard errors of the fit are never used:
   they are 4-6 times too small (see :mod:`identification.bootstrap`).
4. **Drift and flags.** Per parameter Δ = new − old; it is flagged when
   ``|Δ| > z·sqrt(se_old² + se_new²)`` (and ``|Δ| >= min_relative·|old|``), with
   ``z = Φ⁻¹(1 − α/(2m))`` for the ``m`` parameters compared (Bonferroni: a false
   flag anywhere in the table has probability about α when nothing changed).
5. **The refreshed model.** ``fit="auto"`` pools the previous and the new flights
   (eq. 35 over all intervals: the most data) when the previous flights are at hand
   and nothing is flagged; when a parameter changed, the old flights describe an
   aircraft that no longer exists, so the model is fitted on the new flights alone
   (as it is when the old flights are missing). ``"pooled"`` and ``"new"`` force
   the choice. The model is written by
   :func:`identification.report.identify_and_report` (the replaced ``model.json``
   is kept under ``history/``, and so are the replaced ``report.md``, figures and
   previous refresh files), which identifies each *new* flight's wind with the
   refreshed model (eqs. 41-47) and appends the traces to the library as one new
   version (earlier versions untouched).
6. **Provenance.** ``model.json`` gets a ``"refresh"`` entry (previous model's
   SHA-256 and history file, its sources, the new sources, the fit decision, the
   flags and the written model's bootstrap standard errors, which the next refresh
   uses when these flights are gone); ``refresh.json`` and ``refresh.md`` hold the
   drift table.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .bootstrap import DEFAULT_REPLICATES, BootstrapResult, interval_bootstrap
from model_store import ModelDir
from model_store.model_file import MODEL_FILENAME, load_model

from .errors import LibraryError, ModelFileError
from .files import jsonable, keep_copy, sha256_of
from .terms import AXES, TERMS

REFRESH_SCHEMA = "heli-env/refresh"
REFRESH_SCHEMA_VERSION = 1
FIT_CHOICES = ("auto", "pooled", "new")
KEPT_FILES = ("report.md", "refresh.md", "refresh.json")
"""Top-level files of a model directory a refresh replaces; copied to ``history/`` first (with the PNG figures)."""
REPRODUCE_RTOL = 1e-6
"""Relative agreement expected between ``model.json`` and a refit of its source flights."""


class RefreshError(ModelFileError):
    """A model directory cannot be refreshed as asked (unknown structure, previous flights missing for pooling, bad option)."""


class DuplicateFlightError(LibraryError):
    """A new flight is already part of the model or of its disturbance library (same SHA-256)."""


# ------------------------------------------------------------------ results
@dataclass(frozen=True)
class ParameterDrift:
    """One row of the drift table.

    Attributes
    ----------
    name, unit : str
        Parameter (the paper's name) and its unit.
    old, new : float
        Value in the current model and fitted on the new flights alone.
    delta : float
        ``new - old``.
    relative : float
        ``delta / |old|`` (NaN when old is 0).
    se_old, se_new : float
        Standard errors [parameter unit]; ``se_old_source`` says where the first came from.
    se_old_source : str
        ``"bootstrap"``, ``"recorded bootstrap"`` or ``"scaled from the new flights"``.
    ci_old, ci_new : tuple of float
        Percentile bootstrap intervals (``ci_old`` NaN unless the old flights were bootstrapped).
    z : float
        ``|delta| / sqrt(se_old² + se_new²)``.
    threshold : float
        Critical ``z`` of the flag.
    flagged : bool
        Significant change (see :func:`refresh_model`).
    """

    name: str
    unit: str
    old: float
    new: float
    delta: float
    relative: float
    se_old: float
    se_new: float
    se_old_source: str
    ci_old: tuple
    ci_new: tuple
    z: float
    threshold: float
    flagged: bool

    def to_dict(self) -> dict:
        return jsonable(self.__dict__)


@dataclass
class RefreshResult:
    """What :func:`refresh_model` found and wrote.

    Attributes
    ----------
    drift : list of ParameterDrift
    criterion : dict
        ``alpha``, ``z``, ``n_parameters``, ``min_relative`` and the rule in words.
    fit : str
        ``"pooled"`` (previous + new flights) or ``"new"`` (new flights alone).
    reason : str
        Why that fit was chosen.
    previous_flights : dict
        ``found`` (list of {file, sha256, path}) and ``missing`` (list of {file, sha256}).
    bootstrap_new, bootstrap_old, bootstrap_model : BootstrapResult or None
        New flights; previous flights (when at hand); the written model.
    run : IdentificationRun
        The identification that wrote ``model.json``, ``report.md`` and the library version.
    library_version : int or None
    paths : dict of str to Path
    """

    drift: list
    criterion: dict
    fit: str
    reason: str
    previous_flights: dict
    bootstrap_new: BootstrapResult
    bootstrap_old: BootstrapResult | None
    bootstrap_model: BootstrapResult
    run: object
    library_version: int | None
    paths: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    @property
    def flagged(self) -> list[str]:
        """Names of the parameters whose change is significant."""
        return [row.name for row in self.drift if row.flagged]


# ------------------------------------------------------------------ helpers
def estimator_of(doc: dict, where: str = "model.json") -> str:
    """Which estimator identified a model: ``"ml"`` (maximum likelihood) or ``"integral"`` (Fig. 5).

    Models written before the maximum-likelihood estimator existed record only ``method``
    ("integral (Fig. 5)"), or nothing: they are integral-method models.
    """
    ident = doc.get("identification") or {}
    est = ident.get("estimator")
    method = str(ident.get("method", "integral"))
    if est is None:
        est = "ml" if method.startswith("maximum") else ("integral" if method.startswith("integral") else None)
    if est not in ("ml", "integral"):
        raise RefreshError(f"{where}: identified by {method!r}; refresh re-identifies with the maximum-likelihood "
                           "or the integral method only")
    return est


def fisher_result(identifier, names) -> BootstrapResult:
    """The maximum-likelihood fit's uncertainty in the drift table's form: Fisher standard errors, 95 % normal intervals."""
    from scipy import stats

    est, se = {}, {}
    for fit in identifier.axes_.values():
        est.update(fit.params)
        se.update(fit.std_errors)
    z = float(stats.norm.ppf(0.975))
    n = sum(int(round(f.duration)) for f in identifier.flights_)
    return FisherResult(tuple(names), {k: est[k] for k in names}, np.empty((0, len(names))),
                        {k: se[k] for k in names}, {k: (est[k] - z * se[k], est[k] + z * se[k]) for k in names},
                        0.95, 0, 0, n, 0, None, tuple(identifier.params_.taus))


class FisherResult(BootstrapResult):
    """Uncertainty from the Fisher information of a maximum-likelihood fit (no replicates)."""

    def to_dict(self) -> dict:
        out = super().to_dict()
        out["method"] = "Fisher information of the innovations (maximum likelihood)"
        for k in ("n_replicates", "n_failed", "block_intervals", "seed"):
            out.pop(k)
        out["n_seconds"] = out.pop("n_intervals")
        return out


def compared_parameters(identifier, estimator: str) -> list[str]:
    """Parameters the drift table compares: every fitted one, less the offsets kd of a maximum-likelihood fit.

    With a wind state in the model the offsets are each flight's trim plus that day's mean wind
    (:attr:`identification.ml_estimator.MLAxisFit.flight_offsets`): they change from flight to flight
    without the aircraft changing, so they are reported per flight and not flagged.
    """
    names = [k for fit in identifier.axes_.values() for k in fit.params]
    return [k for k in names if not (estimator == "ml" and TERMS[k].effect == "offset")]


def identifier_settings(doc: dict, where: str = "model.json") -> tuple[str, dict]:
    """Structure and identifier keyword arguments the model was identified with (see :func:`estimator_of`).

    Raises
    ------
    RefreshError
        A structure ``heli identify`` does not write (``"custom"``), or an unknown method.
    """
    structure = doc.get("structure")
    if structure not in ("decoupled", "coupled"):
        raise RefreshError(
            f"{where}: structure {structure!r} cannot be refreshed; expected 'decoupled' or 'coupled' "
            "(a model written by 'heli identify')"
        )
    ident = doc.get("identification") or {}
    estimator = estimator_of(doc, where)
    keys = (("input_hold", "wind_model", "remove_vibration", "vibration_min_hz", "max_nfev", "select_terms")
            if estimator == "ml"
            else ("interval", "offsets", "disturbance_order", "input_hold", "prefilter", "max_iter", "tol"))
    kw = {k: ident[k] for k in keys if ident.get(k) is not None}
    if "delay" in ident:
        kw["delay"] = ident["delay"]
    filt = doc.get("filter") or {}
    for k in ("pass_hz", "stop_hz"):
        if filt.get(k) is not None and estimator == "integral":
            kw[k] = float(filt[k])
    extra = tuple((doc.get("added_terms") or {}).keys())
    if extra:
        kw["extra_terms"] = extra
    return structure, kw


def find_source_flights(sources, search_dirs=(), candidates=()) -> tuple[list, list]:
    """Locate a model's source flights by file name and SHA-256.

    Parameters
    ----------
    sources : sequence of dict
        ``model.json`` provenance entries ``{"file": name, "sha256": hex}``.
    search_dirs : sequence of path
        Folders where a file of the source's name is looked for.
    candidates : sequence of path
        Files given explicitly; matched by SHA-256 whatever their name.

    Returns
    -------
    found : list of dict
        ``{"file", "sha256", "path"}`` per source found (its bytes hash to the recorded SHA-256).
    missing : list of dict
        Sources not found (or found with other content: ``"note"`` says so).
    """
    by_sha = {}
    for c in candidates:
        c = Path(c)
        if not c.is_file():
            raise FileNotFoundError(f"previous flight {str(c)!r} does not exist")
        by_sha.setdefault(sha256_of(c), c)
    found, missing = [], []
    for src in sources:
        name, sha = src.get("file"), src.get("sha256")
        path = by_sha.get(sha)
        note = None
        if path is None and name:
            for d in search_dirs:
                p = Path(d) / Path(name).name
                if p.is_file():
                    if sha256_of(p) == sha:
                        path = p
                        break
                    note = f"{p} has other content (SHA-256 differs)"
        if path is not None:
            found.append({"file": name, "sha256": sha, "path": str(path)})
        else:
            missing.append({"file": name, "sha256": sha} | ({"note": note} if note else {}))
    return found, missing


def _check_new_flights(paths, digests, model_sources, library_entries) -> None:
    """Raise :class:`DuplicateFlightError` for a new flight already in the model or library, or given twice."""
    problems = []
    seen = {}
    in_model = {s.get("sha256"): s.get("file") for s in model_sources}
    in_library = {}
    for e in library_entries:
        src = e.get("source") or {}
        if src.get("sha256"):
            in_library.setdefault(src["sha256"], e)
    for path, sha in zip(paths, digests):
        name = Path(path).name
        if sha in seen:
            problems.append(f"{name} is the same file as {Path(seen[sha]).name} (SHA-256 {sha[:12]}…)")
            continue
        seen[sha] = path
        if sha in in_library:
            e = in_library[sha]
            problems.append(
                f"{name} (SHA-256 {sha[:12]}…) is already in the disturbance library as trace {e.get('id')} "
                f"(from {(e.get('source') or {}).get('name')!r}, added in version {e.get('added_in_version')})"
            )
        elif sha in in_model:
            problems.append(f"{name} (SHA-256 {sha[:12]}…) is already a source of model.json (as {in_model[sha]!r})")
    if problems:
        raise DuplicateFlightError(
            "expected flights new to this model; " + "; ".join(problems)
            + ". Refreshing with them again would count their intervals twice and duplicate their wind traces"
        )


def _keep_in_history(root: Path) -> list[Path]:
    """Copy the files a refresh replaces to ``history/`` (see :func:`.files.keep_copy`); returns the copies."""
    files = [root / n for n in KEPT_FILES] + sorted(root.glob("*.png"))
    return [keep_copy(path) for path in files if path.is_file()]


def critical_z(alpha: float, m: int) -> float:
    """Two-sided Bonferroni critical value ``Φ⁻¹(1 − α/(2m))``."""
    from scipy import stats

    return float(stats.norm.ppf(1.0 - alpha / (2.0 * max(int(m), 1))))


def drift_table(old_values: dict, new: BootstrapResult, se_old: dict, se_old_source: str, ci_old: dict | None,
                z_crit: float, min_relative: float = 0.0) -> list[ParameterDrift]:
    """Rows of the drift table for the parameters ``new`` bootstrapped (vectorised over parameters)."""
    names = list(new.names)
    old = np.array([float(old_values[k]) for k in names])
    est = np.array([float(new.estimate[k]) for k in names])
    s_old = np.array([float(se_old[k]) for k in names])
    s_new = np.array([float(new.std_errors[k]) for k in names])
    delta = est - old
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(old != 0, delta / np.abs(old), np.nan)
        se = np.hypot(s_old, s_new)
        z = np.where(se > 0, np.abs(delta) / se, np.where(delta != 0, np.inf, 0.0))
    flagged = (z > z_crit) & (np.abs(delta) >= min_relative * np.abs(old))
    nan2 = (float("nan"), float("nan"))
    return [
        ParameterDrift(k, TERMS[k].unit, float(old[i]), float(est[i]), float(delta[i]), float(rel[i]),
                       float(s_old[i]), float(s_new[i]), se_old_source,
                       tuple(ci_old[k]) if ci_old else nan2, tuple(new.ci[k]), float(z[i]), z_crit,
                       bool(flagged[i]))
        for i, k in enumerate(names)
    ]


def _previous_se(doc: dict, names, new: BootstrapResult, library_entries, old_sources):
    """Standard errors of the current model when its flights are not at hand (module docstring, step 3)."""
    record = (doc.get("refresh") or {}).get("bootstrap") or {}
    recorded = record.get("std_errors") or {}
    if all(isinstance(recorded.get(k), (int, float)) for k in names):
        label = "recorded Fisher information" if str(record.get("method", "")).startswith("Fisher") else \
            "recorded bootstrap"
        return {k: float(recorded[k]) for k in names}, label, None
    if estimator_of(doc) == "ml":  # the fit's own Fisher errors, recorded by heli identify
        fisher = {}
        for axis in ((doc.get("fit_statistics") or {}).get("axes") or {}).values():
            fisher.update(axis.get("std_errors") or {})
        if all(isinstance(fisher.get(k), (int, float)) for k in names):
            return {k: float(fisher[k]) for k in names}, "Fisher information recorded in model.json", None
    durations = {}
    for e in library_entries:
        sha = (e.get("source") or {}).get("sha256")
        if sha and e.get("duration_s"):
            durations[sha] = float(e["duration_s"])
    shas = [s.get("sha256") for s in old_sources]
    interval = float(((doc.get("identification") or {}).get("interval")) or 1.0)
    if shas and all(s in durations for s in shas):
        n_old = sum(math.floor(durations[s] / interval + 1e-9) for s in shas)
        ratio = math.sqrt(new.n_intervals / max(n_old, 1))
        note = (f"previous standard errors scaled from the new flights' bootstrap by sqrt({new.n_intervals}/{n_old}) "
                "intervals (previous flights not at hand; their durations from the disturbance library)")
    else:
        ratio = 1.0
        note = ("previous standard errors taken equal to the new flights' bootstrap (previous flights not at hand "
                "and their durations unknown)")
    return {k: float(new.std_errors[k]) * ratio for k in names}, "scaled from the new flights", note


# ------------------------------------------------------------------ the refresh
def refresh_model(model_dir, new_flights, *, previous_flights=(), fit: str = "auto",
                  n_replicates: int = DEFAULT_REPLICATES, block: int = 1, seed: int = 0, alpha: float = 0.05,
                  min_relative: float = 0.0, plots: bool = True, progress: bool | None = None,
                  backend=None, wait: bool = True) -> RefreshResult:
    """Refresh the model in ``model_dir`` with new flights (module docstring).

    Parameters
    ----------
    model_dir : str or Path
        A directory written by ``heli identify`` (``model.json``, optionally ``disturbances/``).
    new_flights : sequence of path
        Canonical flight logs not yet in the model.
    previous_flights : sequence of path
        Where the current model's source flights are, if not in ``model_dir`` or beside the new flights.
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
    backend : None, {"local", "ray"} or identification.backends.Backend
        Where the new flights' winds are identified, one task per flight
        (:func:`identification.report.identify_and_report`); None: in this process.
    wait : bool
        Wait for another command writing ``model_dir`` (default, saying so), or raise
        :class:`~identification.errors.ModelDirBusyError`. The folder is locked from reading the current model
        to writing the refreshed one, and everything is written as one transaction
        (:class:`model_store.ModelDir`): after a crash it holds the model before or after the refresh.

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
    if fit not in FIT_CHOICES:
        raise RefreshError(f"fit must be one of {FIT_CHOICES}, got {fit!r}")
    if not 0.0 < alpha < 1.0:
        raise RefreshError(f"alpha must lie in (0, 1), got {alpha!r}")
    if not min_relative >= 0.0:
        raise RefreshError(f"min_relative must be >= 0, got {min_relative!r}")
    new_paths = [Path(p) for p in new_flights]
    if not new_paths:
        raise RefreshError("expected at least one new flight, got none")
    root = Path(model_dir)
    if root.suffix == ".json":
        root = root.parent
    load_model(root / MODEL_FILENAME)  # a missing or corrupt model is named before anything is locked or made
    for p in new_paths:
        if not p.is_file():
            raise FileNotFoundError(f"new flight {str(p)!r} does not exist")
    options = dict(previous_flights=previous_flights, fit=fit, n_replicates=n_replicates, block=block, seed=seed,
                   alpha=alpha, min_relative=min_relative, plots=plots, progress=progress, backend=backend)
    with ModelDir(root).transaction(wait=wait, what="refresh") as tx:
        result = _refresh(tx, new_paths, **options)
    if result.run.figures:
        result.paths.update(result.run.draw_figures())
    return result


def _refresh(tx, new_paths, *, previous_flights, fit, n_replicates, block, seed, alpha, min_relative, plots, progress,
             backend) -> RefreshResult:
    """The refresh of :func:`refresh_model` inside its transaction ``tx``: read, compute, stage the files."""
    from tqdm import tqdm

    from .io import read_flight
    from .report import identify_and_report, make_identifier, source_entry

    root = tx.root
    model_path = root / MODEL_FILENAME
    if tx.base.params is None:
        load_model(model_path)  # raises the reader's error
    old_params, doc = tx.base.params, tx.base.document
    structure, kw = identifier_settings(doc, str(model_path))
    old_sources = list((doc.get("provenance") or {}).get("sources") or [])
    entries, previous_version = tx.base.entries, tx.base.library_version

    show = (len(new_paths) > 1) if progress is None else progress
    digests = [sha256_of(p) for p in new_paths]
    _check_new_flights(new_paths, digests, old_sources, entries)
    # the bar only on a terminal (disable=None: tqdm's own check; off one a failing read's error would land on
    # the bar's line), closed on an error too
    with tqdm(new_paths, desc="reading new flights", unit="flight", disable=None if show else True) as bar:
        flights = [read_flight(p) for p in bar]

    # -- uncertainty: the new flights alone, and the previous flights when at hand
    seeds = np.random.SeedSequence(seed).spawn(3)
    estimator = estimator_of(doc, str(model_path))

    def identifier():
        # the drift table compares the same parameters on both sides: no term selection there
        return make_identifier(estimator, structure, **{k: v for k, v in kw.items() if k != "select_terms"})

    def uncertainty(fitted, fit_flights, seq, desc):
        if estimator == "ml":
            return fisher_result(fitted, compared_parameters(fitted, estimator))
        return interval_bootstrap(fit_flights, fitted, n_replicates, block, seq, progress=bool(show), desc=desc)

    new_ident = identifier().fit(flights)
    boot_new = uncertainty(new_ident, flights, seeds[0], "bootstrap (new flights)")
    names = list(boot_new.names)
    search = [root] + list(dict.fromkeys(p.resolve().parent for p in new_paths))
    found, missing = find_source_flights(old_sources, search, previous_flights)
    have_old = bool(old_sources) and not missing
    notes = []
    boot_old, old_flights = None, []
    if have_old:
        old_flights = [read_flight(s["path"]) for s in tqdm(found, desc="reading previous flights", unit="flight",
                                                            disable=None if show else True)]
        old_ident = identifier().fit(old_flights)
        boot_old = uncertainty(old_ident, old_flights, seeds[1], "bootstrap (previous flights)")
        diff = max((abs(old_ident.params_.get(k) - old_params.get(k)) / max(abs(old_params.get(k)), 1e-12)
                    for k in names), default=0.0)
        if diff > REPRODUCE_RTOL:
            notes.append(f"refitting the previous flights gives parameters up to {diff:.2g} (relative) away from "
                         "model.json; the table compares against model.json and takes its uncertainty from the refit")
        se_old, se_source, ci_old = (dict(boot_old.std_errors), "bootstrap" if estimator == "integral" else "Fisher",
                                     dict(boot_old.ci))
    else:
        se_old, se_source, note = _previous_se(doc, names, boot_new, entries, old_sources)
        ci_old = None
        if note:
            notes.append(note)
    z_crit = critical_z(alpha, len(names))
    old_values = old_params.values()
    drift = drift_table(old_values, boot_new, se_old, se_source, ci_old, z_crit, min_relative)
    flagged = [r.name for r in drift if r.flagged]

    # -- which flights the refreshed model is fitted on
    if fit == "pooled" and not have_old:
        raise RefreshError(
            "fit='pooled' needs the previous model's flights; not found: "
            + ", ".join(f"{m.get('file')} (SHA-256 {str(m.get('sha256'))[:12]}…)" for m in missing)
            + (" (model.json records no sources)" if not old_sources else "")
            + "; pass them with --previous-flights or refresh with --fit new"
        )
    if fit == "pooled":
        mode, reason = "pooled", "pooled on request (--fit pooled)"
    elif fit == "new":
        mode, reason = "new", "new flights alone on request (--fit new)"
    elif not have_old:
        mode, reason = "new", ("new flights alone: the previous flights are not at hand ("
                               + ", ".join(str(m.get("file")) for m in missing) + " missing)"
                               if old_sources else "new flights alone: model.json records no source flights")
    elif flagged:
        mode, reason = "new", ("new flights alone: " + ", ".join(flagged) + " changed significantly, so the previous "
                               "flights no longer describe this aircraft")
    else:
        mode, reason = "pooled", "pooled previous and new flights: no parameter changed significantly"
    fit_flights = flights + (old_flights if mode == "pooled" else [])
    fit_paths = [str(p) for p in new_paths] + ([s["path"] for s in found] if mode == "pooled" else [])
    boot_model = boot_new
    if mode == "pooled":
        pooled = identifier() if estimator == "integral" else identifier().fit(fit_flights)
        boot_model = uncertainty(pooled, fit_flights, seeds[2], "bootstrap (refreshed model)")

    # -- stage: the files a refresh replaces are kept in history/, the model + report + library version
    # (identify_and_report) and the drift files are committed together when the transaction ends
    kept = _keep_in_history(root)
    old_digest = tx.base.model_sha256
    new_sources = [source_entry(p, sha) for p, sha in zip(new_paths, digests)]
    sources = new_sources + (old_sources if mode == "pooled" else [])
    created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    record = {
        "created": created,
        "previous_model": {"sha256": old_digest, "kept_as": f"history/model-{old_digest[:12]}.json",
                           "sources": old_sources},
        "new_sources": new_sources,
        "fit": mode, "reason": reason, "flagged": flagged,
        "drift_file": "refresh.json",
        "bootstrap": boot_model.to_dict(),
    }
    run = identify_and_report(
        fit_flights, root, coupled=structure == "coupled", sources=sources, identifier_kwargs=kw,
        flight_paths=fit_paths, plots=plots, disturbances=True, progress=show,
        wind_flights=range(len(flights)), model_extra={"refresh": record}, backend=backend, method=estimator,
        transaction=tx, draw_figures=False,
    )
    library_version = run.library_version
    paths = dict(run.paths)
    result = RefreshResult(
        drift, {"alpha": alpha, "z": z_crit, "n_parameters": len(names), "min_relative": min_relative,
                "rule": "|new - old| > z * sqrt(se_old^2 + se_new^2), z = Phi^-1(1 - alpha / (2 m))"
                + (" and |new - old| >= min_relative * |old|" if min_relative > 0 else "")},
        mode, reason, {"found": found, "missing": missing}, boot_new, boot_old, boot_model, run, library_version,
        paths, notes,
    )
    taus = {"previous": dict(zip(AXES, old_params.taus)), "new flights": dict(zip(AXES, new_ident.params_.taus)),
            "refreshed": dict(zip(AXES, run.params.taus))}
    doc_out = {
        "schema": REFRESH_SCHEMA, "schema_version": REFRESH_SCHEMA_VERSION, "created": created,
        "model_dir": str(root), "structure": structure,
        "previous_model": record["previous_model"],
        "new_flights": [s | {"duration_s": f.duration} for s, f in zip(new_sources, flights)],
        "previous_flights": {"found": found, "missing": missing},
        "criterion": result.criterion,
        "bootstrap_seed": seed,
        "drift": [r.to_dict() for r in drift],
        "flagged": flagged,
        "servo_delay_s": taus,
        "fit": mode, "reason": reason,
        "refreshed_parameters": {k: run.params.get(k) for k in names},
        "estimator": estimator,
        "flight_offsets": ({a: {"new flights": list(f.flight_offsets)} for a, f in new_ident.axes_.items()}
                           if estimator == "ml" else None),
        "bootstrap": {"new": boot_new.to_dict(), "previous": boot_old.to_dict() if boot_old else None,
                      "refreshed": boot_model.to_dict()},
        "library": {"previous_version": previous_version, "version": library_version,
                    "added": [p.source for p in run.disturbances]},
        "model_sha256": tx.model_sha256,
        "kept_in_history": [str(p.relative_to(root)) for p in kept],
        "notes": notes,
    }
    paths["refresh_json"] = tx.write_report("refresh.json",
                                            json.dumps(jsonable(doc_out), indent=2, allow_nan=False) + "\n")
    paths["refresh_md"] = tx.write_report("refresh.md", refresh_markdown(result, doc_out))
    result.paths = paths
    return result


# ------------------------------------------------------------------ report
def _fmt(v: float, digits: int = 4) -> str:
    return "—" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


def refresh_markdown(result: RefreshResult, doc: dict) -> str:
    """``refresh.md``: what was compared, the drift table, the decision and what the library gained."""
    level = result.bootstrap_new.level
    crit = result.criterion
    rows = []
    for r in result.drift:
        rel = "—" if not np.isfinite(r.relative) else f"{100 * r.relative:+.1f}"
        rows.append(
            f"| {r.name} | {r.unit} | {_fmt(r.old)} | {_fmt(r.se_old)} | [{_fmt(r.ci_old[0])}, {_fmt(r.ci_old[1])}] "
            f"| {_fmt(r.new)} | {_fmt(r.se_new)} | [{_fmt(r.ci_new[0])}, {_fmt(r.ci_new[1])}] | {r.delta:+.4f} | {rel} "
            f"| {r.z:.2f} | {'**yes**' if r.flagged else 'no'} |"
        )
    b = result.bootstrap_new
    prev = doc["previous_flights"]
    lines = [
        "# Model refresh",
        "",
        f"{doc['created']}: `{MODEL_FILENAME}` ({doc['structure']}, SHA-256 `{doc['previous_model']['sha256'][:12]}…`, "
        f"kept as `{doc['previous_model']['kept_as']}`) refreshed with:",
        "",
    ]
    lines += [f"- `{s['file']}` ({s['duration_s']:.1f} s, SHA-256 `{s['sha256'][:12]}…`)" for s in doc["new_flights"]]
    lines += ["", "Previous flights: "
              + (", ".join(f"`{f['file']}` found at `{f['path']}`" for f in prev["found"]) or "none found")
              + ("; missing: " + ", ".join(f"`{m['file']}`" for m in prev["missing"]) if prev["missing"] else "")
              + ".", ""]
    lines += [
        "## Parameter drift",
        "",
        f"Old: `{MODEL_FILENAME}` before the refresh (standard error: {result.drift[0].se_old_source if result.drift else '—'}). "
        "New: the same structure and settings identified on the new flights alone. "
        + (f"Standard errors and {100 * level:.0f} % percentile intervals from a moving-block bootstrap over the "
           f"integral method's intervals ({b.n_intervals} in the new flights; {b.n_replicates} replicates, blocks "
           f"of {b.block} interval(s), seed {doc['bootstrap_seed']}; servo delay held at the identified value)."
           if doc.get("estimator", "integral") == "integral" else
           "Standard errors from the Fisher information of the maximum-likelihood fit, 95 % normal intervals. "
           "The offsets kd are not compared: with a wind state in the model they are each flight's trim plus "
           "that day's mean wind, and differ between flights of an unchanged aircraft (per-flight values in "
           "`refresh.json` under `flight_offsets`)."),
        "",
        f"Flag: |Δ| > z·√(se_old² + se_new²) with z = {crit['z']:.2f} = Φ⁻¹(1 − α/(2m)), α = {crit['alpha']:g} "
        f"family-wise over m = {crit['n_parameters']} parameters (Bonferroni)"
        + (f", and |Δ| ≥ {100 * crit['min_relative']:g} % of |old|" if crit["min_relative"] > 0 else "") + ".",
        "",
        "| Parameter | Unit | Old | se old | CI old | New flights | se new | CI new | Δ | Δ (%) | z | Flag |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
    ]
    taus = doc["servo_delay_s"]
    if any(v for d in taus.values() for v in d.values()):
        lines += ["Servo delay (s; not bootstrapped, held fixed in the replicates): "
                  + "; ".join(f"{lab} " + ", ".join(f"{a} {v:.3f}" for a, v in d.items()) for lab, d in taus.items()),
                  ""]
    flagged = result.flagged
    lines += [
        "**Changed:** " + (", ".join(flagged) if flagged else "nothing beyond what the uncertainty explains") + ".",
        "",
        "## The refreshed model",
        "",
        f"Fitted on {'the previous and the new flights pooled' if result.fit == 'pooled' else 'the new flights alone'}"
        f" — {result.reason}. Its parameters and validation are in `report.md`; the "
        f"{'bootstrap' if doc.get('estimator', 'integral') == 'integral' else 'Fisher'} standard errors are "
        f"recorded in `{MODEL_FILENAME}` under `refresh.bootstrap`.",
        "",
        "| Parameter | Refreshed | se |",
        "|---|---|---|",
        *[f"| {k} | {v:.4f} | {_fmt(result.bootstrap_model.std_errors.get(k, float('nan')))} |"
          for k, v in doc["refreshed_parameters"].items()],
        "",
        "## Disturbance library",
        "",
        f"Each new flight's wind was identified with the refreshed model (eqs. 41-47) and appended as version "
        f"{doc['library']['version']} (previous version {doc['library']['previous_version']}, kept). Traces already "
        "in the library stay as they were identified (their manifest entries name the model used).",
        "",
    ]
    if result.notes:
        lines += ["## Notes", ""] + [f"- {n}" for n in result.notes] + [""]
    return "\n".join(lines)
