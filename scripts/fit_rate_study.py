"""Does the fit rate's choice (``identification.fit_rate``) thin the logs it should, and only those?

Per (aircraft, bench cell, log rate, gyro filter, world steps per logged sample, seed) a 300 s flight is flown and
``choose_fit_rate`` decides its fit rate as ``heli identify`` does by default. Printed per condition: on how many
flights the log was thinned and to what rate, and the largest ratio of the damping fitted at the log's rate over
the one at half of it. A white gyro (``--filters 0``) should never be thinned; a gyro low-passed well below the
log's Nyquist rate should be. ``heli identify``'s errors at the chosen rate are ``aircraft_generalisation.py
--set gyro_filter_hz=F``'s.

    python scripts/fit_rate_study.py [--aircraft paper sluggish ...] [--cells independent ...] [--rates 50 100]
        [--filters 0 20 40] [--log-every 1 4] [--seeds 2] [--first-seed 1701] [--duration 300] [--workers 2]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _one(job):
    from threadpoolctl import threadpool_limits

    from identification.bench.aircraft import aircraft_truth
    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.fit_rate import choose_fit_rate

    aircraft, cell, rate, gf, every, seed, duration = job
    warnings.simplefilter("ignore")
    with threadpool_limits(limits=1, user_api="blas"):
        world = float(rate) * every
        if gf and gf >= world / 2:
            return job, None
        config = replace(BENCH_CELLS[cell], duration=duration, sample_rate=float(rate), log_every=every,
                         gyro_filter_hz=float(gf))
        flight = simulate_flight(duration, seed=seed, config=config, truth=aircraft_truth(aircraft)).flight
        t0 = time.perf_counter()
        chosen = choose_fit_rate([flight])
        top = max((max(r.values(), default=0.0) for _, r in chosen.steps[:1]), default=float("nan"))
        return job, (chosen.every, top, time.perf_counter() - t0)


def main(argv=None) -> None:
    from identification.bench.cells import BENCH_CELLS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--aircraft", nargs="+", default=["paper", "sluggish", "agile"])
    ap.add_argument("--cells", nargs="+", default=list(BENCH_CELLS))
    ap.add_argument("--rates", nargs="+", type=float, default=[100.0])
    ap.add_argument("--filters", nargs="+", type=float, default=[0.0], help="gyro filter corners [Hz], 0: none")
    ap.add_argument("--log-every", nargs="+", type=int, default=[1], help="world steps per logged sample")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--first-seed", type=int, default=1701)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    from tqdm import tqdm

    jobs = [(a, c, r, f, e, s, args.duration) for a in args.aircraft for c in args.cells for r in args.rates
            for f in args.filters for e in args.log_every for s in range(args.first_seed, args.first_seed + args.seeds)]
    with ProcessPoolExecutor(args.workers) as pool:
        results = [r for r in tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight")
                   if r[1] is not None]
    print(f"\nCommand: python scripts/fit_rate_study.py --aircraft {' '.join(args.aircraft)} --cells "
          f"{' '.join(args.cells)} --rates {' '.join(f'{r:g}' for r in args.rates)} --filters "
          f"{' '.join(f'{f:g}' for f in args.filters)} --log-every {' '.join(map(str, args.log_every))} --seeds "
          f"{args.seeds} --first-seed {args.first_seed} --duration {args.duration:g}\n")
    print("| gyro filter | log rate | world ÷ log | flights | thinned | fitted at | largest damping ratio (log ÷ half) |"
          " choice time, median |")
    print("|---|---|---|---|---|---|---|---|")
    import numpy as np

    for f in args.filters:
        for r in args.rates:
            for e in args.log_every:
                rows = [v for (a, c, rr, ff, ee, s, d), v in results if (rr, ff, ee) == (r, f, e)]
                if not rows:
                    continue
                thinned = [v for v in rows if v[0] > 1]
                rates = sorted({r / v[0] for v in rows}, reverse=True)
                print(f"| {'none' if not f else f'{f:g} Hz'} | {r:g} Hz | {e} | {len(rows)} | {len(thinned)} | "
                      + ", ".join(f"{hz:g} Hz" for hz in rates)
                      + f" | {np.nanmax([v[1] for v in rows]):.2f} | {np.median([v[2] for v in rows]):.1f} s |")
    white = [(job, v) for job, v in results if not job[3]]
    wrong = [job for job, v in white if v[0] > 1]
    if white:
        print(f"\nWhite gyros thinned: {len(wrong)} of {len(white)}" + (f" ({wrong[:4]})" if wrong else "")
              + f"; their largest ratio {np.nanmax([v[1] for _, v in white]):.2f} (the threshold 1.15 and 3 standard "
              "errors)")


if __name__ == "__main__":
    main()
