"""Has the aircraft changed? The drift table of ``heli refresh``: each parameter's change against its uncertainty.

Per parameter, Δ = new − old is flagged when ``|Δ| > z·sqrt(se_old² + se_new²)``
(and ``|Δ| >= min_relative·|old|``), with ``z = Φ⁻¹(1 − α/(2m))`` for the ``m``
parameters compared (Bonferroni: a false flag anywhere in the table has
probability about α when nothing changed; :func:`critical_z`,
:func:`drift_table`). The standard errors come from the interval bootstrap of
the integral method (:func:`identification.integral.bootstrap.interval_bootstrap`) or
from the Fisher information of a maximum-likelihood fit (:func:`fisher_result`),
which compares every fitted parameter but the offsets
(:func:`compared_parameters`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from heli_core.files import jsonable
from heli_core.terms import TERMS

from ..integral.bootstrap import BootstrapResult


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


class FisherResult(BootstrapResult):
    """Uncertainty from the Fisher information of a maximum-likelihood fit (no replicates)."""

    def to_dict(self) -> dict:
        out = super().to_dict()
        out["method"] = "Fisher information of the innovations (maximum likelihood)"
        for k in ("n_replicates", "n_failed", "block_intervals", "seed"):
            out.pop(k)
        out["n_seconds"] = out.pop("n_intervals")
        return out


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


def compared_parameters(identifier, estimator: str) -> list[str]:
    """Parameters the drift table compares: every fitted one, less the offsets kd of a maximum-likelihood fit.

    With a wind state in the model the offsets are each flight's trim plus that day's mean wind
    (:attr:`identification.likelihood.axis_fit.MLAxisFit.flight_offsets`): they change from flight to flight
    without the aircraft changing, so they are reported per flight and not flagged.
    """
    names = [k for fit in identifier.axes_.values() for k in fit.params]
    return [k for k in names if not (estimator == "ml" and TERMS[k].effect == "offset")]


def previous_std_errors(doc: dict, names, new: BootstrapResult, library_entries, old_sources,
                        estimator: str) -> tuple[dict, str, str | None]:
    """Standard errors of the current model when its flights are not at hand (``heli refresh``, step 3).

    In order: the bootstrap (or Fisher information) an earlier refresh recorded in ``model.json``; the
    maximum-likelihood fit's own Fisher errors recorded by ``heli identify``; else the new flights'
    bootstrap scaled by ``sqrt(n_new / n_old)`` intervals (the old count from the library's record of
    the source flights' durations; equal counts when unknown).

    Parameters
    ----------
    doc : ModelDocument
        The current ``model.json``.
    names : sequence of str
        Parameters compared.
    new : BootstrapResult
        The new flights' uncertainty.
    library_entries : sequence of dict
        The disturbance library's manifest entries (their sources' durations).
    old_sources : sequence of Source
        The current model's source flights (:attr:`model_store.model_file.ModelDocument.sources`).
    estimator : {"ml", "integral"}
        How the current model was identified.

    Returns
    -------
    std_errors : dict of str to float
    source : str
        Where they came from (the drift table's ``se_old_source``).
    note : str or None
        What a reader should know about them.
    """
    record = (doc.refresh or {}).get("bootstrap") or {}
    recorded = record.get("std_errors") or {}
    if all(isinstance(recorded.get(k), (int, float)) for k in names):
        label = "recorded Fisher information" if str(record.get("method", "")).startswith("Fisher") else \
            "recorded bootstrap"
        return {k: float(recorded[k]) for k in names}, label, None
    if estimator == "ml":  # the fit's own Fisher errors, recorded by heli identify
        fisher = doc.std_errors()
        if all(isinstance(fisher.get(k), (int, float)) for k in names):
            source = "Fisher information recorded in model.json"
            return ({k: float(fisher[k]) for k in names},
                    source + (", widened by the input hold's doubt" if doc.hold_in_doubt() else ""), None)
    durations = {}
    for e in library_entries:
        sha = (e.get("source") or {}).get("sha256")
        if sha and e.get("duration_s"):
            durations[sha] = float(e["duration_s"])
    shas = [s.sha256 for s in old_sources]
    interval = float(doc.identification.get("interval") or 1.0)
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
