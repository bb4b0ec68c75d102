"""What a refresh starts from: the current model's estimator and settings, its source flights, and whether
the new flights are new (steps 1-3 of :mod:`identification.workflows.refresh`).

A refresh re-identifies with the model's own structure and settings (:func:`identifier_settings`, read from
``model.json``), looks for the flights the model was fitted on by name and SHA-256
(:func:`find_source_flights`), and refuses a new flight that is already part of the model or of its
disturbance library (:func:`check_new_flights`) before anything is fitted or written.
"""

from __future__ import annotations

from pathlib import Path

from heli_core.files import sha256_of
from model_store.errors import LibraryError, ModelFileError
from model_store.model_file import ModelDocument


class RefreshError(ModelFileError):
    """A model directory cannot be refreshed as asked (unknown structure, previous flights missing for pooling, bad
    option)."""


class DuplicateFlightError(LibraryError):
    """A new flight is already part of the model or of its disturbance library (same SHA-256)."""


def estimator_of(doc: ModelDocument, where: str = "model.json") -> str:
    """Which estimator identified a model: ``"ml"`` (maximum likelihood) or ``"integral"`` (Fig. 5)
    (:attr:`~model_store.model_file.ModelDocument.estimator`), refused for another method."""
    if doc.estimator is None:
        raise RefreshError(f"{where}: identified by {doc.method!r}; refresh re-identifies with the "
                           "maximum-likelihood or the integral method only")
    return doc.estimator


def identifier_settings(doc: ModelDocument, where: str = "model.json") -> tuple[str, dict]:
    """Structure and identifier keyword arguments the model was identified with (see :func:`estimator_of`).

    Raises
    ------
    RefreshError
        A structure ``heli identify`` does not write (``"custom"``), or an unknown method.
    """
    structure = doc.structure
    if structure not in ("decoupled", "coupled"):
        raise RefreshError(
            f"{where}: structure {structure!r} cannot be refreshed; expected 'decoupled' or 'coupled' "
            "(a model written by 'heli identify')"
        )
    ident = doc.identification
    estimator = estimator_of(doc, where)
    keys = (("input_hold", "wind_model", "remove_vibration", "vibration_min_hz", "max_nfev", "select_terms",
             "servo_lag", "closed_loop")
            if estimator == "ml"
            else ("interval", "offsets", "disturbance_order", "input_hold", "prefilter", "remove_folded", "max_iter",
                  "tol"))
    kw = {k: ident[k] for k in keys if ident.get(k) is not None}
    if "delay" in ident:
        kw["delay"] = ident["delay"]
    filt = doc.filter_settings or {}
    for k in ("pass_hz", "stop_hz"):
        if filt.get(k) is not None and estimator == "integral":
            kw[k] = float(filt[k])
    extra = tuple(name for name, _ in doc.params.extra)
    if extra:
        kw["extra_terms"] = extra
    return structure, kw


def find_source_flights(sources, search_dirs=(), candidates=()) -> tuple[list, list]:
    """Locate a model's source flights by file name and SHA-256.

    Parameters
    ----------
    sources : sequence of Source
        The model's source flights (:attr:`model_store.model_file.ModelDocument.sources`).
    search_dirs : sequence of path
        Folders where a file of the source's name is looked for.
    candidates : sequence of path
        Files given explicitly; matched by SHA-256 whatever their name.

    Returns
    -------
    found : list of dict
        ``{"file", "sha256", "path"}`` per source found (its bytes hash to the recorded SHA-256), ``"segment"``
        where the model was fitted on that stretch of the log, ``"controller_loop_hz"`` where its inputs were
        stated as a flight controller's commands from a loop at that rate and ``"gyro_filter_hz"`` where its gyro
        was stated low-passed at that corner.
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
        name, sha = src.file, src.sha256
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
            segment = getattr(src, "segment", None)  # the stretch of its log the model was fitted on
            # its inputs stated as a controller's (--controller-loop), its gyro as filtered (--gyro-filter)
            stated = {k: getattr(src, k, None) for k in ("controller_loop_hz", "gyro_filter_hz")}
            found.append({"file": name, "sha256": sha, "path": str(path)}
                         | ({"segment": tuple(segment)} if segment is not None else {})
                         | {k: v for k, v in stated.items() if v is not None})
        else:
            missing.append({"file": name, "sha256": sha} | ({"note": note} if note else {}))
    return found, missing


def check_new_flights(paths, digests, model_sources, library_entries) -> None:
    """Raise :class:`DuplicateFlightError` for a new flight already in the model or library, or given twice."""
    problems = []
    seen = {}
    in_model = {s.sha256: s.file for s in model_sources}
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
