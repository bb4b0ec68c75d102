"""Does the model verdict judge good models usable, and wrong ones not?

Per (bench cell, aircraft, seed, true servo delay) a 300 s flight is flown and identified as ``heli identify`` does
by default (its fit rate, timing and closed-loop check); the verdict is judged beside the integral method on the
same flight (:func:`identification.validation.model_verdict.judge_identifier`). Printed per flight: the level, the
fitted dampings against the truth's, and the reasons. With ``--wrong F`` the fitted dampings are multiplied by
``F`` before the verdict (and before the closed-loop check that the verdict reads), a model that is wrong by that
factor on every axis: the verdict should not call it usable.

    python scripts/verdict_survey.py [--cells independent held-sticks-pd broadband-autopilot]
        [--aircraft paper sluggish agile] [--seeds 2] [--first-seed 2101] [--delays 0 0.01 0.02] [--wrong F]
        [--workers 2]
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _one(job) -> dict:
    from threadpoolctl import threadpool_limits

    from heli_core.terms import AXES
    from identification.bench.aircraft import aircraft_truth
    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.fit_rate import at_fit_rate
    from identification.integral.method import IntegralIdentifier
    from identification.likelihood.closed_loop import set_axis_values
    from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier
    from identification.validation.model_verdict import DAMPING, GAIN, judge_identifier

    cell, aircraft, seed, delay, wrong = job
    warnings.simplefilter("ignore")
    with threadpool_limits(limits=1, user_api="blas"):
        truth = replace(aircraft_truth(aircraft), tau_roll=delay, tau_pitch=delay, tau_yaw=delay)
        sim = simulate_flight(300.0, seed=seed, config=replace(BENCH_CELLS[cell], duration=300.0), truth=truth)
        (flight,), _ = at_fit_rate([sim.flight], "auto")
        ml = MaximumLikelihoodIdentifier(**CLI_TIMING, closed_loop=None if wrong else "auto", workers=1).fit(flight)
        if wrong:  # every damping off by the factor, the rest as fitted; the check flown on that model
            for axis in AXES:
                params, gain, damping = ml.axes_[axis].params, GAIN[axis], DAMPING[axis]
                set_axis_values(ml, axis, {gain: params[gain], damping: wrong * params[damping]})
            ml.closed_loop_check("report")
        verdict = judge_identifier(ml, IntegralIdentifier(structure="decoupled").fit(flight))
    return {"job": job, "level": verdict.level, "reasons": list(verdict.reasons),
            "dampings": {DAMPING[a]: (ml.params_.values()[DAMPING[a]], truth.values()[DAMPING[a]]) for a in AXES}}


def main(argv=None) -> None:
    from heli_cli.argtypes import number, whole
    from identification.bench.aircraft import AIRCRAFT
    from identification.bench.cells import BENCH_CELLS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", nargs="+", default=["independent", "held-sticks-pd", "broadband-autopilot"],
                    choices=list(BENCH_CELLS), metavar="CELL")
    ap.add_argument("--aircraft", nargs="+", default=["paper", "sluggish", "agile"], choices=["paper", *AIRCRAFT])
    ap.add_argument("--seeds", type=whole(1), default=2)
    ap.add_argument("--first-seed", type=int, default=2101)
    ap.add_argument("--delays", nargs="+", type=number("a servo delay in seconds, 0 or more", 0.0, low_open=False),
                    default=[0.0, 0.01, 0.02], help="true servo delays [s]")
    ap.add_argument("--wrong", type=number("a factor above 0", 0.0), default=None,
                    help="multiply every fitted damping by this factor")
    ap.add_argument("--workers", type=whole(1),
                    default=min(2, os.cpu_count() or 1))
    args = ap.parse_args(argv)
    jobs = [(c, a, s, d, args.wrong) for c in args.cells for a in args.aircraft
            for s in range(args.first_seed, args.first_seed + args.seeds) for d in args.delays]
    print("Command: python scripts/verdict_survey.py " + " ".join(sys.argv[1:] if argv is None else argv))
    print("\n| cell | aircraft | seed | servo delay | verdict | k3 / k7 / k11 fitted (truth) | reasons |")
    print("|---|---|---|---|---|---|---|")
    counts = {}
    with ProcessPoolExecutor(args.workers) as pool:
        for r in pool.map(_one, jobs):
            cell, aircraft, seed, delay, _ = r["job"]
            counts[r["level"]] = counts.get(r["level"], 0) + 1
            damp = " / ".join(f"{v:.3g} ({t:.3g})" for v, t in r["dampings"].values())
            print(f"| {cell} | {aircraft} | {seed} | {1e3 * delay:g} ms | {r['level']} | {damp} | "
                  f"{'; '.join(r['reasons']) or '—'} |", flush=True)
    print("\n" + ", ".join(f"{n} {level}" for level, n in sorted(counts.items())) + f" of {len(jobs)} flights"
          + (f" (every damping x{args.wrong:g})" if args.wrong else ""))


if __name__ == "__main__":
    main()
