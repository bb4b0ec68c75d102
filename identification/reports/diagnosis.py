"""The held-out diagnosis as ``heli diagnose --method integral`` reports it: ``diagnosis.json``'s document,
``diagnosis.md`` and its figures, drawn from a fitted :class:`identification.diagnosis.heldout_diagnoser.Diagnoser`.

:func:`identification.workflows.diagnose.diagnose_and_report` runs the diagnoser and writes, atomically:

* ``diagnosis.json`` — verdict, per step the axis, effect, fitted parameters,
  held-out gap before and after, runner-up and margin; the criterion; every
  candidate's score per round; residual tests before and after;
* ``diagnosis.md`` — the same as tables (the paper's error statistics of
  Table 1 on held-out windows, residual tests) with the figures
  ``diagnosis_residuals.png`` and ``diagnosis_windows.png``;
* when an effect was found, ``model.json`` (a new version: the replaced file
  goes to ``history/``) recording the added terms under ``added_terms`` and the
  diagnosis under ``"diagnosis"``, and this flight's wind profile (eqs. 41-47)
  appended to the disturbance library, so that the directory is a model the
  environment and the controllers load.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from heli_core.files import jsonable, save_figure
from heli_core.terms import AXES, INPUT_FOR_AXIS

from ..diagnosis.effects import CATALOGUE
from ..diagnosis.heldout_diagnoser import Diagnoser, heldout_stats
from .figures import DPI, pyplot

SCHEMA = "heli-env/diagnosis"
SCHEMA_VERSION = 1


def criterion_text(d: Diagnoser) -> str:
    """The acceptance rule, in words, with the settings used."""
    return (
        f"A candidate effect is accepted on an axis when, on {d.folds}-fold cross-validation (contiguous blocks; "
        f"forward simulation of {d.window:g} s windows from measured states, fitted without the window's block), it "
        f"lowers the held-out squared rate error by at least {100 * d.min_gain:.0f} % AND the per-window log error "
        f"ratios baseline/candidate are positive on average by a one-sided t-test at p <= {d.alpha:g}/m (m = "
        "candidates tried on that axis in the round, Bonferroni). Wind and sensor noise make the window-to-window "
        "scatter the test compares with; the gain floor excludes the few-percent gains that wind-fitted terms "
        "reach on flights without a missing effect. The best accepted candidate per axis wins; the runner-up is the "
        f"next best on that axis and the margin is the difference in gain (paired test p <= {d.alpha:g}: decisive). "
        f"Undecided instead of an effect: flight < {d.min_duration:g} s or < {d.min_windows} windows, or the best "
        f"model explains < {100 * d.min_r2:.0f} % of an axis' held-out rate variance."
    )


def _strip(obj):
    """Residual-test dicts without the raw test objects kept for plotting."""
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items() if not str(k).startswith("_")}
    return obj


def diagnosis_document(d: Diagnoser, source: dict | None = None, model_path=None) -> dict:
    """The JSON document of a fitted diagnosis (schema ``heli-env/diagnosis`` version 1)."""
    doc = {
        "schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "source": source or {"name": d.flight_.metadata.get("source", "flight")},
        "verdict": d.verdict_,
        "effects_found": [{"effect": e, "axis": a} for e, a in d.effects_found_],
        "steps": [s.to_dict() for s in d.steps_],
        "criterion": {"text": criterion_text(d), "alpha": d.alpha, "min_gain": d.min_gain, "folds": d.folds,
                      "window_s": d.window, "min_duration_s": d.min_duration, "min_windows": d.min_windows,
                      "min_r2": d.min_r2},
        "evidence": d.evidence_,
        "catalogue": {n: {"description": e.description, "terms": list(e.terms)} for n, e in CATALOGUE.items()},
        "structure_before": d.baseline_spec_.to_dict(),
        "structure_after": d.spec_.to_dict(),
        "heldout_before": heldout_stats(d.baseline_score_) if d.baseline_score_ is not None else None,
        "heldout_after": heldout_stats(d.final_score_) if d.final_score_ is not None else None,
        "rounds": d.rounds_,
        "residual_tests": _strip(d.residual_tests_),
        "parameters_after": d.params_.values() | {f"tau_{a}": d.params_.taus[i] for i, a in enumerate(AXES)},
        "model_file": str(model_path) if model_path else None,
    }
    return jsonable(doc)


# ----------------------------------------------------------------------- markdown
def _table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] * len(header)) + "|"]
    return "\n".join(lines + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows])


def _fmt(v, spec=".3f"):
    return "—" if v is None else format(v, spec)


def _residual_rows(tests: dict) -> list:
    rows = []
    for axis in AXES:
        for kind in ("simulation", "integral"):
            t = tests.get(axis, {}).get(kind)
            if not t:
                continue
            w = t["whiteness"]
            corr = ", ".join(t["correlated_with"]) or "none"
            rows.append([axis, kind, f"{w['ljung_box_q']:.0f}", f"{w['p_value']:.2g}",
                         f"{100 * w['share_outside_bound']:.0f} %", corr])
    return rows


def diagnosis_markdown(d: Diagnoser, doc: dict, figures: dict) -> str:
    """``diagnosis.md``: verdict, criterion, where the gap lies, candidates, steps, before/after."""
    md = ["# Diagnosis", ""]
    found = ", ".join(f"`{e}` on {a}" for e, a in d.effects_found_)
    md += [f"**Verdict: {d.verdict_}**" + (f" — added {found}." if found else "."), ""]
    if d.verdict_ == "undecided":
        md += [f"Evidence: {d.evidence_.get('reason', '')}", ""]
    md += ["## Criterion", "", doc["criterion"]["text"], "", "## Catalogue of candidate effects", "",
           _table(["Effect", "Terms", "Physics"], [[n, ", ".join(e.terms) or "τ per axis (eq. 31)", e.description]
                                                   for n, e in CATALOGUE.items()]), ""]
    before = d.residual_tests_["before"]
    md += ["## Where the model and the flight disagree (before)", ""]
    for axis in AXES:
        sim = before.get(axis, {}).get("simulation")
        if not sim:
            continue
        band = max(sim["bands"], key=lambda b: b["error_share"])
        worst = "; ".join(f"{w['t_start_s']:.0f}-{w['t_end_s']:.0f} s (RMS {w['rms_deg_s']:.2f} deg/s, "
                          f"{w['busiest_stick']} busiest)" for w in sim["worst_windows"])
        md.append(f"- **{axis}**: {100 * band['error_share']:.0f} % of the error power in "
                  f"{band['band_hz'][0]:g}-{band['band_hz'][1]:g} Hz (error/signal there "
                  f"{_fmt(band['error_to_signal'], '.2f')}); worst windows {worst}.")
    md += ["", "Residual tests (lags ±2 s at 0.1 s; correlation bounds at 99 %; signals correlated beyond their "
           "bound at some lag of either sign):", "",
           _table(["Axis", "Residual", "Ljung-Box Q", "p (white)", "lags outside", "correlated with"],
                  _residual_rows(before)), ""]
    if d.rounds_:
        md += ["## Candidates (held-out gain of the squared rate error, one-sided p)", ""]
        for i, rows in enumerate(d.rounds_, start=1):
            md += [f"Round {i}:", "", _table(["Axis", "Effect", "Gain", "t", "p", "held-out R²"],
                                             [[r["axis"], r["effect"], f"{100 * r['gain']:+.1f} %", f"{r['t']:.2f}",
                                               f"{r['p_value']:.2g}", f"{r['r2']:.3f}"]
                                              for r in sorted(rows, key=lambda r: (r["axis"], -r["gain"]))]), ""]
    if d.steps_:
        md += ["## Effects added", "", _table(
            ["Round", "Axis", "Effect", "Parameters", "Held-out MAE before → after (deg/s)", "Gain", "p",
             "Runner-up", "Margin", "Decisive"],
            [[s.round, s.axis, s.effect, ", ".join(f"{k}={v:.4g}" for k, v in s.parameters.items()),
              f"{s.gap_before['mae_deg_s']:.3f} → {s.gap_after['mae_deg_s']:.3f}", f"{100 * s.gain:.1f} %",
              f"{s.p_value:.2g}", s.runner_up or "—", _fmt(s.margin and 100 * s.margin, ".1f") + " %",
              "yes" if s.decisive else "no"] for s in d.steps_]), ""]
    if doc["heldout_before"] is not None:
        rows = []
        for axis in AXES:
            b, a = doc["heldout_before"][axis], doc["heldout_after"][axis]
            rows.append([axis, f"{b['mae_deg_s']:.3f} → {a['mae_deg_s']:.3f}", f"{b['p90_deg_s']:.3f} → {a['p90_deg_s']:.3f}",
                         f"{b['rel_max_pct']:.2f} → {a['rel_max_pct']:.2f}"])
        md += ["## Before → after on held-out windows (paper's Table 1 statistics)", "",
               _table(["Axis", "MAE (deg/s)", "90th pct (deg/s)", "rel. to max (%)"], rows), "",
               "Residual tests after:", "",
               _table(["Axis", "Residual", "Ljung-Box Q", "p (white)", "lags outside", "correlated with"],
                      _residual_rows(d.residual_tests_["after"])), ""]
    md += ["The forward-simulation residual carries the unmodelled wind, which is coloured and which the pilot "
           "answers: it is not expected to be white nor uncorrelated with the sticks at negative lags (feedback) "
           "even for a complete model; what matters is what changes from before to after.", ""]
    for name, path in figures.items():
        md += [f"![{name}]({Path(path).name})", ""]
    return "\n".join(md) + "\n"


# ------------------------------------------------------------------------- plots
def plot_residual_tests(d: Diagnoser, path):
    """Per axis: autocorrelation and cross-correlation with the own stick (before/after), error per band."""
    plt = pyplot()
    fig, axes = plt.subplots(3, 3, figsize=(14, 10))
    for i, axis in enumerate(AXES):
        for label, style in (("before", "C3"), ("after", "C0")):
            sim = d.residual_tests_[label].get(axis, {}).get("simulation")
            if not sim:
                continue
            w, cc = sim["_acf"], sim["_ccf"]
            step = sim["step_s"]
            axes[i, 0].plot(w.lags * step, w.rho, "o-", ms=3, color=style, label=label)
            axes[i, 0].axhspan(-w.bound, w.bound, color="0.9")
            j = cc.names.index(INPUT_FOR_AXIS[i])
            axes[i, 1].plot(cc.lags * step, cc.rho[j], color=style, label=label)
            axes[i, 1].axhspan(-cc.bounds[j], cc.bounds[j], color="0.9")
            shares = [b["error_share"] for b in sim["bands"]]
            x = np.arange(len(shares)) + (0.2 if label == "after" else -0.2)
            axes[i, 2].bar(x, shares, width=0.4, color=style, label=label)
            axes[i, 2].set_xticks(np.arange(len(shares)), [f"{b['band_hz'][0]:g}-{b['band_hz'][1]:g}" for b in sim["bands"]])
        axes[i, 0].set_title(f"{axis}: residual autocorrelation", loc="left", fontsize=10)
        axes[i, 1].set_title(f"{axis}: corr(residual(t+k), {INPUT_FOR_AXIS[i]}(t))", loc="left", fontsize=10)
        axes[i, 2].set_title(f"{axis}: share of error power per band [Hz]", loc="left", fontsize=10)
        for ax in axes[i]:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("lag [s]")
    axes[-1, 1].set_xlabel("lag k [s] (k > 0: stick leads)")
    fig.suptitle("Held-out forward-simulation residual tests, before and after the diagnosis", fontsize=12)
    fig.tight_layout()
    return save_figure(fig, path, dpi=DPI)


def plot_worst_windows(d: Diagnoser, path):
    """Measured vs held-out simulated rates before and after, in each axis' worst window before.

    The y-axis spans the measured and simulated rates; a simulation that diverges in the window is
    clipped and its legend entry says how far it went (:func:`window_limits`).
    """
    plt = pyplot()
    b, a = d.baseline_score_, d.final_score_
    held = d.held_
    fig, axes = plt.subplots(3, 2, figsize=(14, 9))
    t_rel = np.arange(1, held.length + 1) * d.flight_.dt
    for i, axis in enumerate(AXES):
        for j, w in enumerate(np.argsort(b.mse[i])[::-1][:2]):
            ax = axes[i, j]
            t = d.flight_.time[held.starts[w]] + t_rel
            measured = np.degrees(b.measured[i, w])
            simulated = {"before": np.degrees(b.simulated[i, w]), "after": np.degrees(a.simulated[i, w])}
            (lo, hi), notes = window_limits(measured, simulated)
            ax.plot(t, measured, color="black", lw=1, label="measured")
            for label, style in (("before", {"color": "C3", "ls": "--"}), ("after", {"color": "C0"})):
                ax.plot(t, simulated[label], **style, label=label + notes[label])
            ax.set_ylim(lo, hi)
            ax.set_title(f"{axis} rate, held-out window {t[0]:.0f}-{t[-1]:.0f} s", loc="left", fontsize=10)
            ax.set_ylabel("deg/s")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    fig.suptitle("Worst held-out windows of the model before the diagnosis (each simulated from measured state)",
                 fontsize=12)
    fig.tight_layout()
    return save_figure(fig, path, dpi=DPI)


def window_limits(measured, simulated: dict, pad: float = 0.1, diverged: float = 3.0):
    """y-limits of a window's plot and a legend note per simulated curve.

    The limits span the measured rate and every simulated curve that stays within ``diverged`` times
    the measured span of it, plus ``pad`` of the span; a curve that goes further (a model diverging in
    the window) would flatten the comparison, so it is clipped and its note says how far it went.

    Parameters
    ----------
    measured : ndarray, shape (n,)
        Measured rate [deg/s].
    simulated : dict of str to ndarray, shape (n,)
        Simulated rates by label [deg/s].

    Returns
    -------
    (float, float), dict of str to str
        ``(low, high)`` and per label ``""`` or ``" (diverged: up to N deg/s, clipped)"``.
    """
    lo, hi = float(np.nanmin(measured)), float(np.nanmax(measured))
    reach = diverged * max(hi - lo, 1.0)
    notes = {}
    for label, values in simulated.items():
        finite = values[np.isfinite(values)]
        if finite.size == values.size and finite.min() >= lo - reach and finite.max() <= hi + reach:
            notes[label] = ""
            continue
        peak = float(np.abs(finite).max()) if finite.size else float("nan")
        notes[label] = f" (diverged: up to {peak:.0f} deg/s, clipped)" if finite.size else " (diverged, clipped)"
    kept = [measured] + [v for label, v in simulated.items() if not notes[label]]
    low, high = min(float(np.min(v)) for v in kept), max(float(np.max(v)) for v in kept)
    margin = pad * max(high - low, 1.0)
    return (low - margin, high + margin), notes
