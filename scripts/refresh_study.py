"""How often ``heli refresh`` flags an unchanged aircraft, and how often it catches a 10 % change of a damping.

For each seed, two flights of the same aircraft (independent seeds, same conditions) are identified by
maximum likelihood, and the drift table of :func:`identification.validation.parameter_drift.drift_table` is built
exactly as ``heli refresh`` builds it (Fisher standard errors, offsets not compared, Bonferroni over the parameters
compared at family-wise ``alpha``). A false flag is any parameter flagged. For the power, the second
flight's aircraft has one damping (k3, k7 or k11, in turn) 10 % higher; a hit is that damping flagged.

Usage::

    python scripts/refresh_study.py [--seeds 20] [--duration 300] [--workers 2] [--cell NAME] [--change 0.10]
"""

from __future__ import annotations

import argparse
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np

DAMPINGS = ("k3", "k7", "k11")


def _fit(seed, duration, cell, truth):
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier
    from identification.bench.synthetic import simulate_flight

    config = None
    if cell is not None:
        from identification.bench.cells import BENCH_CELLS

        config = BENCH_CELLS[cell]
    sim = simulate_flight(duration, seed=seed, config=config, truth=truth)
    hold = "zoh" if getattr(sim.config, "pilot", "pid") == "autopilot" else "linear"
    return MaximumLikelihoodIdentifier(input_hold=hold).fit(sim.flight)


def _one(job):
    from threadpoolctl import threadpool_limits

    from identification.validation.parameter_drift import compared_parameters, critical_z, drift_table, fisher_result
    from identification.bench.flight_config import PAPER_PARAMS

    seed, duration, cell, change, alpha = job
    with threadpool_limits(limits=1, user_api="blas"):
        old = _fit(seed, duration, cell, None)
        names = compared_parameters(old, "ml")
        z = critical_z(alpha, len(names))
        boot_old = fisher_result(old, names)
        out = {"seed": seed}
        same = _fit(seed + 1000, duration, cell, None)
        rows = drift_table(old.params_.values(), fisher_result(same, names), dict(boot_old.std_errors), "Fisher",
                           None, z)
        out["false_flags"] = [r.name for r in rows if r.flagged]
        damping = DAMPINGS[seed % 3]
        changed = PAPER_PARAMS.with_values(**{damping: PAPER_PARAMS.get(damping) * (1.0 + change)})
        new = _fit(seed + 2000, duration, cell, changed)
        rows = drift_table(old.params_.values(), fisher_result(new, names), dict(boot_old.std_errors), "Fisher",
                           None, z)
        out["changed"] = damping
        out["hit"] = any(r.flagged for r in rows if r.name == damping)
        out["other_flags"] = [r.name for r in rows if r.flagged and r.name != damping]
        out["z"] = {r.name: r.z for r in rows}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--cell", default=None)
    ap.add_argument("--change", type=float, default=0.10)
    ap.add_argument("--alpha", type=float, default=0.05)
    args = ap.parse_args(argv)
    from tqdm import tqdm

    jobs = [(s, args.duration, args.cell, args.change, args.alpha) for s in range(1, args.seeds + 1)]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="refresh pairs", unit="pair"))
    n = len(rows)
    false = sum(bool(r["false_flags"]) for r in rows)
    print(f"\nRefresh by maximum likelihood, {n} seeds, {args.duration:g} s flights"
          + (f", bench cell {args.cell}" if args.cell else ", default heli simulate-flight")
          + f". Command: python scripts/refresh_study.py --seeds {args.seeds} --duration {args.duration:g}"
          + (f" --cell {args.cell}" if args.cell else ""))
    print("\n| measure | result |\n|---|---|")
    print(f"| unchanged aircraft: refreshes with any parameter flagged (family-wise alpha {args.alpha:g}) | "
          f"{false}/{n} ({100 * false / n:.0f} %) |")
    flagged = {}
    for r in rows:
        for k in r["false_flags"]:
            flagged[k] = flagged.get(k, 0) + 1
    print(f"| parameters flagged on the unchanged aircraft | {flagged or 'none'} |")
    for d in DAMPINGS:
        rs = [r for r in rows if r["changed"] == d]
        if rs:
            zs = [r["z"][d] for r in rs]
            print(f"| {d} +{100 * args.change:.0f} %: flagged | {sum(r['hit'] for r in rs)}/{len(rs)} "
                  f"(median z {np.median(zs):.1f}) |")
    hits = sum(r["hit"] for r in rows)
    print(f"| any damping +{100 * args.change:.0f} %: flagged | {hits}/{n} ({100 * hits / n:.0f} %) |")
    others = sum(bool(r["other_flags"]) for r in rows)
    print(f"| changed aircraft: another parameter flagged too | {others}/{n} |")


if __name__ == "__main__":
    main()
