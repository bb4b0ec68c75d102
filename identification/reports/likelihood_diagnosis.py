"""The diagnosis by likelihood as ``heli diagnose`` (the default) reports it: ``diagnosis.json``'s document,
``diagnosis.md`` and its figure, drawn from a fitted
:class:`identification.diagnosis.likelihood_diagnoser.LikelihoodDiagnoser`.

:func:`identification.workflows.diagnose.diagnose_by_likelihood` runs the diagnoser and writes, each file
atomically:

* ``diagnosis.json`` — verdict, per step the axis, effect, parameters, likelihood-ratio statistic and
  threshold, runner-up, R² (one step, 0.5 s ahead, sticks-only simulation) before and after; every
  candidate's statistic per round; the share of each stick the pilot's or controller's loop explains;
* ``diagnosis.md`` — the same as tables, with ``diagnosis_likelihood.png`` (each candidate's statistic
  over its threshold, per axis and round);
* when an effect was found, ``model.json`` (a new version, the replaced one in ``history/``) fitted by
  maximum likelihood with the effect added (``added_terms``, ``"diagnosis"``), and this flight's wind (the
  smoother's) appended to the disturbance library, so that the directory is a model the environment and the
  controllers load. The model carries the verdict ``heli identify`` gives its models
  (:func:`identification.validation.model_verdict.judge_identifier`, with the integral method beside it and its
  simulation from the flight's sticks), also in ``diagnosis.json`` (``model_verdict``) and first in
  ``diagnosis.md``: where ``heli identify`` refuses a flight as diverging, the diagnosis does not write a
  model of it that reads as sound.

Presentation only: it reads the fitted diagnoser's attributes and imports none of the diagnosis by likelihood
(the annotations name :class:`~identification.diagnosis.likelihood_diagnoser.LikelihoodDiagnoser`; with postponed
annotations the name needs no import).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from heli_core.files import jsonable, save_figure
from heli_core.terms import AXES
from model_store.verdict import ModelVerdict

from ..diagnosis.effects import CATALOGUE, describe
from ..likelihood.ahead_score import AHEAD_S, format_r2
from ..log_band import log_band
from .figures import pyplot

SCHEMA = "heli-env/diagnosis"
SCHEMA_VERSION = 2


def criterion_text(d: LikelihoodDiagnoser) -> str:
    """The acceptance rule, in words, with the settings used."""
    return (
        "Each axis is fitted by maximum likelihood with a stochastic wind (a slow and a fast Gauss-Markov gust, "
        "white gyro noise), then with each candidate effect added. A candidate is accepted when the "
        "likelihood-ratio statistic LR = 2 (NLL before - NLL after) exceeds both the chi-square quantile of its k "
        f"added parameters at 1 - {d.alpha:g}/m (m candidates on the axis, Bonferroni) and "
        f"{d.min_lr_per_parameter:g}·k ({d.min_lr_alignment:g} for the alignment and the servo lag, which is "
        "tried behind a servo delay found; floors calibrated on flights without a missing effect). The best "
        "accepted candidate per axis (largest LR over its threshold) is added and the search repeats on the axes "
        f"that changed (at most {d.max_rounds} rounds). A candidate whose fitted terms break a physical bound "
        "(an inertia ratio outside [-1, 1], a negative quadratic damping) is not accepted, whatever its LR: it fits "
        f"something else, such as a controller's loop or a misread input. Undecided: a flight shorter than {d.min_duration:g} s."
    )


def diagnosis_document(d: LikelihoodDiagnoser, source: dict | None = None, model_path=None,
                       verdict: ModelVerdict | None = None) -> dict:
    """The content of ``diagnosis.json``; ``verdict``: the written model's (:mod:`model_store.verdict`)."""
    out = {"schema": SCHEMA, "schema_version": SCHEMA_VERSION, "method": "likelihood",
           "source": source or {"name": str(d.flight_.metadata.get("source", "flight"))}}
    out.update(d.summary())
    out["criterion"]["text"] = criterion_text(d)
    out["parameters_after"] = d.params_.values() | {f"tau_{a}": d.params_.taus[i] for i, a in enumerate(AXES)}
    out["model_written"] = str(model_path) if model_path else None
    if (check := written_model_check(d)) is not None:
        out["closed_loop"] = check.describe()
    if verdict is not None:
        out["model_verdict"] = verdict.to_dict()
    return jsonable(out)


