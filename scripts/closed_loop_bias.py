"""The dampings' bias in a closed loop whose pilot sees more than the gyro: mean error over seeds, per setting.

Flies one bench cell (default ``independent``: a PD pilot who sees the aircraft itself) on an aircraft of
``scripts/aircraft_generalisation.py`` with the gyro noise, wind and other :class:`FlightConfig` fields given,
no vibration lines (they are not the cause, and their removal is not measured here), and fits each flight by
maximum likelihood at a fixed input hold (the truth's by default: 1 for a pilot's hand, 0 for an autopilot's
held commands), so that the hold's own choice does not enter. Prints the mean relative error of the dampings
k3 / k7 / k11 with its standard error over the seeds, and their RMS (docs/method.md, "Where it does not hold").

Usage::

    python scripts/closed_loop_bias.py --aircraft sluggish --gyro 0.03 [--no-wind] [--cell independent]
        [--hold 1] [--seeds 12] [--first-seed 301] [--set pilot_bandwidth=0.7 ...] [--workers 2]
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))  # the study's aircraft are aircraft_generalisation's
from aircraft_generalisation import config_field  # noqa: E402
from identification.bench.aircraft import AIRCRAFT, aircraft_truth  # noqa: E402

DAMPINGS = ("k3", "k7", "k11")
GAINS = ("k2", "k6", "k10")
PARAMS = DAMPINGS + GAINS
NO_WIND = (1e-4, 1e-4, 1e-4)
"""A wind too weak to matter (the bench's flights need a positive level)."""


def _one(job) -> list:
    """Relative errors [%] of the dampings of one flight."""
    from threadpoolctl import threadpool_limits

    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier

    aircraft, cell, fields, hold, duration, seed, check = job
    with threadpool_limits(limits=1, user_api="blas"):
        config = replace(BENCH_CELLS[cell], duration=duration, **fields)
        sim = simulate_flight(duration, seed=seed, config=config, truth=aircraft_truth(aircraft))
        truth = sim.truth.values()
        ml = MaximumLikelihoodIdentifier(input_hold=hold, workers=1).fit(sim.flight)
        fitted = ml.params_.values()
        errors = [100.0 * (fitted[k] - truth[k]) / truth[k] for k in PARAMS]
        if check:
            from identification.likelihood.closed_loop import check_closed_loop

            found = check_closed_loop(ml, workers=1)
            corrected = dict(fitted)
            for axis in found.axes.values():
                corrected.update(axis.corrected)
            errors += [100.0 * (corrected[k] - truth[k]) / truth[k] for k in PARAMS]
    return errors


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--aircraft", default="paper", choices=["paper", *AIRCRAFT])
    ap.add_argument("--cell", default="independent")
    ap.add_argument("--gyro", type=float, default=0.03, help="gyro noise [rad/s] (default 0.03)")
    ap.add_argument("--no-wind", action="store_true", help="fly without gusts")
    ap.add_argument("--hold", type=float, default=None, help="input hold fitted at (default: the truth's)")
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--first-seed", type=int, default=301)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--set", type=config_field, nargs="*", default=[], metavar="FIELD=VALUE",
                    help="other FlightConfig fields, e.g. pilot_bandwidth=0.7 sample_rate=400.0")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--check", action="store_true",
                    help="also run the closed-loop check (identification.likelihood.closed_loop) and print the "
                         "errors after it")
    args = ap.parse_args(argv)
    from identification.bench.cells import BENCH_CELLS

    if args.seeds < 2:
        ap.error(f"--seeds must be at least 2 (a mean and its standard error), got {args.seeds}")
    if args.cell not in BENCH_CELLS:
        ap.error(f"--cell must be a bench cell ({', '.join(BENCH_CELLS)}), got {args.cell!r}")
    base = BENCH_CELLS[args.cell]
    fields = {"gyro_noise": args.gyro, "vibration_lines": (), "vibration": 0.0, **dict(args.set)}
    if args.no_wind:
        fields["wind_level"] = NO_WIND
    hold = args.hold if args.hold is not None else (0.0 if base.pilot == "autopilot" or base.held_sticks else 1.0)
    jobs = [(args.aircraft, args.cell, fields, hold, args.duration, s, args.check)
            for s in range(args.first_seed, args.first_seed + args.seeds)]
    if args.workers == 1:  # in this process
        errors = np.array([_one(job) for job in jobs])
    else:
        with ProcessPoolExecutor(args.workers) as pool:
            errors = np.array(list(pool.map(_one, jobs)))
    print(f"{args.aircraft}, cell {args.cell}, gyro {args.gyro:g} rad/s, {'no wind' if args.no_wind else 'wind'}, "
          f"hold {hold:g}, {dict(args.set) or 'no other change'}; {len(errors)} flights of {args.duration:g} s")
    _print(errors[:, :len(PARAMS)], "as fitted")
    if args.check:
        _print(errors[:, len(PARAMS):], "after the closed-loop check")
    return 0


def _print(errors: np.ndarray, title: str) -> None:
    """Mean error, its standard error and the RMS of each parameter over the flights."""
    mean, se = errors.mean(axis=0), errors.std(axis=0, ddof=1) / np.sqrt(len(errors))
    rms = np.sqrt((errors ** 2).mean(axis=0))
    print(f"{title}:")
    for k, m, e, r in zip(PARAMS, mean, se, rms):
        print(f"- {k}: mean error {m:+.1f} % (standard error {e:.1f}), RMS {r:.1f} %")


if __name__ == "__main__":
    raise SystemExit(main())
