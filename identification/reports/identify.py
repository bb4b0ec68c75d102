"""``report.md`` of ``heli identify``: its tables, its text and its figures.

:func:`identification.workflows.identify.identify_and_report` fits, validates and writes; this module says what
came out: the parameter table (± standard errors, against a synthetic flight's truth), the fit
statistics, the maximum-likelihood wind model, each flight's wind section, and the figures the
report links (``rates.png``, ``attitude.png``, the wind profiles).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from heli_core.params import ModelParams
from heli_core.terms import AXES, BASE_PARAMS, TERMS

from ..disturbance.profile import compare_with_truth
from ..likelihood.input_hold import std_errors_with_hold
from ..validation.result import ValidationResult
from .disturbance import figure_names, profile_markdown, save_figures
from .validation import flight_validation_markdown, plot_attitude_fit, plot_rate_fit, validation_markdown

STABILISED_NOTE = (
    "Where the aircraft is flybarless (or flown through any stabilising controller), its sticks are commands to "
    "that controller, not swash angles: the model identified is then stick -> rate of the stabilised aircraft "
    "(k2/k6/k10 over k3/k7/k11 the steady rate per unit stick the controller holds, the damping its rate loop's "
    "bandwidth, the wind what the controller left). The env then flies that stabilised aircraft: a PD or an RL "
    "agent designed on it is an outer loop around the aircraft's own controller, and a sweep's errors are those "
    "of the pair; gains of the firmware's own loop are tuned with heli tune, not here. A stick logged later than "
    "the response is typical of such a log: the receiver's channel written after the controller acted on it.")
"""What the model means when the sticks command a stabilising controller: the report's words after a late input
(:func:`identification.diagnosis.alignment_check.check_alignment` tests for one)."""


def parameter_table(identifiers: dict, truth: ModelParams | None) -> str:
    """Markdown table of identified parameters (decoupled and coupled, ± standard error, truth)."""
    labels = list(identifiers)
    header = ["Parameter", "Unit"] + [f"{lab}" for lab in labels]
    if truth is not None:
        header += ["Truth"] + [f"{lab} error (%)" for lab in labels]
    rows = []
    names = list(BASE_PARAMS) + sorted({k for ident in identifiers.values() for k, _ in ident.params_.extra})
    ses = {lab: {axis: std_errors_with_hold(f.params, f.std_errors, getattr(ident, "hold_alternative_", None), axis)
                 for axis, f in ident.axes_.items()}  # with the hold's doubt, where the log leaves one
           for lab, ident in identifiers.items()}
    for name in names:
        cells, vals = [], []
        axis = AXES[TERMS[name].axis]
        for lab in labels:
            fit = identifiers[lab].axes_.get(axis)
            if fit is None or name not in fit.params:
                cells.append("—")
                vals.append(None)
                continue
            v, se = fit.params[name], ses[lab][axis].get(name, float("nan"))
            cells.append(f"{v:.4f} ± {se:.4f}" if np.isfinite(se) else f"{v:.4f}")
            vals.append(v)
        if all(v is None for v in vals):
            continue
        row = [name, TERMS[name].unit] + cells
        if truth is not None:
            tv = truth.get(name)
            row.append(f"{tv:.4f}")
            for v in vals:
                row.append("—" if v is None or tv == 0 else f"{100 * (v - tv) / tv:+.1f}")
        rows.append(row)
    for kind, servo in (("tau", lambda p: p.taus), ("lag", lambda p: p.lags)):  # the servo's delay and lag
        for axis in AXES:
            values = [servo(identifiers[lab].params_)[AXES.index(axis)] for lab in labels]
            if any(values):  # a delay searched with the rest has its standard error (a lag's profile has none)
                se = [ses[lab].get(axis, {}).get(f"{kind}_{axis}", 0.0) if t else 0.0 for lab, t in zip(labels, values)]
                row = [f"{kind}_{axis}", "s"] + [f"{t:.3f} ± {e:.3f}" if e > 0 else f"{t:.3f}"
                                                 for t, e in zip(values, se)]
                if truth is not None:
                    row += [f"{servo(truth)[AXES.index(axis)]:.3f}"] + ["—" for _ in labels]
                rows.append(row)
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] * len(header)) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def fit_table(identifiers: dict) -> str:
    """Markdown table of fit statistics per model and axis."""
    lines = ["| Model | Axis | R² | R² of | Condition number | Servo delay (s) |", "|---|---|---|---|---|---|"]
    for lab, ident in identifiers.items():
        what = ("the sticks-only simulation" if getattr(ident, "method", "").startswith("maximum")
                else f"the integral fit ({len(next(iter(ident.axes_.values())).history)} iterations)")
        for axis, fit in ident.axes_.items():
            lines.append(f"| {lab} | {axis} | {fit.r2:.4f} | {what} | {fit.condition:.3g} | {fit.delay:.3f} |")
    return "\n".join(lines)


def _shift_sentence(ident) -> str:
    """What an input found late means, when ``delay="auto"`` or ``"detect"`` found one (else empty)."""
    late = {a: v for a, v in (getattr(ident, "input_shifts_", None) or {}).items() if v < 0.0}
    if not late:
        return ""
    return (" The sticks of this log lag the response: they were advanced by "
            + ", ".join(f"{a} {-v:.3f} s" for a, v in late.items())
            + f" before the fit (the alignment searched by --delay {ident.delay}; a log's timing, so the model has "
            "no servo delay for it). " + STABILISED_NOTE)


def _timing_sentence(ident) -> str:
    """How the servo's timing was found, when it was searched (``delay="detect"`` or ``"auto"``; else empty)."""
    delay = getattr(ident, "delay", None)
    if not isinstance(delay, str):
        return ""
    how = ("a servo delay searched a few steps from the undelayed fit and profiled where its likelihood ratio "
           "reached 20 (--delay detect)" if delay == "detect" else "the alignment profiled over -0.6-0.5 s on "
           "every axis (--delay auto)")
    found = ", ".join(f"{a} {1e3 * f.delay:.0f} ms" for a, f in ident.axes_.items() if f.delay > 0)
    lags = ", ".join(f"{a} {1e3 * f.lag:.0f} ms" for a, f in ident.axes_.items() if f.lag > 0)
    late = min((getattr(ident, "input_shifts_", None) or {}).values(), default=0.0) < 0.0
    none = "none (the timing found is the log's input column, below)" if late else "none the data support"
    return (f" Servo timing: {how}: servo delay {found or none}"
            + (f"; first-order servo lag {lags}" if lags else "") + ".")


