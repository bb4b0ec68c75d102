"""How often the likelihood diagnosis names a hidden effect, and how often it names one that is not there.

For every case (a hidden effect of :data:`identification.bench.flight_config.EFFECTS` at the size of the
README's study, a time-misaligned log, or no effect) and every seed, flies a default synthetic
flight (the closed-loop pilot of ``heli simulate-flight``, one-stick sweeps, the paper's wind; or a
bench cell with ``--cell``), runs :class:`identification.diagnosis.likelihood_diagnoser.LikelihoodDiagnoser` without
telling it the truth, and counts per case:

* **named**: the true effect named on every axis it acts on (a delay within 15 ms), and nothing else (a servo
  lag shows first as a delay, which the lag then shortens: with a lag hidden alone, a delay on an axis whose lag
  is named is the lag's first step, not a wrong effect);
* **partly**: the true effect named on some of its axes, nothing else;
* **wrong**: any effect named that is not the truth (on a no-effect flight: any effect at all);

and the dampings of the model the diagnosis fits at the end (what ``heli diagnose`` writes when it names an
effect) against the truth's: RMS relative error per axis over the seeds, and the worst. With ``--closed-loop auto``
the model written is checked in the flight's closed loop first, as ``heli diagnose`` does by default
(:func:`identification.workflows.diagnose.check_written_model`): the dampings before → after the check, and the
check's seconds beside the diagnosis'.

Usage::

    python scripts/likelihood_diagnosis_study.py [--seeds 20] [--duration 180] [--workers 2] [--cell NAME]
        [--closed-loop auto]
    python scripts/likelihood_diagnosis_study.py --null-cells [--seeds 5]   # the floors' calibration
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))  # the --set parser is aircraft_generalisation's
from aircraft_generalisation import config_field  # noqa: E402

CASES = {
    "none": {},
    "servo_delay": {"effects": ("servo_delay",)},
    # a fast servo, 20 / 20 / 12.5 ms: at 100 Hz roll's and pitch's two samples are named; yaw's is below the
    # timing resolution, not named, but the model written keeps it (the dampings column)
    "servo_delay (0.25x)": {"effects": ("servo_delay",), "effect_scale": 0.25},
    # between the two: 32 / 32 / 20 ms (the yaw's on the two-sample bound, as the 0.25x roll and pitch) and
    # 48 / 48 / 30 ms
    "servo_delay (0.4x)": {"effects": ("servo_delay",), "effect_scale": 0.4},
    "servo_delay (0.6x)": {"effects": ("servo_delay",), "effect_scale": 0.6},
    "servo_lag": {"effects": ("servo_lag",)},
    "servo_delay + servo_lag": {"effects": ("servo_delay", "servo_lag")},
    "log input lags 0.3 s": {"shift": 0.3},
    "cross_coupling": {"effects": ("cross_coupling",)},
    "gyroscopic": {"effects": ("gyroscopic",)},
    "collective_torque": {"effects": ("collective_torque",)},
    "gain_scheduling": {"effects": ("gain_scheduling",)},
    "nonlinear_damping (5x)": {"effects": ("nonlinear_damping",), "effect_scale": 5.0},
    # effects that scale with products or powers of the rates, at their catalogue size, on flights that
    # reach the rates where they act (large sweeps on all sticks at once: MANOEUVRE_CONFIG)
    "gyroscopic, manoeuvre": {"effects": ("gyroscopic",), "manoeuvre": True},
    "nonlinear_damping, manoeuvre": {"effects": ("nonlinear_damping",), "manoeuvre": True},
}
TRUE_AXES = {
    "servo_delay": {"servo_delay": ("roll", "pitch", "yaw")},
    "servo_delay (0.25x)": {"servo_delay": ("roll", "pitch")},
    "servo_delay (0.4x)": {"servo_delay": ("roll", "pitch")},
    "servo_delay (0.6x)": {"servo_delay": ("roll", "pitch", "yaw")},
    "servo_lag": {"servo_lag": ("roll", "pitch", "yaw")},
    "servo_delay + servo_lag": {"servo_delay": ("roll", "pitch", "yaw"), "servo_lag": ("roll", "pitch", "yaw")},
    "log input lags 0.3 s": {"servo_delay": ("roll", "pitch", "yaw")},
    "cross_coupling": {"cross_coupling": ("roll", "pitch")},
    "gyroscopic": {"gyroscopic": ("roll", "pitch", "yaw")},
    "collective_torque": {"collective_torque": ("roll", "pitch")},
    "gain_scheduling": {"gain_scheduling": ("roll", "pitch", "yaw")},
    "nonlinear_damping (5x)": {"nonlinear_damping": ("roll", "pitch", "yaw")},
    "gyroscopic, manoeuvre": {"gyroscopic": ("roll", "pitch", "yaw")},
    "nonlinear_damping, manoeuvre": {"nonlinear_damping": ("roll", "pitch", "yaw")},
}


def _flight(name, seed, duration, cell, settings=(), fit_rate="log"):
    """The case's flight and the flight the diagnosis reads: ``settings`` (FlightConfig field, value) changed in
    the flight's config, read at ``fit_rate`` as ``heli diagnose --fit-rate`` reads it."""
    from dataclasses import replace

    from identification.bench.flight_config import MANOEUVRE_CONFIG, FlightConfig
    from identification.bench.synthetic import simulate_flight
    from identification.fit_rate import at_fit_rate
    from identification.preprocess import shift_inputs

    case = CASES[name]
    config = MANOEUVRE_CONFIG if case.get("manoeuvre") else None
    if cell is not None:  # the cell's wind, pilot and sensors; a manoeuvre case keeps its large sweeps
        from identification.bench.cells import BENCH_CELLS

        config = BENCH_CELLS[cell]
        if case.get("manoeuvre"):
            config = replace(config, sweep_amplitude=MANOEUVRE_CONFIG.sweep_amplitude,
                             sweep_mode=MANOEUVRE_CONFIG.sweep_mode)
    if settings:
        config = replace(config or FlightConfig(), **dict(settings))
    sim = simulate_flight(duration, seed=seed, effects=case.get("effects", ()), config=config,
                          effect_scale=case.get("effect_scale", 1.0))
    flight = sim.flight
    if "shift" in case:  # the log's input column lags the response: the sticks are recorded late
        flight = shift_inputs(flight, (case["shift"],) * 3)
    (flight,), _ = at_fit_rate([flight], fit_rate)
    return sim, flight


