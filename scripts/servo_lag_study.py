"""Does the likelihood find a servo lag where there is one, and only there?

For every case (no servo dynamics, a transport delay only, a first-order lag only, both) and bench
cell (:data:`identification.bench.cells.BENCH_CELLS`), flies ``--seeds`` flights and identifies each with
``MaximumLikelihoodIdentifier(delay="auto", servo_lag="auto")`` (what ``heli identify --delay auto
--servo-lag auto`` runs). Prints per case and cell: on how many axes a lag was kept, the lags and delays
found (median over seeds and axes, truth beside), the likelihood-ratio statistic of the best lag
(median, largest), and the damping's error (RMS over seeds and axes).

Usage::

    python scripts/servo_lag_study.py [--seeds 5] [--duration 180] [--workers 2] [--cells A B ...]
"""

from __future__ import annotations

import argparse
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np

CASES = {
    "none": {},
    "delay 40/40/30 ms": {"tau_roll": 0.04, "tau_pitch": 0.04, "tau_yaw": 0.03},
    "lag 40/40/30 ms": {"lag_roll": 0.04, "lag_pitch": 0.04, "lag_yaw": 0.03},
    "delay 30 + lag 40/40/30 ms": {"tau_roll": 0.03, "tau_pitch": 0.03, "tau_yaw": 0.03,
                                   "lag_roll": 0.04, "lag_pitch": 0.04, "lag_yaw": 0.03},
}
DAMPINGS = ("k3", "k7", "k11")


def _one(job):
    from threadpoolctl import threadpool_limits

    from identification.bench.cells import BENCH_CELLS
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier
    from identification.bench.flight_config import PAPER_PARAMS
    from identification.bench.synthetic import simulate_flight

    case, cell, seed, duration = job
    truth = PAPER_PARAMS.with_values(**CASES[case])
    cfg = BENCH_CELLS[cell]
    with threadpool_limits(limits=1, user_api="blas"):
        sim = simulate_flight(duration, seed=seed, config=cfg, truth=truth)
        hold = "zoh" if cfg.pilot == "autopilot" else "linear"
        ident = MaximumLikelihoodIdentifier(delay="auto", servo_lag="auto", input_hold=hold).fit(sim.flight)
    fits = list(ident.axes_.values())
    return {"case": case, "cell": cell, "lag": [f.lag for f in fits], "delay": [f.delay for f in fits],
            "lr": [f.lag_lr for f in fits],
            "damping_err": [100 * (f.params[d] / truth.get(d) - 1) for f, d in zip(fits, DAMPINGS)]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=180.0)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--cells", nargs="+", default=["independent", "broadband-autopilot", "broadband-pd-noisy-gyro",
                                                     "default"])
    args = ap.parse_args(argv)
    from tqdm import tqdm

    jobs = [(c, cell, s, args.duration) for c in CASES for cell in args.cells for s in range(1, args.seeds + 1)]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight"))
    print(f"\nCommand: python scripts/servo_lag_study.py --seeds {args.seeds} --duration {args.duration:g} "
          f"--cells {' '.join(args.cells)}\n")
    print("| case | cell | axes with a lag kept | lag found, ms (median) | delay found, ms (median) "
          "| LR of the best lag: median (largest) | damping error % RMS (worst) |")
    print("|---|---|---|---|---|---|---|")
    for case in CASES:
        for cell in args.cells:
            rs = [r for r in rows if r["case"] == case and r["cell"] == cell]
            lag = np.array([v for r in rs for v in r["lag"]])
            delay = np.array([v for r in rs for v in r["delay"]])
            lr = np.array([v for r in rs for v in r["lr"]], dtype=float)
            err = np.array([v for r in rs for v in r["damping_err"]])
            print(f"| {case} | {cell} | {int(np.sum(lag > 0))}/{lag.size} | {1e3 * np.median(lag):.0f} "
                  f"| {1e3 * np.median(delay):.0f} | {np.median(lr):.1f} ({np.max(lr):.1f}) "
                  f"| {np.sqrt(np.mean(err ** 2)):.1f} ({np.max(np.abs(err)):.1f}) |")


if __name__ == "__main__":
    main()