def _table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] * len(header)) + "|"]
    return "\n".join(lines + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows])


def _r2(r: dict) -> str:
    return (f"{format_r2(r.get('one_step'), 4)} / {format_r2(r.get('ahead_0.5s'))} / "
            f"{format_r2(r.get('simulation'))}")


def heldout_change(before: dict, after: dict) -> str:
    """A step's ``AHEAD_S``-ahead R² on held-out blocks, before -> after, or why it was not checked."""
    b, a = before.get("heldout_0.5s"), after.get("heldout_0.5s")
    if a is None:
        return "not checked (flight too short to cut into blocks)"
    return f"{format_r2(b)} -> {format_r2(a)}"


HELD = 0.5
"""A hold fraction below this reads as sticks held over each sample (0 held, 1 interpolated)."""


def flight_controller_note(d: LikelihoodDiagnoser) -> str | None:
    """What the closed-loop share cannot show when the sticks are held over each sample (a flight controller's
    commands, or a digital link's), else None."""
    fractions = getattr(d, "hold_fractions_", {}) or {}
    held = d.input_hold_ == "zoh" or (fractions and max(fractions.values()) < HELD)
    band = log_band(d.flight_) if hasattr(d, "flight_") else None
    if not held or (band is not None and band.filtered and d.input_hold_ != "zoh"):
        return None  # a log with nothing near its Nyquist frequency cannot say how its sticks were held
    said = "set" if d.input_hold_ == "zoh" else \
        "estimated hold fraction " + ", ".join(f"{a} {v:.2f}" for a, v in fractions.items())
    return (f"The sticks reach the aircraft held over each sample ({said}; 0 held, 1 interpolated). If they are a "
            "flight controller's commands, it closes the loop within a sample, faster than the 0.1-0.5 s the share "
            "looks at, so every axis is closed by it whatever the share says; the effects are judged on what its "
            "corrections leave, with its gyro's vibration removed from the commands and the rates alike.")


def timing_note(d: LikelihoodDiagnoser) -> str | None:
    """The servo delays kept in the model without being named (:attr:`LikelihoodDiagnoser.timing_detected_`:
    shorter than the timing resolution, in the candidates' base, taken into it where the likelihood preferred it,
    or found by the final fit); None when there is none."""
    found = getattr(d, "timing_detected_", None)
    if not found:
        return None
    parts = [f"{axis} {1e3 * delay:.1f} ms" for axis, delay in found.items()]
    return ("servo delay in the model, not named: " + ", ".join(parts) + ". Detected as heli identify detects it "
            "(--delay detect) or as the likelihood placed the log's timing; below 2 samples a delay cannot be told "
            "from the log's timing convention, so it is not named as an effect, but the model keeps it: left out, it "
            "biases the damping.")


def written_model_check(d: LikelihoodDiagnoser):
    """The closed-loop check run on the model the diagnosis wrote
    (:func:`identification.workflows.diagnose.check_written_model`), or None when it was not run."""
    ident = getattr(d, "identifier_", None)
    return getattr(ident, "closed_loop_", None) if d.steps_ else None


