"""Reproduce the paper's method comparison (Tables 3-5) on a synthetic or recorded flight.

Without a flight argument, flies a 300 s synthetic hover flight (seed 1, the
paper's wind level) into a temporary folder, then runs the full comparison of
:func:`identification.method_comparison.compare_methods`: the integral method
(median of 20 timed runs), nonlinear regression from Table 3's three start
points (one run each; each costs tens of forward simulations of 300 s), and the
EKF in Table 4's six cases and Table 5's three sample lengths (median of 3).
Prints the tables and the speed ratios measured in this run; ``--out DIR``
also writes ``comparison.json`` and ``comparison.md``.

BLAS is held to one thread for the whole run (environment variables set before
numpy loads), so CPU times add up one thread's work for every method.

Usage::

    python scripts/compare_methods.py [FLIGHT.csv] [--out DIR] [--duration 300] [--seed 1]
                                      [--axis roll] [--quick]
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("flight", nargs="?", help="canonical CSV flight (default: a synthetic flight)")
    parser.add_argument("--out", help="also write comparison.json and comparison.md here")
    parser.add_argument("--duration", type=float, default=300.0, help="synthetic flight length [s] (default 300)")
    parser.add_argument("--seed", type=int, default=1, help="synthetic flight seed (default 1)")
    parser.add_argument("--axis", default="roll", choices=("roll", "pitch", "yaw"))
    parser.add_argument("--quick", action="store_true", help="cap NLR evaluations and repeats (fast look)")
    args = parser.parse_args(argv)

    from heli_cli.compare_methods import load_truth_if_any
    from identification.io import read_flight
    from identification.method_comparison import QUICK_NLR_MAX_NFEV, compare_methods
    from identification.synthetic import simulate_flight

    with tempfile.TemporaryDirectory(prefix="heli-compare-") as tmp:
        path = args.flight
        if path is None:
            t0 = time.perf_counter()
            path = Path(tmp) / f"synthetic-{args.duration:g}s-seed{args.seed}.csv"
            simulate_flight(args.duration, seed=args.seed).save(path)
            print(f"synthetic flight: {args.duration:g} s, seed {args.seed} ({time.perf_counter() - t0:.1f} s to fly)")
        flight = read_flight(path)
        truth = load_truth_if_any(path)
        kwargs = {}
        if args.quick:
            kwargs = {"nlr_max_nfev": QUICK_NLR_MAX_NFEV, "repeats": {"integral": 5, "ekf": 1}, "quick": True}
        t0 = time.perf_counter()
        result = compare_methods(flight, axis=args.axis, truth=truth, **kwargs)
        elapsed = time.perf_counter() - t0

    print(result.markdown())
    print(f"(whole comparison: {elapsed:.1f} s wall, BLAS threads: {os.environ['OPENBLAS_NUM_THREADS']} via "
          f"OPENBLAS_NUM_THREADS; threadpoolctl: {result.settings['blas_threads']})")
    if args.out:
        for p in result.save(args.out).values():
            print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