def _closed_loop_sentence(ident) -> str:
    """What the closed-loop check found (:mod:`identification.likelihood.closed_loop`), when it ran; else empty."""
    check = getattr(ident, "closed_loop_", None)
    if check is None:
        return ""
    what = ("removed where significant (the values above are after it)" if check.mode == "auto"
            else "reported only (the values above are as fitted)")
    return f" Closed-loop check ({check.headline()}; a bias {what}): " + "; ".join(check.lines()) + "."


def method_sentence(ident) -> str:
    """One sentence of the report saying how the model was identified."""
    if getattr(ident, "method", "").startswith("maximum likelihood"):  # what the identifier says it is
        winds = ", ".join(f"{a} {f.wind['model']}" for a, f in ident.axes_.items())
        holds = ", ".join(f"{a} {f.input_hold:.2f}" for a, f in ident.axes_.items())
        decision = getattr(ident, "hold_decision_", None) or {}
        said = (f"the log's {decision['named']} hold, kept as the data do not reject it" if decision.get("named")
                else "the axes' pooled fraction")
        if decision.get("preferred") and decision.get("named") == "zoh":  # a controller's, not rejected by the data
            said += f": {decision['preferred']}"
        alternative = getattr(ident, "hold_alternative_", None)
        if alternative:
            said += (f"; nor do they reject the {alternative['hold']} hold (likelihood ratio {alternative['lr']:.1f}, "
                     f"a decision needs {alternative['threshold']:.1f}): every axis was fitted at it too and the "
                     f"standard errors include the gap, weighted by its probability {alternative['weight']:.2f}")
        moved = getattr(getattr(ident, "closed_loop_", None), "hold", None)
        if moved is not None and moved.applied:
            said = (f"the log's {moved.chosen} hold, decided in the closed loop's world where the likelihood "
                    f"alone had read {moved.decided}")
        how = (f"a fraction of linear interpolation (0 held over the sample, 1 interpolated) estimated per axis "
               f"and decided for the log ({said}; per axis {holds})" if ident.input_hold == "auto"
               else f"a fixed hold ({ident.input_hold})")
        return ("Method: maximum likelihood (filter-error / prediction-error method): per axis the rate, a slow and "
                "a fast Gauss-Markov gust entering as torque, white gyro noise; exact discretisation with the "
                f"sticks between samples as {how}, "
                "steady-state Kalman filter, innovations minimised over the damping and the wind model with the "
                f"linear parameters projected out; gust models chosen by likelihood ({winds}); standard errors "
                "from the Fisher information; no prefilter (vibration lines removed by regression on their "
                "sinusoids). The integral method of Fig. 5 is its starting point and is shown for comparison."
                + _timing_sentence(ident) + _shift_sentence(ident) + _closed_loop_sentence(ident))
    return ("Method: integral-based identification (paper Section 2.5.2, Fig. 5) with "
            f"{ident.interval:g} s intervals, per-interval initial values (eq. 34), "
            + ("a per-interval polynomial disturbance of degree "
               f"{ident.disturbance_order} (generalising eq. 43)" if ident.offsets == "per_interval"
               else "one constant offset")
            + (f", zero-phase FIR prefilter {ident.pass_hz:g}/{ident.stop_hz:g} Hz (Section 3.1)"
               if ident.prefilter else "") + ".")


