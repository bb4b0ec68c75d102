"""Short airborne runs fitted together: how close do they come to one flight of the same total length?

``heli import --segment each`` writes each airborne run of a log as a flight of its own, and ``heli identify``
fits the runs together (one set of parameters and gust statistics, an offset per flight). Per bench cell and
seed this script flies one flight of ``--duration`` seconds and fits it as ``heli identify`` does by default
(:class:`MaximumLikelihoodIdentifier` with ``CLI_TIMING``, the closed-loop check on):

* ``whole``: the flight as flown;
* ``R x L s``: ``R`` runs of ``L`` seconds cut from it, a ``--gap`` of seconds dropped between neighbours (the
  aircraft on the ground: each run starts its filter afresh and has its own offset), fitted together.

Prints per cell and split the RMS [worst flight] relative error in % of the gains (k2, k6, k10) and the
dampings (k3, k7, k11) over the seeds, worst parameter first, and the split's total airborne time.

    python scripts/airborne_runs_study.py [--seeds 3] [--cells independent dryden-2Hz-pd held-sticks-pd]
        [--splits 5x50 10x20] [--gap 5] [--duration 300] [--workers 2]
"""

from __future__ import annotations

import argparse
import shlex
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from csv_clock_study import rms_line  # noqa: E402  (this script's folder is on the path)

GAINS = ("k2", "k6", "k10")
DAMPINGS = ("k3", "k7", "k11")


def _split(text: str) -> tuple[int, float]:
    """``"5x50"`` -> (5 runs, 50 s each)."""
    runs, length = text.lower().split("x")
    return int(runs), float(length)


def _runs(flight, runs: int, length: float, gap: float) -> list:
    """``runs`` runs of ``length`` s from the start of ``flight``, ``gap`` s dropped between neighbours."""
    t0 = float(flight.time[0])
    pieces = [flight.segment(t0 + k * (length + gap), t0 + k * (length + gap) + length) for k in range(runs)]
    if pieces[-1].time[-1] > flight.time[-1] - 1e-9 and pieces[-1].duration < length - 0.5:
        raise SystemExit(f"{runs} runs of {length:g} s with {gap:g} s gaps do not fit in {flight.duration:.0f} s")
    return pieces


def _one(job):
    """Fly one (cell, seed), fit the whole flight and each split; relative errors in %."""
    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier

    cell, seed, duration, splits, gap = job
    sim = simulate_flight(duration, seed=seed, config=replace(BENCH_CELLS[cell], duration=duration))
    truth = sim.truth.values()
    out = {"cell": cell, "seed": seed, "errors": {}}
    for name, flights in [("whole", sim.flight), *((f"{r} x {L:g} s", _runs(sim.flight, r, L, gap))
                                                   for r, L in splits)]:
        try:
            v = MaximumLikelihoodIdentifier(**CLI_TIMING, closed_loop="auto").fit(flights).params_.values()
        except Exception as exc:  # a refusal is a finding here
            out["errors"][name] = f"{type(exc).__name__}: {exc}"
            continue
        out[name] = {k: 100.0 * (v[k] - truth[k]) / truth[k] for k in GAINS + DAMPINGS}
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", nargs="+", default=["independent", "dryden-2Hz-pd", "held-sticks-pd"])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--splits", nargs="+", type=_split, default=[(5, 50.0), (10, 20.0)],
                    help="RxL: R runs of L seconds (default 5x50 10x20)")
    ap.add_argument("--gap", type=float, default=5.0, help="seconds dropped between neighbouring runs")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    from tqdm import tqdm

    jobs = [(c, s, args.duration, tuple(args.splits), args.gap)
            for c in args.cells for s in range(args.first_seed, args.first_seed + args.seeds)]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight"))
    names = ["whole", *(f"{r} x {L:g} s" for r, L in args.splits)]
    print(f"\n`python scripts/airborne_runs_study.py {shlex.join(sys.argv[1:] if argv is None else argv)}`\n")
    print("| cell | flights | airborne s | gains: RMS % (worst) [worst flight] | dampings: the same |")
    print("|---|---|---|---|---|")
    for cell in args.cells:
        got = [r for r in rows if r["cell"] == cell]
        for name, (r, L) in zip(names, [(1, args.duration), *args.splits]):
            print(f"| {cell} | {name} | {r * L:g} | {rms_line(got, name, GAINS)} | {rms_line(got, name, DAMPINGS)} |")
    for r in rows:
        for name, error in r["errors"].items():
            print(f"refused: {r['cell']} seed {r['seed']} {name}: {error}")


if __name__ == "__main__":
    main()
