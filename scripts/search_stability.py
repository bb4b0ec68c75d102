"""Does the likelihood search land on the same optimum when the arithmetic changes in its last digits?

An axis fit of :class:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier` is a search over the
damping, the gust model's time constants and levels and the input's hold. Its answer should not depend on the
rounding of the machine it runs on (which BLAS kernel, which Riccati solver). This study fits every flight twice
as ``heli identify`` fits it (the log's timing detected, the hold estimated; the closed-loop check off, its own
flights would add their own draws): once as it is, once with the steady-state Kalman gain multiplied by
``1 + perturbation`` (default 1e-13: a change of the innovations in their 13th digit, what another solver or BLAS
kernel makes). Per axis it prints the difference of the two fits' negative log-likelihoods (``dNLL``: the second
less the first; a converged search gives about 0) and of their dampings, over bench cells and seeds, and the
real T-REX hover of ``../shared`` when it is there.

Usage::

    python scripts/search_stability.py [--cells default independent ...] [--seeds 3] [--first-seed 1]
        [--duration 300] [--perturbation 1e-13] [--workers 2] [--no-trex]
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))  # the T-REX hover where real_heli.py finds it
from real_heli import DEFAULT_LOG as TREX  # noqa: E402


def _fit(flight, perturbation: float):
    """``flight`` fitted as ``heli identify`` fits it (no closed-loop check), the Kalman gain scaled by
    ``1 + perturbation``: ``{axis: (nll, damping, hold, gust model, delay)}`` or the refusal's text."""
    import identification.likelihood.axis_likelihood as axis_likelihood
    from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier

    exact = axis_likelihood.kalman

    def perturbed(Ad, Qd, R=1.0):
        P, L, S = exact(Ad, Qd, R)
        return P, L * (1.0 + perturbation), S

    axis_likelihood.kalman = perturbed
    try:
        ml = MaximumLikelihoodIdentifier(**CLI_TIMING, workers=1).fit(flight)
    except Exception as exc:  # a refusal is a finding of this study
        return f"{type(exc).__name__}: {exc}"[:120]
    finally:
        axis_likelihood.kalman = exact
    from identification.diagnosis.alignment_check import DAMPING

    return {axis: (float(fit.nll), float(fit.params.get(DAMPING[axis], np.nan)), float(fit.input_hold),
                   fit.wind["model"], float(fit.delay)) for axis, fit in ml.axes_.items()}


def _one(job):
    """Fit one flight twice (module docstring)."""
    from threadpoolctl import threadpool_limits

    cell, seed, duration, perturbation = job
    with threadpool_limits(limits=1, user_api="blas"):
        if cell == "trex":
            from identification.io import read_log

            flight = read_log(TREX)
        else:
            from identification.bench.cells import bench_flight

            flight = bench_flight(cell, seed, duration).flight
        t0 = time.perf_counter()
        first = _fit(flight, 0.0)
        second = _fit(flight, perturbation)
    return {"cell": cell, "seed": seed, "first": first, "second": second, "seconds": time.perf_counter() - t0}


def _rows(results) -> list:
    """Per flight and axis: (cell, seed, axis, dNLL, damping change [%], first hold, second hold, note)."""
    rows = []
    for r in results:
        first, second = r["first"], r["second"]
        if isinstance(first, str) or isinstance(second, str):
            same = isinstance(first, str) and isinstance(second, str)
            rows.append((r["cell"], r["seed"], "-", np.nan, np.nan, "-", "-",
                         ("both refused" if same else "one refused") + f": {first if isinstance(first, str) else second}"))
            continue
        for axis in first:
            a, b = first[axis], second[axis]
            note = "" if a[3] == b[3] else f"gust model {a[3]} / {b[3]}"
            if abs(a[4] - b[4]) > 1e-3:
                note += f" delay {a[4]:.3f} / {b[4]:.3f} s"
            rows.append((r["cell"], r["seed"], axis, b[0] - a[0], 100.0 * (b[1] / a[1] - 1.0), f"{a[2]:.2f}",
                         f"{b[2]:.2f}", note.strip()))
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cells", nargs="+", default=["default", "independent", "held-sticks-pd", "dryden-2Hz-pd",
                                                   "broadband-pd-noisy-gyro"])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--perturbation", type=float, default=1e-13)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--no-trex", action="store_true", help="leave out the real T-REX hover of ../shared")
    args = ap.parse_args(argv)
    from identification.bench.cells import BENCH_CELLS

    unknown = [c for c in args.cells if c not in BENCH_CELLS]
    if unknown:
        raise SystemExit(f"unknown cells {unknown}; known: {', '.join(BENCH_CELLS)}")
    jobs = [(c, s, args.duration, args.perturbation) for c in args.cells
            for s in range(args.first_seed, args.first_seed + args.seeds)]
    if not args.no_trex and TREX.exists():
        jobs.append(("trex", 0, 0.0, args.perturbation))
    from tqdm import tqdm

    with ProcessPoolExecutor(max(1, args.workers)) as pool:
        results = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight"))
    rows = _rows(results)
    print(f"\nEach flight fitted twice, the second with the Kalman gain x (1 + {args.perturbation:g}). Command: python "
          f"scripts/search_stability.py --cells {' '.join(args.cells)} --seeds {args.seeds} --first-seed "
          f"{args.first_seed} --duration {args.duration:g} --perturbation {args.perturbation:g}"
          + (" --no-trex" if args.no_trex else ""))
    print("| cell | seed | axis | dNLL | damping change % | hold | note |")
    print("|---|---|---|---|---|---|---|")
    for cell, seed, axis, dnll, dd, h1, h2, note in rows:
        print(f"| {cell} | {seed} | {axis} | {dnll:+.2f} | {dd:+.2f} | {h1} / {h2} | {note} |")
    d = np.array([r[3] for r in rows if np.isfinite(r[3])])
    dd = np.array([r[4] for r in rows if np.isfinite(r[4])])
    if d.size:
        print(f"\n{d.size} axis fits: |dNLL| median {np.median(np.abs(d)):.2f}, max {np.abs(d).max():.2f}; "
              f"> 1 on {np.mean(np.abs(d) > 1):.0%}; damping |change| median {np.median(np.abs(dd)):.2f} %, max "
              f"{np.abs(dd).max():.2f} %; {sum(1 for r in rows if r[7])} with another gust model, delay or refusal")


if __name__ == "__main__":
    main()
