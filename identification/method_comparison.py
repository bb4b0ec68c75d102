"""The paper's method comparison on one flight: integral method, NLR and EKF (Tables 3-5).

Section 3.5 times the integral method (Fig. 5) against nonlinear regression
over forward simulations (eqs. 71-73, Table 3); Section 3.6 runs the parameter
EKF (eqs. 48-64) for six settings of ``Q`` and the initial state (Table 4) and
on three lengths of data (Table 5). :func:`compare_methods` reproduces the
three tables on any flight, with every figure measured in the same run:

* **Same data.** The flight is low-pass filtered once (Section 3.1, the 4/8 Hz
  zero-phase FIR of :func:`identification.preprocess.lowpass_flight`) and every
  method identifies the *same* decoupled single-axis model (roll: eq. 18 with
  ``k1 = k4 = 0``, parameters ``k3, k2, kd1``) on that filtered flight. The
  integral method is therefore run with ``prefilter=False``; the shared
  filtering is timed separately and counted in no method.
* **Same yardstick.** Each identified model is forward-simulated over the whole
  flight from the measured initial rate
  (:func:`identification.baselines.simulate_rate`, one physics core) and
  compared with the same filtered measured rate: mean absolute error and 90th
  percentile [deg/s] (:func:`identification.baselines.rate_errors`).
* **Held-out flight.** The in-sample error flatters NLR, which minimises that
  very error: on a windy flight it bends the parameters to absorb the
  unmodelled wind. Pass a second flight as ``validation`` and every identified
  model is also scored on it (prefiltered the same way, the same forward
  simulation, the same MAE / 90th percentile), a flight no method has seen.
  The target verdict then states both comparisons, in-sample and held-out.
* **Same clock.** Each method's ``fit`` call is timed with
  :func:`time.process_time` (CPU) and :func:`time.perf_counter` (wall); fast
  methods are repeated after one untimed warm-up and the median is kept
  (:data:`DEFAULT_REPEATS`: integral 20, EKF 3, NLR 1). The speed ratios
  NLR/integral and EKF/integral are taken between these medians. While timing,
  BLAS is held to ``blas_threads`` threads (default 1) when ``threadpoolctl``
  is installed: process time adds up the CPU of every thread, so a library
  that spins up threads for tiny matrices would otherwise be charged for it.

On a synthetic flight the true parameters are known
(:func:`identification.synthetic.load_truth`); pass them as ``truth`` and the
tables also show each parameter's error and a reference row with the true
parameters simulated the same way (the wind is not modelled by any method, so
its MAE is the floor none of the three can be expected to beat by much).
"""

from __future__ import annotations

import contextlib
import json
import math
import platform
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .baselines import (
    P0_EQ74,
    TABLE3_STARTS,
    TABLE4_M0,
    TABLE4_Q,
    TABLE5_LENGTHS,
    NonlinearRegression,
    ParameterEKF,
    parameter_names,
    rate_errors,
    simulate_rate,
)
from .baselines.single_axis import axis_index, make_params
from .errors import FlightLogError, IdentifiabilityError
from .files import jsonable, write_text
from .flight import Flight
from .integral_method import IntegralIdentifier
from .model import ModelParams
from .preprocess import DEFAULT_PASS_HZ, DEFAULT_STOP_HZ, lowpass_flight

SCHEMA = "heli-env/method-comparison/2"
"""Schema tag of :meth:`MethodComparison.to_dict` (2: held-out errors on a validation flight)."""

READABLE_SCHEMAS = (SCHEMA, "heli-env/method-comparison/1")
"""Schemas :meth:`MethodComparison.from_dict` reads (version 1 has no held-out errors)."""

SAMPLE_RATE_TOLERANCE = 1e-3
"""Relative difference allowed between the sample rates of the identification
and the validation flight (median sample intervals of logged data jitter)."""

TABLE4_CASES: tuple[tuple[str, float, tuple[float, ...]], ...] = tuple(
    (f"Case {c}({m})", TABLE4_Q[c], TABLE4_M0[m]) for c in (1, 2, 3) for m in ("a", "b")
)
"""Table 4's six EKF settings ``(label, Q [(rad/s)^2], m_o = [p0, k_damp, k_gain, kd])``."""

TABLE5_EKF = {"q": TABLE4_Q[3], "m0": TABLE4_M0["a"]}
"""EKF settings of Table 5 (``Q = 1e-2`` and ``m_o`` of case (a), Section 3.6)."""

DEFAULT_REPEATS = {"integral": 20, "ekf": 3, "nlr": 1}
"""Timed runs per method; the median CPU and wall time are reported."""

