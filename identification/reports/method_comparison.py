"""``comparison.md``: Tables 3, 4 and 5 of the paper, as measured by
:func:`~identification.bench.method_comparison.compare_methods`.

:func:`comparison_markdown` writes a :class:`~identification.bench.method_comparison.MethodComparison`
in the paper's layout: Table 3 (integral method and NLR), Table 4 (the EKF's
six settings), Table 5 (the EKF on shorter windows), then the speed ratios of
the run and the issue's target, judged in-sample and, with a validation
flight, held-out.
"""

from __future__ import annotations

import math
import statistics
from typing import TYPE_CHECKING

from ..baselines.ekf import P0_EQ74
from ..bench.method_comparison import TARGET_SPEEDUP
from .tables import markdown_table

if TYPE_CHECKING:
    from ..bench.method_comparison import MethodComparison
    from ..bench.method_runs import MethodRun


def comparison_markdown(comparison: MethodComparison) -> str:
    """Tables 3, 4 and 5 in the paper's layout, plus the speed ratios of this run.

    With a validation flight, Tables 3-5 also hold each model's held-out
    errors on it, and the target is judged both in-sample and held-out.
    """
    text = _ComparisonText(comparison)
    lines = text.intro() + text.table3() + text.table4() + text.table5() + text.speed()
    return "\n".join(lines) + "\n"


