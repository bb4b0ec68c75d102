"""The flights a model was validated on (``heli identify --validate``), kept through ``heli refresh``.

``model.json``'s ``fit_statistics.validation_flights`` holds the model's scores on flights it was not fitted on
(:mod:`identification.validation.other_flights`). A refresh rewrites ``model.json`` and ``report.md`` for a new model;
without this module it passed no validation flights, and the table disappeared from both. :func:`kept_validation`
decides, entry by entry, what the refreshed model shows:

* the flight file is found again (at its recorded path, or by name in the model folder, beside the new flights
  or in the working directory, or among ``--previous-flights``; its bytes must hash to the recorded SHA-256):
  the refreshed model is validated on it again, as ``heli identify --validate`` would;
* it is not found, or can no longer validate this model (it is now one of the fitted flights, or sampled at
  another rate than them): the earlier entry is carried over as it was, marked with the model it was computed
  on and why it was not computed again (:attr:`FlightValidation.computed_on`), and said in a note.

The function reads files and returns plain data; :mod:`identification.workflows.refresh` passes the result to
:func:`identification.workflows.identify.identify_and_report`, which writes it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from heli_core.files import sha256_of

from ..validation.other_flights import FlightValidation


@dataclass
class KeptValidation:
    """What a refreshed model shows of the earlier validation.

    Attributes
    ----------
    flights : list of Flight
        Flights to validate the refreshed model on again (found, their SHA-256 as recorded).
    names, paths : list of str
        Their names in the report (as recorded) and the files read (absolute).
    carried : list of FlightValidation
        Earlier results carried over, each with its ``computed_on``.
    notes : list of str
        One sentence per flight carried over or dropped, for the refresh's notes.
    """

    flights: list = field(default_factory=list)
    names: list = field(default_factory=list)
    paths: list = field(default_factory=list)
    carried: list = field(default_factory=list)
    notes: list = field(default_factory=list)


def _locate(entry: dict, search_dirs, by_sha: dict) -> Path | None:
    """The file of a validation entry whose bytes hash to its SHA-256: among the given files, at its recorded
    path, or by its name in ``search_dirs``; None when none is found."""
    sha = entry.get("sha256")
    if sha in by_sha:
        return by_sha[sha]
    places = ([Path(entry["path"])] if entry.get("path") else []) + [
        Path(d) / Path(str(entry.get("file"))).name for d in search_dirs]
    for place in dict.fromkeys(places):
        if place.is_file() and sha is not None and sha256_of(place) == sha:
            return place.resolve()
    return None


def kept_validation(entries, model_sha256: str, search_dirs, candidates=(), fitted_sha256=(),
                    sample_rate: float | None = None) -> KeptValidation:
    """Sort the earlier model's validation flights into those validated again and those carried over.

    Parameters
    ----------
    entries : sequence of dict
        The earlier model's validation flights (:attr:`model_store.model_file.ModelDocument.validation_flights`).
    model_sha256 : str
        Its SHA-256 (what a carried-over entry was computed on, unless it says an older one).
    search_dirs : sequence of path
        Folders where a validation flight is looked for by its file name (the model folder, the new flights'
        folders, the working directory).
    candidates : sequence of path
        Files given explicitly (``--previous-flights``); matched by SHA-256 whatever their name.
    fitted_sha256 : sequence of str
        SHA-256 of the flights the refreshed model is fitted on: such a flight validates it no more.
    sample_rate : float, optional
        The fitted flights' sample rate [Hz]: a flight at another rate cannot be validated on
        (:func:`identification.validation.other_flights.check_validation_flights`).

    Returns
    -------
    KeptValidation
    """
    from ..io import read_flight

    by_sha = {}
    for c in candidates:
        if Path(c).is_file():
            by_sha.setdefault(sha256_of(c), Path(c).resolve())
    fitted = set(fitted_sha256)
    kept = KeptValidation()
    for entry in entries:
        name = str(entry.get("file"))
        if entry.get("sha256") in fitted:
            kept.notes.append(f"validation flight {name} is now one of the fitted flights: the refreshed model is "
                              "not validated on it, and its earlier scores are dropped")
            continue
        path = _locate(entry, search_dirs, by_sha)
        reason = None
        if path is None:
            reason = ("its file was not found at its recorded path, in the model folder, beside the new flights or in "
                      "the working directory (pass it with --previous-flights)")
        else:
            flight = read_flight(path)
            if sample_rate is not None and not math.isclose(flight.sample_rate, sample_rate, rel_tol=1e-3):
                reason = (f"it is sampled at {flight.sample_rate:g} Hz, the refreshed model's flights at "
                          f"{sample_rate:g} Hz")
        if reason is None:
            kept.flights.append(flight)
            kept.names.append(name)
            kept.paths.append(str(path))
            continue
        computed_on = {"model_sha256": model_sha256, "reason": reason}
        carried = FlightValidation.from_dict(entry, computed_on)
        kept.carried.append(carried)
        kept.notes.append(f"validation flight {name}: its earlier scores are carried over, computed on model "
                          f"{str(carried.computed_on.get('model_sha256'))[:12]}…: {carried.computed_on['reason']}")
    return kept