QUICK_NLR_MAX_NFEV = 10
"""Objective evaluations allowed per NLR start with ``--quick`` (a converged
roll fit from eq. (73)'s start takes about 8-9; far starts are cut short)."""

TARGET_SPEEDUP = 1000.0
"""Issue target: the integral method at least this many times faster than NLR (CPU time)."""


# ------------------------------------------------------------------ results
@dataclass(frozen=True)
class MethodRun:
    """One row of the comparison: a method, its settings, timing and errors.

    Attributes
    ----------
    method : {"integral", "nlr", "ekf", "ekf_length"}
        Which identifier (``ekf_length`` is a Table 5 row).
    label : str
        Row label in the paper's wording, e.g. ``"NLR [5, 5, 5]"``, ``"Case 2(a)"``.
    settings : dict
        Method settings: NLR ``start``, ``max_nfev``; EKF ``q``, ``m0``, ``r``;
        Table 5 ``length_s``.
    params : dict of str to float
        Identified parameters (paper order: damping, gain, offset).
    mae : float
        Mean absolute error of the forward simulation over the whole flight [deg/s].
    p90 : float
        90th percentile of the absolute error [deg/s].
    heldout_mae, heldout_p90 : float or None
        The same errors of the same parameters on the validation flight
        [deg/s]; ``None`` without one.
    cpu_time : float
        Median CPU time of ``fit`` [s] (:func:`time.process_time`).
    wall_time : float
        Median wall time of ``fit`` [s] (:func:`time.perf_counter`).
    cpu_times, wall_times : tuple of float
        Every timed run [s].
    converged : bool or None
        NLR: ``least_squares`` stopped on a tolerance; EKF: did not diverge;
        ``None`` where it does not apply.
    note : str
        Anything a reader should know (cut short, diverged, ...).
    """

    method: str
    label: str
    settings: dict
    params: dict
    mae: float
    p90: float
    cpu_time: float
    wall_time: float
    cpu_times: tuple = ()
    wall_times: tuple = ()
    converged: bool | None = None
    note: str = ""
    heldout_mae: float | None = None
    heldout_p90: float | None = None

    @property
    def repeats(self) -> int:
        """Number of timed runs behind the medians."""
        return len(self.cpu_times)

    def to_dict(self) -> dict:
        return {
            "method": self.method, "label": self.label, "settings": jsonable(self.settings),
            "params": dict(self.params), "mae_deg_s": self.mae, "p90_deg_s": self.p90,
            "cpu_time_s": self.cpu_time, "wall_time_s": self.wall_time, "repeats": self.repeats,
            "cpu_times_s": list(self.cpu_times), "wall_times_s": list(self.wall_times),
            "converged": self.converged, "note": self.note,
            "heldout_mae_deg_s": self.heldout_mae, "heldout_p90_deg_s": self.heldout_p90,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "MethodRun":
        return cls(
            method=d["method"], label=d["label"], settings=dict(d["settings"]),
            params=dict(d["params"]), mae=_float(d["mae_deg_s"]), p90=_float(d["p90_deg_s"]),
            cpu_time=_float(d["cpu_time_s"]), wall_time=_float(d["wall_time_s"]),
            cpu_times=tuple(map(_float, d["cpu_times_s"])), wall_times=tuple(map(_float, d["wall_times_s"])),
            converged=d["converged"], note=d["note"],
            heldout_mae=_optional_float(d.get("heldout_mae_deg_s")),
            heldout_p90=_optional_float(d.get("heldout_p90_deg_s")),
        )


@dataclass(frozen=True)
class MethodComparison:
    """Tables 3, 4 and 5 measured on one flight (see :func:`compare_methods`).

    Attributes
    ----------
    axis : str
        Axis compared (``"roll"`` in the paper).
    param_names : tuple of str
        Identified parameters in the paper's order, e.g. ``("k3", "k2", "kd1")``.
    flight : dict
        Source, SHA-256 (when read from a file), samples, duration [s], sample rate [Hz].
    prefilter : dict
        The shared low-pass filter: band edges [Hz] and its CPU and wall time [s].
    integral : MethodRun
        Table 3, first row.
    nlr : tuple of MethodRun
        Table 3, one row per start point.
    ekf : tuple of MethodRun
        Table 4, one row per case.
    sample_lengths : tuple of MethodRun
        Table 5, one row per identification window.
    truth : dict of str to float or None
        True values of ``param_names`` (synthetic flights).
    truth_errors : dict or None
        ``{"mae_deg_s", "p90_deg_s"}`` of the true parameters simulated the same way.
    settings : dict
        Repeats, NLR evaluation limit, ``quick``, BLAS threading, versions.
    validation : dict or None
        The held-out flight, when one was given: ``flight`` (as ``flight``),
        ``truth`` (true values of ``param_names`` it was flown with, or None) and
        ``truth_errors`` (``{"mae_deg_s", "p90_deg_s"}`` of those true values on
        it, or None). Each run's ``heldout_mae`` / ``heldout_p90`` are on it.
    """

    axis: str
    param_names: tuple
    flight: dict
    prefilter: dict
    integral: MethodRun
    nlr: tuple = ()
    ekf: tuple = ()
    sample_lengths: tuple = ()
    truth: dict | None = None
    truth_errors: dict | None = None
    settings: dict = field(default_factory=dict)
    validation: dict | None = None

    # ---------------------------------------------------------- derived
    def speed_ratios(self) -> dict[str, dict[str, float]]:
        """CPU-time ratios against the integral method, from this run's medians.

        Returns
        -------
        dict
            ``{"nlr": {label: ratio}, "ekf": {label: ratio}}``; a ratio of 1000
            means the method took 1000 times the integral method's CPU time.
        """
        base = self.integral.cpu_time

        def ratio(run):
            return run.cpu_time / base if base > 0 else float("inf")

        return {"nlr": {r.label: ratio(r) for r in self.nlr}, "ekf": {r.label: ratio(r) for r in self.ekf}}

    def param_errors(self, run: MethodRun) -> dict[str, float] | None:
        """Relative error of each identified parameter against the truth [%], or None without truth."""
        if not self.truth:
            return None
        out = {}
        for name in self.param_names:
            t = self.truth.get(name)
            v = run.params.get(name, float("nan"))
            out[name] = 100.0 * (v - t) / abs(t) if t else float("nan")
        return out

    def target(self) -> dict:
        """The issue's target against the NLR run from eq. (73)'s start (the paper's 710x row).

        The target is "integral at least :data:`TARGET_SPEEDUP` times faster than
        NLR at equal or better MAE". It is judged twice and both verdicts are
        reported: on the identification flight itself (in-sample, where NLR
        minimises the very error it is scored by) and on the validation flight
        (held-out), when one was given.

        Returns
        -------
        dict
            ``nlr_label``, ``speedup`` (NLR CPU time / integral CPU time), ``faster``
            (speedup >= :data:`TARGET_SPEEDUP`);
            in-sample: ``mae_integral``, ``mae_nlr``, ``mae_ratio`` (integral / NLR),
            ``mae_change_pct`` (integral relative to NLR), ``as_accurate``
            (integral MAE <= NLR MAE), ``met`` (``faster`` and ``as_accurate``) and
            ``mae_truth`` (MAE of the true parameters, None without truth);
            held-out (all None without a validation flight): ``heldout_mae_integral``,
            ``heldout_mae_nlr``, ``heldout_mae_ratio``, ``heldout_mae_change_pct``,
            ``heldout_as_accurate``, ``met_heldout`` and ``heldout_mae_truth``.
            Empty without NLR rows.
        """
        if not self.nlr:
            return {}
        ref = self.nlr[0]
        speedup = self.speed_ratios()["nlr"][ref.label]
        faster = speedup >= TARGET_SPEEDUP
        ratio, change = _mae_ratio(self.integral.mae, ref.mae)
        accurate = self.integral.mae <= ref.mae
        out = {"nlr_label": ref.label, "speedup": speedup, "faster": faster,
               "mae_integral": self.integral.mae, "mae_nlr": ref.mae, "mae_ratio": ratio,
               "mae_change_pct": change, "as_accurate": accurate, "met": faster and accurate,
               "mae_truth": self.truth_errors["mae_deg_s"] if self.truth_errors else None,
               "heldout_mae_integral": None, "heldout_mae_nlr": None, "heldout_mae_ratio": None,
               "heldout_mae_change_pct": None, "heldout_as_accurate": None, "met_heldout": None,
               "heldout_mae_truth": None}
        if self.validation is not None and self.integral.heldout_mae is not None and ref.heldout_mae is not None:
            h_ratio, h_change = _mae_ratio(self.integral.heldout_mae, ref.heldout_mae)
            h_accurate = self.integral.heldout_mae <= ref.heldout_mae
            v_truth = self.validation.get("truth_errors")
            out.update({"heldout_mae_integral": self.integral.heldout_mae, "heldout_mae_nlr": ref.heldout_mae,
                        "heldout_mae_ratio": h_ratio, "heldout_mae_change_pct": h_change,
                        "heldout_as_accurate": h_accurate, "met_heldout": faster and h_accurate,
                        "heldout_mae_truth": v_truth["mae_deg_s"] if v_truth else None})
        return out

    # ---------------------------------------------------------- serialisation
    def to_dict(self) -> dict:
        """JSON-ready dictionary (non-finite floats become ``None``); inverse of :meth:`from_dict`."""
        return jsonable({
            "schema": SCHEMA,
            "axis": self.axis,
            "param_names": list(self.param_names),
            "flight": self.flight,
            "prefilter": self.prefilter,
            "settings": self.settings,
            "truth": self.truth,
            "truth_errors": self.truth_errors,
            "integral": self.integral.to_dict(),
            "nlr": [r.to_dict() for r in self.nlr],
            "ekf": [r.to_dict() for r in self.ekf],
            "sample_lengths": [r.to_dict() for r in self.sample_lengths],
            "validation": self.validation,
            "speed_ratios": self.speed_ratios(),
            "target": self.target(),
        })

    @classmethod
    def from_dict(cls, d: dict) -> "MethodComparison":
        """Rebuild a comparison from :meth:`to_dict` output (e.g. a loaded ``comparison.json``)."""
        if d.get("schema") not in READABLE_SCHEMAS:
            raise ValueError(f"expected a method comparison of schema {SCHEMA!r}, got {d.get('schema')!r}")
        return cls(
            axis=d["axis"], param_names=tuple(d["param_names"]), flight=dict(d["flight"]),
            prefilter=dict(d["prefilter"]), integral=MethodRun.from_dict(d["integral"]),
            nlr=tuple(MethodRun.from_dict(r) for r in d["nlr"]),
            ekf=tuple(MethodRun.from_dict(r) for r in d["ekf"]),
            sample_lengths=tuple(MethodRun.from_dict(r) for r in d["sample_lengths"]),
            truth=d["truth"], truth_errors=d["truth_errors"],
            settings=dict(d["settings"]), validation=d.get("validation"),
        )

    def save(self, directory) -> dict[str, Path]:
        """Write ``comparison.json`` and ``comparison.md`` into ``directory``, each atomically."""
        directory = Path(directory)
        paths = {"json": directory / "comparison.json", "markdown": directory / "comparison.md"}
        write_text(paths["json"], json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n")
        write_text(paths["markdown"], self.markdown())
        return paths

    # ---------------------------------------------------------- markdown
    def markdown(self) -> str:
        """Tables 3, 4 and 5 in the paper's layout, plus the speed ratios of this run.

        With a validation flight, Tables 3-5 also hold each model's held-out
        errors on it, and the target is judged both in-sample and held-out.
        """
        names = self.param_names
        ratios = self.speed_ratios()
        f = self.flight
        s = self.settings
        pf = self.prefilter
        v = self.validation
        lines = [
            f"## Method comparison, {self.axis} axis (paper Tables 3-5)",
            "",
            f"Flight: {f.get('source', 'in memory')}, {f['duration_s']:.1f} s, {f['samples']} samples at "
            f"{f['sample_rate_hz']:.0f} Hz. Every method fits the decoupled model "
            f"({', '.join(names)}; paper: k1, k2, kd) on the same flight low-pass filtered once "
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
        held = ["Held-out MAE (deg/s)", "Held-out p90 (deg/s)"] if v is not None else []
        head = ["CPU time (s)", "Wall time (s)", "Runs", "Mean absolute error (deg/s)",
                "90th percentile (deg/s)", *held, "CPU time / integral"]
        phead = [_param_head(n, self.truth) for n in names]

        rows = [[self.integral.label, *self._cells(self.integral, None), *self._pcells(self.integral)]]
        for r in self.nlr:
            rows.append([r.label, *self._cells(r, ratios["nlr"][r.label]), *self._pcells(r)])
        v_truth = (v or {}).get("truth")
        v_errors = (v or {}).get("truth_errors")
        if self.truth_errors or v_errors:
            ref_values = self.truth or v_truth
            rows.append(["True parameters (reference)", "", "", "", *self._truth_cells(), "",
                         *[_fmt(ref_values[n]) for n in names]])
        lines += ["", "### Table 3: integral method and nonlinear regression (NLR)", "",
                  _md_table(["Method", *head, *phead], rows)]
        notes = [f"{r.label}: {r.note}" for r in (self.integral, *self.nlr) if r.note]
        if self.truth and v_truth and any(not math.isclose(self.truth[n], v_truth[n], rel_tol=1e-9) for n in names):
            notes.append("the validation flight was flown with other true parameters ("
                         + ", ".join(f"{n} = {_fmt(v_truth[n])}" for n in names)
                         + "); its reference row shows the identification flight's")
        elif v is not None and not v_truth and self.truth_errors:
            notes.append("the validation flight's true parameters are unknown: no held-out reference")
        if notes:
            lines += [""] + [f"- {n}" for n in notes]

        if self.ekf:
            rows = [[r.label, _fmt_vector(r.settings["m0"]), f"{r.settings['q']:g}",
                     *self._cells(r, ratios["ekf"][r.label]), *self._pcells(r)] for r in self.ekf]
            lines += ["", "### Table 4: EKF, error statistics for the rate", "",
                      "m_o = [initial rate (rad/s), damping, gain, offset]; "
                      f"initial covariance diag({', '.join(f'{v:g}' for v in P0_EQ74)}) (eq. 74); "
                      "R estimated from the filtered rate.", "",
                      _md_table(["Case", "m_o", "Q", *head, *phead], rows)]
            notes = [f"{r.label}: {r.note}" for r in self.ekf if r.note]
            if notes:
                lines += [""] + [f"- {n}" for n in notes]

        if self.sample_lengths:
            first = self.sample_lengths[0].settings
            rows = [[r.label, f"{r.settings['length_s']:g}", _fmt(r.mae), _fmt(r.p90), *self._heldout_cells(r),
                     _fmt_time(r.cpu_time), *self._pcells(r)] for r in self.sample_lengths]
            lines += ["", "### Table 5: EKF, error statistics for different sample lengths", "",
                      f"EKF with Q = {first['q']:g} and m_o = {_fmt_vector(first['m0'])}, run on the first "
                      "seconds of the flight; errors of the forward simulation over the whole flight"
                      + (" (and over the whole validation flight, held-out)." if v is not None else "."), "",
                      _md_table(["Case", "Sample time period (s)", "Mean absolute error (deg/s)",
                                 "90th percentile (deg/s)", *held, "CPU time (s)", *phead], rows)]
            notes = [f"{r.label}: {r.note}" for r in self.sample_lengths if r.note]
            if notes:
                lines += [""] + [f"- {n}" for n in notes]

        lines += ["", "### Speed ratios (CPU time, this run)", ""]
        if ratios["nlr"]:
            lines.append("- NLR / integral: " + ", ".join(f"{k} {_fmt_ratio(v)}" for k, v in ratios["nlr"].items()))
        if ratios["ekf"]:
            ekf = list(ratios["ekf"].values())
            lines.append("- EKF / integral: " + ", ".join(f"{k} {_fmt_ratio(v)}" for k, v in ratios["ekf"].items())
                         + f" (median {_fmt_ratio(statistics.median(ekf))})")
        t = self.target()
        if t:
            lines += [
                f"- Target (integral >= {TARGET_SPEEDUP:.0f}x faster than NLR at equal or better MAE), against "
                f"{t['nlr_label']}: speed ratio {_fmt_ratio(t['speedup'])} "
                f"({'>=' if t['faster'] else '<'} {TARGET_SPEEDUP:.0f}x).",
                "  - In-sample (identification flight): " + _verdict(
                    t["mae_integral"], t["mae_nlr"], t["mae_ratio"], t["mae_change_pct"], t["faster"],
                    t["as_accurate"], t["met"], t["speedup"]),
            ]
            if t["heldout_mae_ratio"] is not None:
                lines.append("  - Held-out (validation flight): " + _verdict(
                    t["heldout_mae_integral"], t["heldout_mae_nlr"], t["heldout_mae_ratio"],
                    t["heldout_mae_change_pct"], t["faster"], t["heldout_as_accurate"], t["met_heldout"],
                    t["speedup"]))
            else:
                lines.append("  - Held-out: not evaluated (no validation flight).")
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
        lines.append("- Paper (Tables 3-4): NLR [5, 5, 5] / integral ~710x; EKF / integral ~30x.")
        return "\n".join(lines) + "\n"

    def _cells(self, run: MethodRun, ratio) -> list[str]:
        return [_fmt_time(run.cpu_time), _fmt_time(run.wall_time), str(run.repeats), _fmt(run.mae), _fmt(run.p90),
                *self._heldout_cells(run), "1x" if ratio is None else _fmt_ratio(ratio)]

    def _heldout_cells(self, run: MethodRun) -> list[str]:
        if self.validation is None:
            return []
        return [_fmt(run.heldout_mae), _fmt(run.heldout_p90)]

    def _truth_cells(self) -> list[str]:
        """In-sample (and held-out) MAE and p90 cells of the reference row."""
        e = self.truth_errors or {}
        cells = [_fmt(e.get("mae_deg_s")), _fmt(e.get("p90_deg_s"))]
        if self.validation is not None:
            h = self.validation.get("truth_errors") or {}
            cells += [_fmt(h.get("mae_deg_s")), _fmt(h.get("p90_deg_s"))]
        return cells

    def _pcells(self, run: MethodRun) -> list[str]:
        errs = self.param_errors(run)
        cells = []
        for n in self.param_names:
            v = run.params.get(n, float("nan"))
            cells.append(_fmt(v) if errs is None else f"{_fmt(v)} ({errs[n]:+.1f} %)")
        return cells


# ------------------------------------------------------------------ running
def compare_methods(flight: Flight, axis: str = "roll", nlr_starts=TABLE3_STARTS, ekf_cases=TABLE4_CASES,
                    sample_lengths=TABLE5_LENGTHS, repeats=None, progress: bool = True, *,
                    truth: ModelParams | None = None, nlr_max_nfev: int | None = None, prefilter: bool = True,
                    pass_hz: float = DEFAULT_PASS_HZ, stop_hz: float = DEFAULT_STOP_HZ,
                    blas_threads: int | None = 1, quick: bool = False, validation: Flight | None = None,
                    validation_truth: ModelParams | None = None, stage=None) -> MethodComparison:
    """Run the integral method, NLR and the EKF on one flight and tabulate them (Tables 3-5).

    With ``validation``, every identified model is also scored on that second
    flight (held-out): prefiltered the same way, forward-simulated the same
    way, the same MAE and 90th percentile. No method sees it while fitting, and
    its evaluation is outside every timing.

    Parameters
    ----------
    flight : Flight
        The measured flight (rates [rad/s], sticks); filtered here once unless
        ``prefilter=False``.
    axis : {"roll", "pitch", "yaw"}
        Axis whose decoupled model is identified (paper: roll).
    nlr_starts : sequence of sequence of float, shape (n_starts, 3)
        NLR start points ``(k_damp, k_gain, kd)``; default Table 3's.
    ekf_cases : sequence of (label, q, m0)
        EKF settings; default Table 4's six cases (:data:`TABLE4_CASES`).
    sample_lengths : sequence of float
        Table 5 identification windows [s], each at most the flight's duration.
        The EKF settings are :data:`TABLE5_EKF`.
    repeats : dict, optional
        Timed runs per method, merged into :data:`DEFAULT_REPEATS` (keys
        ``"integral"``, ``"ekf"``, ``"nlr"``); Table 5 uses the EKF's.
    progress : bool
        Show a tqdm progress bar over the methods (only when stderr is a terminal).
    stage : callable, optional
        Called with each method's label as it starts (e.g. one line per method in a log).
    truth : ModelParams, optional
        True parameters of a synthetic flight: adds parameter errors and a reference row.
    nlr_max_nfev : int, optional
        Objective evaluations allowed per NLR start (``None``: scipy's default).
    prefilter : bool
        Low-pass filter the flight first (Section 3.1); off when it already is.
    pass_hz, stop_hz : float
        Band edges of the prefilter [Hz].
    blas_threads : int or None
        BLAS threads while timing (needs ``threadpoolctl``; ``None`` leaves them).
    quick : bool
        Recorded in the result (and the Markdown) to flag a shortened run.
    validation : Flight, optional
        A second flight of the same aircraft, at the same sample rate, for the
        held-out errors (``MethodRun.heldout_mae`` / ``heldout_p90``).
    validation_truth : ModelParams, optional
        True parameters the validation flight was flown with (a synthetic
        flight): adds the held-out errors of the reference row. Needs ``validation``.

    Returns
    -------
    MethodComparison

    Raises
    ------
    IdentifiabilityError
        A Table 5 window is longer than the flight, or the integral method
        cannot identify the axis.
    FlightLogError
        The validation flight has another sample rate than the flight, or is
        the flight itself.
    ValueError
        Unknown axis, bad start points, EKF settings or repeat counts.
    """
    names = parameter_names(axis)
    i = axis_index(axis)
    reps = dict(DEFAULT_REPEATS)
    if repeats:
        unknown = set(repeats) - set(reps)
        if unknown:
            raise ValueError(f"repeats keys must be among {sorted(reps)}, got {sorted(unknown)}")
        reps.update(repeats)
    for k, v in reps.items():
        if int(v) != v or v < 1:
            raise ValueError(f"repeats[{k!r}] must be a positive integer, got {v!r}")
    lengths = [float(v) for v in sample_lengths]
    for length in lengths:
        if not 0.0 < length <= flight.duration + 1e-9:
            raise IdentifiabilityError(
                f"Table 5 window of {length:g} s does not fit the flight of {flight.duration:.2f} s; "
                f"pass sample_lengths within (0, {flight.duration:.2f}] s"
            )
    starts = [tuple(float(v) for v in s) for s in nlr_starts]
    cases = [(str(label), float(q), tuple(float(v) for v in m0)) for label, q, m0 in ekf_cases]
    if validation is not None:
        _check_validation(flight, validation)
    elif validation_truth is not None:
        raise ValueError("validation_truth is the truth of a validation flight; pass validation too")

    with _limit_blas(blas_threads) as threads:
        c0, w0 = time.process_time(), time.perf_counter()
        data = lowpass_flight(flight, pass_hz, stop_hz) if prefilter else flight
        pre = {"applied": bool(prefilter), "pass_hz": pass_hz, "stop_hz": stop_hz,
               "cpu_time_s": time.process_time() - c0 if prefilter else 0.0,
               "wall_time_s": time.perf_counter() - w0 if prefilter else 0.0}
        measured = data.rates[i]
        t0 = float(data.time[0])

        def errors_of(params):
            return rate_errors(simulate_rate(params, data, axis), measured)

        heldout_of = None
        if validation is not None:  # filtered outside every timing, as the flight itself
            held = lowpass_flight(validation, pass_hz, stop_hz) if prefilter else validation

            def heldout_of(params):
                return rate_errors(simulate_rate(params, held, axis), held.rates[i])

        jobs = 1 + len(starts) + len(cases) + len(lengths)
        bar = _progress_bar(jobs, progress)

        def begin(label):
            bar.set_description(label)
            if stage is not None:
                stage(label)

        try:
            begin("integral method")
            integ, cpu, wall = _timed(
                lambda: IntegralIdentifier(structure={i: names}, axes=(axis,), prefilter=False).fit(data),
                reps["integral"], warmup=reps["integral"] > 1)
            integral = _run("integral", "Integral method", {"structure": list(names), "prefilter": False},
                            integ.params_, names, errors_of, cpu, wall, heldout_of=heldout_of)
            bar.update()

            nlr_runs = []
            for start in starts:
                label = f"NLR [{', '.join(f'{v:g}' for v in start)}]"
                begin(label)
                est, cpu, wall = _timed(
                    lambda: NonlinearRegression(axis=axis, start=start, max_nfev=nlr_max_nfev).fit(data),
                    reps["nlr"], warmup=False)
                note = ""
                if est.diverged_:
                    note = "the final simulation diverged"
                elif not est.converged_:
                    note = f"stopped after {est.nfev_} evaluations (max_nfev), not converged"
                nlr_runs.append(_run("nlr", label, {"start": list(start), "max_nfev": nlr_max_nfev,
                                                    "simulations": est.n_simulations_, "nfev": est.nfev_},
                                     est.params_, names, errors_of, cpu, wall, est.converged_, note,
                                     heldout_of=heldout_of))
                bar.update()

            ekf_runs = []
            for label, q, m0 in cases:
                begin(f"EKF {label}")
                est, cpu, wall = _timed(lambda: ParameterEKF(axis=axis, q=q, m0=m0).fit(data),
                                        reps["ekf"], warmup=reps["ekf"] > 1)
                ekf_runs.append(_run("ekf", label, {"q": q, "m0": list(m0), "r": est.r_}, est.params_, names,
                                     errors_of, cpu, wall, not est.diverged_,
                                     "the filter diverged; last finite estimate used" if est.diverged_ else "",
                                     heldout_of=heldout_of))
                bar.update()

            length_runs = []
            for k, length in enumerate(lengths, start=1):
                begin(f"EKF on {length:g} s")
                window = data.segment(t0, t0 + length)
                est, cpu, wall = _timed(lambda: ParameterEKF(axis=axis, **TABLE5_EKF).fit(window),
                                        reps["ekf"], warmup=reps["ekf"] > 1)
                length_runs.append(_run("ekf_length", f"Case {k}",
                                        {"length_s": length, "samples": window.n, "q": TABLE5_EKF["q"],
                                         "m0": list(TABLE5_EKF["m0"]), "r": est.r_},
                                        est.params_, names, errors_of, cpu, wall, not est.diverged_,
                                        "the filter diverged; last finite estimate used" if est.diverged_ else "",
                                        heldout_of=heldout_of))
                bar.update()
        finally:
            bar.close()

    truth_values = truth_errors = None
    if truth is not None:
        truth_values = {n: float(truth.get(n)) for n in names}
        e = errors_of(make_params(names, [truth_values[n] for n in names]))
        truth_errors = {"mae_deg_s": e.mae, "p90_deg_s": e.p90}
    validation_info = None
    if validation is not None:
        v_truth = v_errors = None
        if validation_truth is not None:
            v_truth = {n: float(validation_truth.get(n)) for n in names}
            e = heldout_of(make_params(names, [v_truth[n] for n in names]))
            v_errors = {"mae_deg_s": e.mae, "p90_deg_s": e.p90}
        validation_info = {"flight": _flight_info(validation), "truth": v_truth, "truth_errors": v_errors}
    flight_info = _flight_info(flight)
    settings = {"repeats": reps, "nlr_max_nfev": nlr_max_nfev, "quick": bool(quick), "blas_threads": threads,
                "clock": "time.process_time (CPU), time.perf_counter (wall); medians",
                "python": platform.python_version(), "numpy": np.__version__, "machine": platform.machine()}
    return MethodComparison(axis, tuple(names), flight_info, pre, integral, tuple(nlr_runs), tuple(ekf_runs),
                            tuple(length_runs), truth_values, truth_errors, settings, validation=validation_info)


def _flight_info(flight: Flight) -> dict:
    meta = flight.metadata
    return {"source": str(meta.get("source", "in memory")), "sha256": meta.get("sha256"),
            "samples": int(flight.n), "duration_s": float(flight.duration),
            "sample_rate_hz": float(flight.sample_rate)}


def _check_validation(flight: Flight, validation: Flight) -> None:
    """The validation flight must be another flight at the same sample rate."""
    if not isinstance(validation, Flight):
        raise TypeError(f"validation must be a Flight, got {type(validation).__name__}")
    fs, vs = float(flight.sample_rate), float(validation.sample_rate)
    if not math.isclose(fs, vs, rel_tol=SAMPLE_RATE_TOLERANCE):
        raise FlightLogError(
            f"the validation flight ({validation.metadata.get('source', 'in memory')}) is sampled at {vs:g} Hz, "
            f"the identification flight at {fs:g} Hz; the held-out errors need the same sample rate "
            "(the same prefilter and simulation step): resample it or pick a flight logged at "
            f"{fs:g} Hz")
    sha = flight.metadata.get("sha256")
    same = (sha is not None and sha == validation.metadata.get("sha256")) or (
        flight.n == validation.n and np.array_equal(flight.time, validation.time)
        and np.array_equal(flight.rates, validation.rates) and np.array_equal(flight.sticks, validation.sticks))
    if same:
        raise FlightLogError("the validation flight is the identification flight itself; held-out errors need a "
                             "flight the methods did not see")


def _timed(fn, repeats: int, warmup: bool):
    """Run ``fn`` ``repeats`` times (after an untimed warm-up); last result and CPU/wall times."""
    if warmup:
        fn()
    cpu, wall = [], []
    result = None
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        result = fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    return result, cpu, wall


def _run(method, label, settings, params, names, errors_of, cpu, wall, converged=None, note="",
         heldout_of=None) -> MethodRun:
    model = make_params(names, [params.get(n) for n in names])
    e = errors_of(model)
    h = heldout_of(model) if heldout_of is not None else None
    return MethodRun(method, label, settings, {n: float(params.get(n)) for n in names}, e.mae, e.p90,
                     statistics.median(cpu), statistics.median(wall), tuple(cpu), tuple(wall), converged, note,
                     heldout_mae=None if h is None else h.mae, heldout_p90=None if h is None else h.p90)


@contextlib.contextmanager
def _limit_blas(threads):
    """Hold BLAS to ``threads`` threads with threadpoolctl if it is installed; yield what was done."""
    if threads is None:
        yield "not limited"
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        yield "not limited (threadpoolctl not installed)"
        return
    with threadpool_limits(limits=int(threads), user_api="blas"):
        yield int(threads)


def _progress_bar(total: int, enabled: bool):
    """A tqdm bar over the methods on stderr; disabled unless asked for and stderr is a terminal."""
    from tqdm import tqdm

    return tqdm(total=total, unit="method", leave=False, file=sys.stderr,
                disable=not (enabled and sys.stderr.isatty()))


# ------------------------------------------------------------------ formatting
def _float(v) -> float:
    return float("nan") if v is None else float(v)


def _optional_float(v) -> float | None:
    return None if v is None else float(v)


def _mae_ratio(mae_integral: float, mae_nlr: float) -> tuple[float, float]:
    """``(integral / NLR, 100 * (integral - NLR) / NLR)``; NaN when NLR's MAE is 0."""
    if not mae_nlr > 0:
        return float("nan"), float("nan")
    return mae_integral / mae_nlr, 100.0 * (mae_integral - mae_nlr) / mae_nlr


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


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    def cell(t):
        return str(t).replace("|", "\\|")

    out = ["| " + " | ".join(map(cell, header)) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(map(cell, r)) + " |" for r in rows]
    return "\n".join(out)