def diagnosis_markdown(d: LikelihoodDiagnoser, figure: Path | None, verdict: ModelVerdict | None = None) -> str:
    """``diagnosis.md``: the written model's verdict, the diagnosis' verdict, closed-loop shares, the steps, and
    every candidate per round."""
    found = ", ".join(f"`{e}` on {a}" for e, a in d.effects_found_)
    md = ["# Diagnosis (likelihood)", "", *(verdict.markdown() if verdict is not None else []), f"**Verdict: {d.verdict_}**" + (f" — added {found}." if found else "."), ""]
    if d.verdict_ == "undecided":
        md += [f"Evidence: {d.evidence_.get('reason', '')}", ""]
    md += [criterion_text(d), ""]
    md += ["## Who closes the loop", "",
           "Share of each stick explained by the attitude and rate 0.1–0.5 s before (a pilot or a flight controller "
           "holding the attitude). The estimator models the gust as a state, so a closed loop does not bias it; a "
           "large share means the stick mirrors the response and the effects below are judged on what the "
           "pilot's corrections leave.", "",
           _table(["Axis", "closed-loop share of the stick"],
                  [[a, f"{100 * v:.0f} %"] for a, v in d.closed_loop_.items()]), ""]
    if flight_controller_note(d):
        md += [flight_controller_note(d), ""]
    if getattr(d, "untestable_", None):
        md += ["## Not tested", "", "Effects whose regressor does not vary in this flight cannot be told from the "
               "model's own terms, so they are not named either way:", ""]
        md += [f"- `{name}`: {why}" for name, why in d.untestable_.items()] + [""]
    if d.steps_:
        md += ["## Effects added", "",
               f"R² columns: one-step prediction / {AHEAD_S:g} s ahead / simulation from the sticks alone; "
               f"held out: the {AHEAD_S:g} s-ahead R² of blocks of the flight each predicted by the structure "
               "fitted on the others (an effect is added only when neither gets worse).", "",
               _table(["Round", "Axis", "Effect", "Parameters", "LR", "threshold", "runner-up (LR)", "R² before",
                       "R² after", "held out"],
                      [[s.round, s.axis, describe(s.effect, AXES.index(s.axis)),
                        ", ".join(f"{k} = {v:.4g}" for k, v in s.parameters.items()), f"{s.lr:.1f}",
                        f"{s.threshold:.1f}", f"{s.runner_up} ({s.runner_up_lr:.1f})" if s.runner_up else "—",
                        _r2(s.r2_before), _r2(s.r2_after), heldout_change(s.r2_before, s.r2_after)]
                       for s in d.steps_]), ""]
    if note := timing_note(d):
        md += ["## The model's timing", "", note, ""]
    if (check := written_model_check(d)) is not None:
        md += ["## The model written, checked in the closed loop", "",
               f"As `heli identify` checks its model ({check.headline()}; mode `{check.mode}`): the effects above "
               "were named on the fits as found, the model written carries the values after the check.", "",
               *[f"- {line}" for line in check.lines()], ""]
    for i, rows in enumerate(d.rounds_, start=1):
        md += [f"## Candidates, round {i}", "",
               _table(["Axis", "Effect", "k", "LR", "threshold", "timing (s)", "accepted"],
                      [[r["axis"], r["effect"], r["n_parameters"], f"{r['lr']:.1f}", f"{r['threshold']:.1f}",
                        _timing(r),
                        "**yes**" if r["accepted"] else ("no: " + r["implausible"] if r.get("implausible") else "no")]
                       for r in rows]), ""]
    if figure is not None:
        md += [f"![Likelihood-ratio statistics]({figure.name})", ""]
    return "\n".join(md)


def _timing(row: dict) -> str:
    """A candidate row's timing: the alignment of ``servo_delay``, the lag (and the delay beside it) of
    ``servo_lag``, nothing for a term."""
    if row["effect"] == "servo_delay":
        return f"{row['alignment_s']:+.3f}"
    if row["effect"] == "servo_lag":
        return f"lag {row.get('lag_s', 0.0):.3f}, delay {row['alignment_s']:+.3f}"
    return "—"


def plot_statistics(d: LikelihoodDiagnoser, path) -> Path | None:
    """Bar chart: each candidate's LR over its threshold per axis (round 1; 1 = the acceptance line)."""
    if not d.rounds_:
        return None
    plt = pyplot()
    rows = d.rounds_[0]
    effects = list(CATALOGUE)
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), sharey=True)
    for ax, axis in zip(axes, AXES):
        vals = [next((r["lr"] / r["threshold"] for r in rows if r["axis"] == axis and r["effect"] == e), np.nan)
                for e in effects]
        colors = ["tab:red" if v > 1 else "tab:gray" for v in vals]
        ax.barh(range(len(effects)), np.clip(np.nan_to_num(vals, nan=0.0), 1e-3, None), color=colors)
        ax.axvline(1.0, color="k", lw=1, ls="--")
        ax.set_xscale("log")
        ax.set_title(axis)
        ax.set_xlabel("LR / threshold")
        ax.set_yticks(range(len(effects)))
        ax.set_yticklabels(effects)
    fig.suptitle("Likelihood-ratio statistic of each candidate effect, round 1 (right of the line: accepted)")
    fig.tight_layout()
    return save_figure(fig, path)