class _ComparisonText:
    """The sections of ``comparison.md`` for one comparison, with the column headings they share."""

    def __init__(self, comparison: MethodComparison):
        self.c = comparison
        self.ratios = comparison.speed_ratios()
        self.held = ["Held-out MAE (deg/s)", "Held-out p90 (deg/s)"] if comparison.validation is not None else []
        self.head = ["CPU time (s)", "Wall time (s)", "Runs", "Mean absolute error (deg/s)",
                     "90th percentile (deg/s)", *self.held, "CPU time / integral"]
        self.phead = [_param_head(n, comparison.truth) for n in comparison.param_names]

    def intro(self) -> list[str]:
        """Heading, the flight, the shared filter, the yardstick and (when shortened) the quick-run warning."""
        c = self.c
        f, s, pf, v = c.flight, c.settings, c.prefilter, c.validation
        lines = [
            f"## Method comparison, {c.axis} axis (paper Tables 3-5)",
            "",
            f"Flight: {f.get('source', 'in memory')}, {f['duration_s']:.1f} s, {f['samples']} samples at "
            f"{f['sample_rate_hz']:.0f} Hz. Every method fits the decoupled model "
            f"({', '.join(c.param_names)}; paper: k1, k2, kd) on the same flight low-pass filtered once "
            f"(zero-phase FIR, pass {pf['pass_hz']:g} Hz / stop {pf['stop_hz']:g} Hz, "
            f"{_fmt_time(pf['cpu_time_s'])} s CPU, counted in no method).",
            f"MAE and 90th percentile: forward simulation of each identified model over the whole flight against "
            f"the filtered measured rate (in-sample). CPU time: median of the timed runs (time.process_time), "
            f"BLAS threads: {s.get('blas_threads', 'not limited')}.",
        ]
        if v is not None:
            vf = v["flight"]
            lines.append(
                f"Held-out MAE and p90: the same identified parameters simulated the same way on a validation flight "
                f"no method saw: {vf.get('source', 'in memory')}, {vf['duration_s']:.1f} s, {vf['samples']} samples "
                f"at {vf['sample_rate_hz']:.0f} Hz, prefiltered the same way.")
        else:
            lines.append("No validation flight: in-sample errors only (held-out comparison not run).")
        if s.get("quick"):
            lines += ["", f"**Quick run:** NLR limited to {s.get('nlr_max_nfev')} objective evaluations per start "
                          f"and fewer repeats; the NLR figures are indicative only."]
        return lines

    def table3(self) -> list[str]:
        """Table 3: the integral method, NLR from each start and the true parameters' reference row."""
        c = self.c
        names, v = c.param_names, c.validation
        rows = [[c.integral.label, *self.cells(c.integral, None), *self.pcells(c.integral)]]
        for r in c.nlr:
            rows.append([r.label, *self.cells(r, self.ratios["nlr"][r.label]), *self.pcells(r)])
        v_truth = (v or {}).get("truth")
        v_errors = (v or {}).get("truth_errors")
        if c.truth_errors or v_errors:
            ref_values = c.truth or v_truth
            rows.append(["True parameters (reference)", "", "", "", *self.truth_cells(), "",
                         *[_fmt(ref_values[n]) for n in names]])
        lines = ["", "### Table 3: integral method and nonlinear regression (NLR)", "",
                 markdown_table(["Method", *self.head, *self.phead], rows, right_align=False)]
        notes = [f"{r.label}: {r.note}" for r in (c.integral, *c.nlr) if r.note]
        if c.truth and v_truth and any(not math.isclose(c.truth[n], v_truth[n], rel_tol=1e-9) for n in names):
            notes.append("the validation flight was flown with other true parameters ("
                         + ", ".join(f"{n} = {_fmt(v_truth[n])}" for n in names)
                         + "); its reference row shows the identification flight's")
        elif v is not None and not v_truth and c.truth_errors:
            notes.append("the validation flight's true parameters are unknown: no held-out reference")
        return lines + _notes(notes)

    def table4(self) -> list[str]:
        """Table 4: the EKF for each setting of ``Q`` and the initial state (empty without EKF rows)."""
        if not self.c.ekf:
            return []
        rows = [[r.label, _fmt_vector(r.settings["m0"]), f"{r.settings['q']:g}",
                 *self.cells(r, self.ratios["ekf"][r.label]), *self.pcells(r)] for r in self.c.ekf]
        lines = ["", "### Table 4: EKF, error statistics for the rate", "",
                 "m_o = [initial rate (rad/s), damping, gain, offset]; "
                 f"initial covariance diag({', '.join(f'{v:g}' for v in P0_EQ74)}) (eq. 74); "
                 "R estimated from the filtered rate.", "",
                 markdown_table(["Case", "m_o", "Q", *self.head, *self.phead], rows, right_align=False)]
        return lines + _notes([f"{r.label}: {r.note}" for r in self.c.ekf if r.note])

    def table5(self) -> list[str]:
        """Table 5: the EKF on the first seconds of the flight (empty without such rows)."""
        runs = self.c.sample_lengths
        if not runs:
            return []
        first = runs[0].settings
        rows = [[r.label, f"{r.settings['length_s']:g}", _fmt(r.mae), _fmt(r.p90), *self.heldout_cells(r),
                 _fmt_time(r.cpu_time), *self.pcells(r)] for r in runs]
        lines = ["", "### Table 5: EKF, error statistics for different sample lengths", "",
                 f"EKF with Q = {first['q']:g} and m_o = {_fmt_vector(first['m0'])}, run on the first "
                 "seconds of the flight; errors of the forward simulation over the whole flight"
                 + (" (and over the whole validation flight, held-out)." if self.c.validation is not None else "."),
                 "",
                 markdown_table(["Case", "Sample time period (s)", "Mean absolute error (deg/s)",
                                 "90th percentile (deg/s)", *self.held, "CPU time (s)", *self.phead], rows,
                                right_align=False)]
        return lines + _notes([f"{r.label}: {r.note}" for r in runs if r.note])

    def speed(self) -> list[str]:
        """The speed ratios of this run, the target's verdicts and the paper's figures."""
        ratios = self.ratios
        lines = ["", "### Speed ratios (CPU time, this run)", ""]
        if ratios["nlr"]:
            lines.append("- NLR / integral: " + ", ".join(f"{k} {_fmt_ratio(v)}" for k, v in ratios["nlr"].items()))
        if ratios["ekf"]:
            ekf = list(ratios["ekf"].values())
            lines.append("- EKF / integral: " + ", ".join(f"{k} {_fmt_ratio(v)}" for k, v in ratios["ekf"].items())
                         + f" (median {_fmt_ratio(statistics.median(ekf))})")
        t = self.c.target()
        if t:
            lines += [
                f"- Target (integral >= {TARGET_SPEEDUP:.0f}x faster than NLR at equal or better MAE), against "
                f"{t['nlr_label']}: speed ratio {_fmt_ratio(t['speedup'])} "
                f"({'>=' if t['faster'] else '<'} {TARGET_SPEEDUP:.0f}x).",
                "  - In-sample (identification flight): " + _verdict(
                    t["mae_integral"], t["mae_nlr"], t["mae_ratio"], t["mae_change_pct"], t["faster"],
                    t["as_accurate"], t["met"], t["speedup"]),
            ]
            lines += _heldout_verdict(t)
        lines.append("- Paper (Tables 3-4): NLR [5, 5, 5] / integral ~710x; EKF / integral ~30x.")
        return lines

    # ------------------------------------------------------------ cells
    def cells(self, run: MethodRun, ratio) -> list[str]:
        """Timing, errors and the speed ratio of ``run`` (``ratio`` None: the integral method's own row)."""
        return [_fmt_time(run.cpu_time), _fmt_time(run.wall_time), str(run.repeats), _fmt(run.mae), _fmt(run.p90),
                *self.heldout_cells(run), "1x" if ratio is None else _fmt_ratio(ratio)]

    def heldout_cells(self, run: MethodRun) -> list[str]:
        """Held-out MAE and p90 of ``run`` (no cells without a validation flight)."""
        if self.c.validation is None:
            return []
        return [_fmt(run.heldout_mae), _fmt(run.heldout_p90)]

    def truth_cells(self) -> list[str]:
        """In-sample (and held-out) MAE and p90 cells of the reference row."""
        e = self.c.truth_errors or {}
        cells = [_fmt(e.get("mae_deg_s")), _fmt(e.get("p90_deg_s"))]
        if self.c.validation is not None:
            h = self.c.validation.get("truth_errors") or {}
            cells += [_fmt(h.get("mae_deg_s")), _fmt(h.get("p90_deg_s"))]
        return cells

    def pcells(self, run: MethodRun) -> list[str]:
        """The identified parameters of ``run``, each with its error against the truth when known."""
        errs = self.c.param_errors(run)
        cells = []
        for n in self.c.param_names:
            v = run.params.get(n, float("nan"))
            cells.append(_fmt(v) if errs is None else f"{_fmt(v)} ({errs[n]:+.1f} %)")
        return cells