def _one(job):
    from threadpoolctl import threadpool_limits

    from identification.diagnosis.likelihood_diagnoser import LikelihoodDiagnoser

    name, seed, duration, cell, closed_loop, settings, fit_rate = job
    with threadpool_limits(limits=1, user_api="blas"):
        sim, flight = _flight(name, seed, duration, cell, settings, fit_rate)
        t0 = time.perf_counter()
        d = LikelihoodDiagnoser().fit(flight)  # not told the truth: the sticks' hold is chosen by likelihood too
        seconds = time.perf_counter() - t0
        fitted = _damping_error(d, sim)
        check_seconds = 0.0
        if closed_loop != "off" and d.steps_:  # heli diagnose checks the model it writes
            from identification.workflows.diagnose import check_written_model

            check_written_model(d, closed_loop)
            check_seconds = time.perf_counter() - t0 - seconds
    found = {}
    for s in d.steps_:
        found.setdefault(s.effect, {})[s.axis] = s.parameters.get("alignment_s")
    truth = TRUE_AXES.get(name, {})
    # a servo lag shows first as a delay, which the lag then shortens: a delay on an axis whose hidden lag is
    # named is the lag's first step (its value is checked only where the truth has a delay)
    lag_only = "servo_lag" in truth and "servo_delay" not in truth
    wrong = [e for e in found if e not in truth and not (
        lag_only and e == "servo_delay" and set(found[e]) <= set(found.get("servo_lag", {})))]
    ok_axes = []
    for effect, axes in truth.items():
        for axis in axes:
            if axis in found.get(effect, {}):
                value = found[effect][axis]
                if effect == "servo_delay" and "servo_lag" not in truth:
                    want = -CASES[name]["shift"] if "shift" in CASES[name] else sim.truth.taus[("roll", "pitch",
                                                                                                "yaw").index(axis)]
                    if abs(value - want) > 0.015:
                        continue
                ok_axes.append(axis)
    n_true = sum(len(v) for v in truth.values())
    return {"case": name, "seed": seed, "found": {e: sorted(v) for e, v in found.items()},
            "named": bool(truth) and not wrong and len(ok_axes) == n_true,
            "partly": bool(truth) and not wrong and 0 < len(ok_axes) < n_true,
            "wrong": bool(wrong), "seconds": seconds,
            "max_lr": max((r["lr"] / r["threshold"] for rows in d.rounds_[:1] for r in rows), default=0.0),
            "cell": cell, "round1": [(r["axis"], r["effect"], r["lr"]) for rows in d.rounds_[:1] for r in rows],
            "closed": dict(d.closed_loop_), "steps": [(s.axis, s.effect, s.lr) for s in d.steps_],
            "lags": dict(zip(("roll", "pitch", "yaw"), d.lags_)),
            "alignment": dict(zip(("roll", "pitch", "yaw"), d.alignment_)),
            "timing_detected": dict(getattr(d, "timing_detected_", {})),
            # the model heli diagnose writes when it names an effect: its dampings against the truth, as fitted and
            # after the closed-loop check (the same without it)
            "damping_error_fitted": fitted, "damping_error": _damping_error(d, sim), "check_seconds": check_seconds}


