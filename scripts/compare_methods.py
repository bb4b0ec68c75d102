"""Reproduce the paper's method comparison (Tables 3-5) on a synthetic or recorded flight.

Without a flight argument, flies a 300 s synthetic hover flight (seed 1, the
paper's wind level) into a temporary folder, then runs the full comparison of
:func:`identification.bench.method_comparison.compare_methods`: the integral method
(median of 20 timed runs), nonlinear regression from Table 3's three start
points (one run each; each costs tens of forward simulations of 300 s), and the
EKF in Table 4's six cases and Table 5's three sample lengths (median of 3).
Prints the tables and the speed ratios measured in this run; ``--out DIR``
also writes ``comparison.json`` and ``comparison.md``.

Held-out errors: every identified model is also scored on a validation flight
no method sees. ``--validate OTHER.csv`` names it; otherwise, for a synthetic
flight (its own or one with ``<stem>.truth.json`` beside it) the script flies a
second one with the same truth, settings and length and the seed + 1000
(:data:`VALIDATION_SEED_OFFSET`), and says so. A recorded flight without
``--validate`` gets in-sample errors only.

BLAS is held to one thread for the whole run (environment variables set before
numpy loads), so CPU times add up one thread's work for every method.

Usage::

    python scripts/compare_methods.py [FLIGHT.csv] [--validate OTHER.csv] [--out DIR] [--duration 300]
                                      [--seed 1] [--axis roll] [--quick]
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

VALIDATION_SEED_OFFSET = 1000
"""Seed of the synthetic validation flight: the identification flight's seed plus this."""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("flight", nargs="?", help="canonical CSV flight (default: a synthetic flight)")
    parser.add_argument("--validate", metavar="OTHER.csv",
                        help="validation flight for the held-out errors (default: for a synthetic flight, a second "
                        f"one with the same truth and seed + {VALIDATION_SEED_OFFSET})")
    parser.add_argument("--out", help="also write comparison.json and comparison.md here")
    parser.add_argument("--duration", type=float, default=300.0, help="synthetic flight length [s] (default 300)")
    parser.add_argument("--seed", type=int, default=1, help="synthetic flight seed (default 1)")
    parser.add_argument("--axis", default="roll", choices=("roll", "pitch", "yaw"))
    parser.add_argument("--quick", action="store_true", help="cap NLR evaluations and repeats (fast look)")
    args = parser.parse_args(argv)

    from heli_cli.compare_methods import load_truth_if_any
    from identification.io import read_flight
    from identification.bench.comparison_config import QUICK_NLR_MAX_NFEV
    from identification.bench.method_comparison import compare_methods
    from identification.reports.method_comparison import comparison_markdown
    from identification.workflows.method_comparison import write_comparison
    from identification.bench.synthetic import simulate_flight

    with tempfile.TemporaryDirectory(prefix="heli-compare-") as tmp:
        path = args.flight
        if path is None:
            t0 = time.perf_counter()
            path = Path(tmp) / f"synthetic-{args.duration:g}s-seed{args.seed}.csv"
            simulate_flight(args.duration, seed=args.seed).save(path)
            print(f"synthetic flight: {args.duration:g} s, seed {args.seed} ({time.perf_counter() - t0:.1f} s to fly)")
        flight = read_flight(path)
        truth = load_truth_if_any(path)
        validate = args.validate
        if validate is None and truth is not None:
            validate = fly_validation_twin(path, Path(tmp))
        elif validate is None:
            print("no validation flight (recorded flight, no --validate): in-sample errors only")
        validation = read_flight(validate) if validate is not None else None
        validation_truth = load_truth_if_any(validate) if validate is not None else None
        kwargs = {"validation": validation, "validation_truth": validation_truth}
        if args.quick:
            kwargs.update({"nlr_max_nfev": QUICK_NLR_MAX_NFEV, "repeats": {"integral": 5, "ekf": 1}, "quick": True})
        t0 = time.perf_counter()
        result = compare_methods(flight, axis=args.axis, truth=truth, **kwargs)
        elapsed = time.perf_counter() - t0

    print(comparison_markdown(result))
    print(f"(whole comparison: {elapsed:.1f} s wall, BLAS threads: {os.environ['OPENBLAS_NUM_THREADS']} via "
          f"OPENBLAS_NUM_THREADS; threadpoolctl: {result.settings['blas_threads']})")
    if args.out:
        for p in write_comparison(result, args.out).values():
            print(f"wrote {p}")
    return 0


def fly_validation_twin(flight_path, directory: Path) -> Path:
    """Fly the held-out twin of a synthetic flight: same truth, effects and settings, seed + 1000.

    Reads ``<stem>.truth.json`` beside ``flight_path``; writes the twin (and its
    truth) into ``directory`` and returns its path.
    """
    from identification.bench.flight_config import FlightConfig
    from identification.bench.synthetic import load_truth, simulate_flight, truth_paths

    saved = json.loads(truth_paths(flight_path)["truth"].read_text())
    config = FlightConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in saved["config"].items()})
    seed = int(saved["seed"]) + VALIDATION_SEED_OFFSET
    t0 = time.perf_counter()
    twin = simulate_flight(config=config, seed=seed, effects=tuple(saved.get("effects", ())),
                           truth=load_truth(flight_path)[0])
    path = directory / f"validation-{config.duration:g}s-seed{seed}.csv"
    twin.save(path)
    print(f"validation flight (held-out, seen by no method): synthetic, same truth and settings as "
          f"{Path(flight_path).name}, {config.duration:g} s, seed {seed} = {saved['seed']} + {VALIDATION_SEED_OFFSET} "
          f"({time.perf_counter() - t0:.1f} s to fly)")
    return path


if __name__ == "__main__":
    sys.exit(main())