def wind_table(ident) -> str:
    """Markdown table of the maximum-likelihood wind model and noise per axis (empty for the integral method)."""
    if not hasattr(ident, "axes_") or not all(hasattr(f, "wind") for f in ident.axes_.values()):
        return ""
    lines = ["| Axis | gust model | T slow (s) | T fast (s) | torque std slow / fast (rad/s²) | u_d std slow / fast "
             "| gyro noise (deg/s) | one-step R² |", "|---|---|---|---|---|---|---|---|"]
    for axis, f in ident.axes_.items():
        w = f.wind
        ud = " / ".join("—" if v is None else f"{v:.4f}" for v in w["ud_std"])
        lines.append(
            f"| {axis} | {w['model']} | {w['time_constants_s'][0]:.2f} ± {w['time_constants_se_s'][0]:.2f} "
            f"| {w['time_constants_s'][1]:.3f} ± {w['time_constants_se_s'][1]:.3f} "
            f"| {w['torque_std'][0]:.4f} / {w['torque_std'][1]:.4f} | {ud} | {np.degrees(f.noise_std):.3f} "
            f"| {f.prediction_r2:.4f} |")
    return "\n".join(lines)


def wind_section(profile, title: str, true_ud=None, figure_prefix: str | None = None) -> list[str]:
    """The lines of one flight's wind in ``report.md``: the profile, its errors against a synthetic flight's
    true wind ``true_ud`` (3, n) when known, and links to its figures (named ``figure_prefix_*.png``)."""
    section = [profile_markdown(profile, title)]
    if true_ud is not None:
        cmp = compare_with_truth(profile, true_ud)
        section += ["", "Against the true wind of this synthetic flight:", "",
                    "| Axis | correlation | RMS error | RMS of the true wind |", "|---|---|---|---|"]
        section += [f"| {a} | {v['correlation']:.3f} | {v['rms_error']:.4f} | {v['rms_truth']:.4f} |"
                    for a, v in cmp.items()]
    if figure_prefix is not None:
        section += [""] + [f"![{k}]({figure_prefix}_{k}.png)" for k in figure_names(profile)]
    return section + [""]


@dataclass(frozen=True)
class ReportContent:
    """What ``report.md`` says.

    Attributes
    ----------
    flights : list of Flight
        The flights identified from (pooled).
    identifiers : dict of str to identifier
        The ``"decoupled"`` and ``"coupled"`` fits (only the chosen one when the workflow was asked not to
        compare the structures).
    chosen : str
        Which one was written.
    model_path : Path
        Where ``model.json`` was written.
    sources : sequence of dict
        Provenance of the flight files (``{"file": ..., "sha256": ...}``).
    warnings : list of str
        What the data cannot support well.
    truth : ModelParams or None
        Truth of a synthetic flight.
    method : {"ml", "integral"}
    validation : ValidationResult
    plots : bool
        Whether the report links the figures.
    disturbances : bool
        Whether the flights' winds were identified and stored.
    library_version : int or None
        Version of the disturbance library written.
    wind_sections : list of str
        The lines of every flight's wind section (:func:`wind_section`).
    reference : IntegralIdentifier or None
        The integral method's fit shown beside a maximum-likelihood one.
    verdict : model_store.verdict.ModelVerdict or None
        Whether the written model can be used; the report opens with it.
    frequency : FrequencyComparison or str or None
        The model's and the fitted flights' frequency responses
        (:func:`identification.validation.frequency_response.compare_frequency_response`), or why there are none.
    flight_checks : list of FlightValidation
        The model on flights it was not fitted on (``--validate``,
        :mod:`identification.validation.other_flights`).
    """

    flights: list
    identifiers: dict
    chosen: str
    model_path: Path
    sources: list
    warnings: list
    truth: ModelParams | None
    method: str
    validation: ValidationResult
    plots: bool
    disturbances: bool
    library_version: int | None
    wind_sections: list
    reference: object = None
    verdict: object = None
    frequency: object = None
    flight_checks: list = ()


