"""``refresh.md``: what ``heli refresh`` compared, the drift table, the decision and what the library gained."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from model_store.model_file import MODEL_FILENAME

from .tables import markdown_table

if TYPE_CHECKING:
    from ..workflows.refresh_result import RefreshResult


def _fmt(v: float, digits: int = 4) -> str:
    return "—" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


def refresh_markdown(result: RefreshResult, doc: dict) -> str:
    """``refresh.md``: what was compared, the drift table, the decision and what the library gained.

    Parameters
    ----------
    result : RefreshResult
    doc : dict
        The ``refresh.json`` document written beside it.
    """
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
    lines += _drift_section(result, doc) + _refreshed_section(result, doc)
    if result.notes:
        lines += ["## Notes", ""] + [f"- {n}" for n in result.notes] + [""]
    return "\n".join(lines)


def _drift_section(result: RefreshResult, doc: dict) -> list[str]:
    """The parameter drift: where the uncertainties come from, the flag rule, the table and the servo delays."""
    level = result.bootstrap_new.level
    crit = result.criterion
    b = result.bootstrap_new
    rows = []
    for r in result.drift:
        rel = "—" if not np.isfinite(r.relative) else f"{100 * r.relative:+.1f}"
        rows.append([r.name, r.unit, _fmt(r.old), _fmt(r.se_old), f"[{_fmt(r.ci_old[0])}, {_fmt(r.ci_old[1])}]",
                     _fmt(r.new), _fmt(r.se_new), f"[{_fmt(r.ci_new[0])}, {_fmt(r.ci_new[1])}]", f"{r.delta:+.4f}",
                     rel, f"{r.z:.2f}", "**yes**" if r.flagged else "no"])
    lines = [
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
        markdown_table(["Parameter", "Unit", "Old", "se old", "CI old", "New flights", "se new", "CI new", "Δ",
                        "Δ (%)", "z", "Flag"], rows, right_align=False),
        "",
    ]
    taus = doc["servo_delay_s"]
    if any(v for d in taus.values() for v in d.values()):
        lines += ["Servo delay (s; not bootstrapped, held fixed in the replicates): "
                  + "; ".join(f"{lab} " + ", ".join(f"{a} {v:.3f}" for a, v in d.items()) for lab, d in taus.items()),
                  ""]
    return lines


def _refreshed_section(result: RefreshResult, doc: dict) -> list[str]:
    """What changed, the refreshed model and its fit decision, and the new version of the disturbance library."""
    flagged = result.flagged
    return [
        "**Changed:** " + (", ".join(flagged) if flagged else "nothing beyond what the uncertainty explains") + ".",
        "",
        "## The refreshed model",
        "",
        f"Fitted on {'the previous and the new flights pooled' if result.fit == 'pooled' else 'the new flights alone'}"
        f" — {result.reason}. Its parameters and validation are in `report.md`; the "
        f"{'bootstrap' if doc.get('estimator', 'integral') == 'integral' else 'Fisher'} standard errors are "
        f"recorded in `{MODEL_FILENAME}` under `refresh.bootstrap`.",
        "",
        markdown_table(["Parameter", "Refreshed", "se"],
                       [[k, f"{v:.4f}", _fmt(result.bootstrap_model.std_errors.get(k, float("nan")))]
                        for k, v in doc["refreshed_parameters"].items()], right_align=False),
        "",
        "## Disturbance library",
        "",
        f"Each new flight's wind was identified with the refreshed model (eqs. 41-47) and appended as version "
        f"{doc['library']['version']} (previous version {doc['library']['previous_version']}, kept). Traces already "
        "in the library stay as they were identified (their manifest entries name the model used).",
        "",
    ]