def _heldout_verdict(t: dict) -> list[str]:
    """The target's held-out verdict and what the true parameters' errors say about both verdicts."""
    if t["heldout_mae_ratio"] is not None:
        lines = ["  - Held-out (validation flight): " + _verdict(
            t["heldout_mae_integral"], t["heldout_mae_nlr"], t["heldout_mae_ratio"],
            t["heldout_mae_change_pct"], t["faster"], t["heldout_as_accurate"], t["met_heldout"],
            t["speedup"])]
    else:
        lines = ["  - Held-out: not evaluated (no validation flight)."]
    if t["mae_truth"] is not None:
        held_truth = (f" ({t['heldout_mae_truth']:.4f} deg/s on the validation flight)"
                      if t["heldout_mae_truth"] is not None else "")
        lines.append(
            f"- The true parameters simulate to {t['mae_truth']:.4f} deg/s MAE on this flight{held_truth}: "
            "no method models the wind, and an MAE below that comes from bending the parameters "
            "to absorb it (see the parameter errors).")
        if t["heldout_mae_truth"] is not None and t["heldout_mae_nlr"] < t["heldout_mae_truth"]:
            lines.append(
                f"- NLR's parameters also beat the true ones on the validation flight "
                f"({t['heldout_mae_nlr']:.4f} vs {t['heldout_mae_truth']:.4f} deg/s): their bend is not "
                "fitted to this flight's gusts alone; the forward-simulation MAE favours it on an unseen "
                "flight with the same wind as well, so a held-out MAE does not measure closeness to the "
                "truth either.")
    return lines


def _notes(notes: list[str]) -> list[str]:
    """A table's notes as a bulleted list after a blank line (nothing without notes)."""
    return [""] + [f"- {n}" for n in notes] if notes else []


def _verdict(mae_integral, mae_nlr, ratio, change, faster, accurate, met, speedup) -> str:
    """One line of the target: the MAEs, their ratio and the verdict with its reasons."""
    why = []
    if not faster:
        why.append(f"speed-up {_fmt_ratio(speedup)} < {TARGET_SPEEDUP:.0f}x")
    if not accurate:
        why.append(f"integral MAE {change:+.1f} % against NLR")
    return (f"MAE integral {mae_integral:.4f} vs NLR {mae_nlr:.4f} deg/s, ratio integral/NLR {ratio:.3f} "
            f"({change:+.1f} %): **{'met' if met else 'NOT met'}**" + (f" ({'; '.join(why)})" if why else "") + ".")


def _fmt(v) -> str:
    if v is None or not math.isfinite(v):
        return "n/a"
    return f"{v:.4f}" if abs(v) < 1e4 else f"{v:.4g}"


def _fmt_time(v) -> str:
    if v is None or not math.isfinite(v):
        return "n/a"
    return f"{v:.4f}" if v < 1.0 else f"{v:.2f}"


def _fmt_ratio(v) -> str:
    if not math.isfinite(v):
        return "n/a"
    return f"{v:,.0f}x" if v >= 10 else f"{v:.1f}x"


def _fmt_vector(v) -> str:
    return "[" + " ".join(f"{x:g}" for x in v) + "]"


def _param_head(name: str, truth) -> str:
    unit = {"damp": "1/s", "gain": "rad/s^2", "offset": "rad/s^2"}
    role = {0: "damp", 1: "gain", 2: "offset"}
    for names in (("k3", "k2", "kd1"), ("k7", "k6", "kd2"), ("k11", "k10", "kd3")):
        if name in names:
            u = unit[role[names.index(name)]]
            break
    else:
        u = ""
    head = f"{name} ({u})" if u else name
    return head + (" (error)" if truth else "")