def _damping_error(d, sim) -> dict:
    """The relative errors of the diagnosis' final dampings against the truth's."""
    return {k: getattr(d.params_, k) / getattr(sim.truth, k) - 1.0 for k in ("k3", "k7", "k11")}


def _dampings(rows, key: str = "damping_error") -> str:
    """The final model's dampings' RMS relative error over the rows, in %, and the worst single one (``key``:
    after the closed-loop check, or ``"damping_error_fitted"`` before it)."""
    errs = np.array([[r[key][k] for k in ("k3", "k7", "k11")] for r in rows]) * 100.0
    rms = np.sqrt(np.mean(errs ** 2, axis=0))
    return " / ".join(f"{v:.1f}" for v in rms) + f" [{np.max(np.abs(errs)):.1f}]"


def _null_table(rows, cells):
    """Per candidate effect: the largest round-1 statistic on effect-free flights, per cell and over all."""
    from identification.diagnosis.effects import CATALOGUE
    from identification.diagnosis.likelihood_diagnoser import LikelihoodDiagnoser

    thr_terms, thr_align = LikelihoodDiagnoser().threshold(6, 1), LikelihoodDiagnoser().threshold(6, 1, True)
    print("\nEffect-free flights: the largest round-1 likelihood-ratio statistic of each candidate (any axis), "
          f"against the thresholds for one parameter among six candidates ({thr_terms:.1f} for a term, "
          f"{thr_align:.1f} for the alignment)\n")
    print("| cell | flights | " + " | ".join(CATALOGUE) + " | flights with a wrong effect |")
    print("|---|---|" + "---|" * len(CATALOGUE) + "---|")
    for cell in cells + ["all"]:
        rs = [r for r in rows if cell == "all" or r["cell"] == cell]
        top = {e: max((lr for r in rs for _, ee, lr in r["round1"] if ee == e), default=float("nan"))
               for e in CATALOGUE}
        print(f"| {cell} | {len(rs)} | " + " | ".join(f"{v:.1f}" for v in top.values())
              + f" | {sum(r['wrong'] for r in rs)}/{len(rs)} |")