def report_markdown(c: ReportContent) -> str:
    """The text of ``report.md``."""
    ident = c.identifiers[c.chosen]
    first = ident.flights_[0]
    n_total = sum(f.n for f in c.flights)
    dur = sum(f.duration for f in c.flights)
    src_lines = ("\n".join(f"- `{s.get('file')}` (SHA-256 `{s.get('sha256', '')[:16]}…`)" for s in c.sources)
                 or "- (in memory)")
    md = [
        "# Identification report",
        "",
        *(c.verdict.markdown() if c.verdict is not None else []),
        f"Model written: `{c.model_path.name}` ({c.chosen}). Flights: {len(c.flights)}, {dur:.1f} s, {n_total} "
        f"samples at {first.sample_rate:.1f} Hz.",
        "",
        src_lines,
        "",
        method_sentence(ident),
        "",
    ]
    if c.warnings:
        md += ["## Warnings", ""] + [f"- {w}" for w in c.warnings] + [""]
    md += ["## Identified parameters", "", parameter_table(c.identifiers, c.truth), ""]
    if c.method == "ml":
        md += _likelihood_sections(c, ident)
    md += ["## Fit statistics", "", fit_table(c.identifiers), "",
           "## Validation by forward simulation (no disturbance)", "", validation_markdown(c.validation)]
    if c.plots:
        md += ["![Measured vs modelled body rates](rates.png)", "", "![Detrended attitude](attitude.png)", ""]
    if c.flight_checks:
        md += ["## Validation on flights not used for the fit", ""]
        md += flight_validation_markdown(c.flight_checks, figures=c.plots)
    md += _frequency_section(c)
    if c.disturbances:
        md += ["## Wind disturbance (eqs. 41-47)", "",
               f"Identified with the {c.chosen} model and appended to the disturbance library "
               f"`disturbances/` as version {c.library_version}.", ""] + c.wind_sections
    return "\n".join(md) + "\n"


def _frequency_section(c: ReportContent) -> list[str]:
    """The frequency-response comparison's section of ``report.md`` (CIFER-style), or why there is none."""
    from .frequency_response import FIGURE_NAME, frequency_markdown

    if c.frequency is None:
        return []
    md = ["## Frequency response: flight and model, with coherence", ""]
    if isinstance(c.frequency, str):
        return md + [f"Not estimated: {c.frequency}", ""]
    return md + frequency_markdown(c.frequency, FIGURE_NAME if c.plots else None)


def _likelihood_sections(c: ReportContent, ident) -> list[str]:
    """A maximum-likelihood fit's extra lines: the coupled terms it left out, the wind model, the integral
    method's parameters beside it."""
    md = []
    coupled = c.identifiers.get("coupled")  # absent when only the decoupled model was fitted (heli tune)
    dropped = [p for f in coupled.axes_.values() for p in f.dropped] if coupled is not None else []
    if dropped:
        md += [f"Coupled model: {', '.join(dropped)} left out (—): the data do not support them "
               "(|value| < 3 standard errors; each dropped in turn, weakest first, and the axis refitted).", ""]
    return md + ["## Wind model and sensor noise (maximum likelihood)", "", wind_table(ident), "",
                 "## The integral method (Fig. 5) on the same flights, for comparison", "",
                 parameter_table({f"integral ({c.chosen})": c.reference}, c.truth), ""]


def fit_figures(validation: ValidationResult, out: Path) -> dict:
    """``rates.png`` and ``attitude.png`` of the validation in ``out``: ``{key: path}``."""
    return {"rates_png": plot_rate_fit(validation, out / "rates.png"),
            "attitude_png": plot_attitude_fit(validation, out / "attitude.png")}


def comparison_figures(frequency, flight_checks, out: Path) -> dict:
    """The frequency-response figure (when ``frequency`` is a result) and each validation flight's rates
    (``validation_N.png``, N its place among ``flight_checks``) in ``out``: ``{key: path}``."""
    from .frequency_response import FIGURE_NAME, plot_frequency_response

    paths = {}
    if frequency is not None and not isinstance(frequency, str):
        paths["frequency_response_png"] = plot_frequency_response(frequency, out / FIGURE_NAME)
    for i, c in enumerate(flight_checks):
        if c.validation is not None:
            title = (f"Body rates on {c.name}, a flight not used for the fit: measured vs the {c.model} model "
                     "simulated from its sticks")
            paths[f"validation_{i + 1}_png"] = plot_rate_fit(c.validation, out / f"validation_{i + 1}.png",
                                                             title=title)
    return paths


def wind_figures(profile, out: Path, true_ud, prefix: str) -> dict:
    """One flight's wind figures in ``out``, named ``prefix_*.png``: ``{prefix_key: path}``."""
    return {f"{prefix}_{k}": v for k, v in save_figures(profile, out, true_ud=true_ud, prefix=prefix).items()}