def _run(jobs, args) -> list:
    """Every job's row (in parallel), also written to ``args.json`` when asked."""
    from tqdm import tqdm

    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight"))
    if args.json:
        from heli_core.files import write_text

        write_text(args.json, json.dumps(rows, indent=1))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1,
                    help="first seed (default 1; calibrate on other seeds than the ones a table reports)")
    ap.add_argument("--duration", type=float, default=180.0)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES), metavar="CASE")
    ap.add_argument("--cell", default=None, help="a bench cell (identification.bench.cells) instead of the default flight")
    ap.add_argument("--null-cells", action="store_true",
                    help="instead: effect-free flights of every bench cell, and the largest statistic per candidate "
                    "(the calibration of the floors)")
    ap.add_argument("--cells", nargs="+", default=None, metavar="CELL",
                    help="with --null-cells: these bench cells only (default all)")
    ap.add_argument("--closed-loop", choices=("off", "auto", "report"), default="off",
                    help="check the model written in the flight's closed loop, as heli diagnose does by default "
                    "('auto'; default off: the diagnosis alone)")
    ap.add_argument("--set", type=config_field, nargs="*", default=[], metavar="FIELD=VALUE",
                    help="FlightConfig fields changed in every flight, e.g. gyro_filter_hz=20.0 log_every=4")
    ap.add_argument("--fit-rate", choices=("log", "auto"), default="log",
                    help="the rate each flight is diagnosed at: its log's (default: the figures in docs/diagnosis.md "
                    "were measured so; no white log was ever thinned) or chosen as heli diagnose chooses it ('auto')")
    ap.add_argument("--json", default=None, metavar="PATH", help="also write every flight's row (found effects, "
                    "round-1 statistics, closed-loop shares) to PATH")
    args = ap.parse_args(argv)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    if args.null_cells:
        from identification.bench.cells import BENCH_CELLS

        cells = args.cells or list(BENCH_CELLS)
        unknown = [c for c in cells if c not in BENCH_CELLS]
        if unknown:
            raise SystemExit(f"unknown cells {unknown}; known: {', '.join(BENCH_CELLS)}")
        rows = _run([("none", s, args.duration, c, "off", tuple(args.set), args.fit_rate) for s in seeds
                     for c in cells], args)
        print(f"\nCommand: python scripts/likelihood_diagnosis_study.py --null-cells --seeds {args.seeds} "
              f"--duration {args.duration:g}" + (f" --first-seed {args.first_seed}" if args.first_seed != 1 else "")
              + (f" --cells {' '.join(args.cells)}" if args.cells else ""))
        _null_table(rows, cells)
        return
    rows = _run([(c, s, args.duration, args.cell, args.closed_loop, tuple(args.set), args.fit_rate)
                 for c in args.cases for s in seeds], args)
    print(f"\nLikelihood diagnosis, {args.seeds} seeds per case, {args.duration:g} s flights"
          + (f", bench cell {args.cell}" if args.cell else ", default heli simulate-flight pilot")
          + f". Command: python scripts/likelihood_diagnosis_study.py --seeds {args.seeds} --duration "
          f"{args.duration:g}" + (f" --cell {args.cell}" if args.cell else "")
          + (f" --first-seed {args.first_seed}" if args.first_seed != 1 else "")
          + (f" --cases {' '.join(args.cases)}" if list(args.cases) != list(CASES) else "")
          + (f" --closed-loop {args.closed_loop}" if args.closed_loop != "off" else "")
          + (" --set " + " ".join(f"{k}={v!r}" for k, v in args.set) if args.set else "")
          + (f" --fit-rate {args.fit_rate}" if args.fit_rate != "log" else ""))
    checked = args.closed_loop != "off"
    print("\n| case | named (all true axes) | partly | wrong effect | median s | dampings' RMS error k3 / k7 / k11 "
          "[worst]" + (" as fitted → after the check | check's median s" if checked else "")
          + " | what was named, most often |")
    print("|---|---|---|---|---|---|---|" + ("---|" if checked else ""))
    for c in args.cases:
        rs = [r for r in rows if r["case"] == c]
        n = len(rs)
        common = {}
        for r in rs:
            key = "; ".join(f"{e} ({', '.join(a)})" for e, a in sorted(r["found"].items())) or "none"
            common[key] = common.get(key, 0) + 1
        top = sorted(common.items(), key=lambda kv: -kv[1])[:2]
        print(f"| {c} | {sum(r['named'] for r in rs)}/{n} | {sum(r['partly'] for r in rs)}/{n} "
              f"| {sum(r['wrong'] for r in rs)}/{n} | {np.median([r['seconds'] for r in rs]):.1f} | "
              + (f"{_dampings(rs, 'damping_error_fitted')} → {_dampings(rs)} | "
                 f"{np.median([r['check_seconds'] for r in rs]):.1f}" if checked else _dampings(rs))
              + " | " + "; ".join(f"{k} ×{v}" for k, v in top) + " |")


if __name__ == "__main__":
    main()
