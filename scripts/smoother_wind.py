"""How well the maximum-likelihood smoother's wind matches the true wind, raw and as the aircraft feels it.

For every bench cell (:data:`identification.bench.cells.BENCH_CELLS`) and seed, flies a flight, fits
:class:`identification.likelihood.estimator.MaximumLikelihoodIdentifier` and correlates its
Rauch-Tung-Striebel wind torque (:meth:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier.wind_torque`)
with the true one, per axis:

* **raw**: sample by sample;
* **as felt**: both passed through the axis' own rate response ``1 / (s + k)`` (``k`` the true
  damping k3, k7, k11, eqs. 18, 21). A gust much faster than the aircraft's bandwidth moves
  the rates by little, so no estimator can see its detail in the gyro; what the environment
  needs from a replayed trace is the rate it causes, which is what this column scores.

Usage::

    python scripts/smoother_wind.py [--seeds 5] [--duration 300] [--workers 2] [--cells A B ...]
"""

from __future__ import annotations

import argparse
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy import signal

DAMPINGS = ("k3", "k7", "k11")


def as_felt(torque: np.ndarray, damping: float, fs: float) -> np.ndarray:
    """``torque`` through the first-order rate response ``1 / (s + damping)`` (bilinear, at ``fs``)."""
    b, a = signal.bilinear([1.0], [1.0, damping], fs)
    return signal.lfilter(b, a, torque)


def _one(job):
    from threadpoolctl import threadpool_limits

    from identification.bench.cells import bench_flight
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier

    cell, seed, duration = job
    with threadpool_limits(limits=1, user_api="blas"):
        sim = bench_flight(cell, seed, duration)
        hold = "zoh" if sim.config.pilot == "autopilot" else "linear"
        wind = MaximumLikelihoodIdentifier(input_hold=hold).fit(sim.flight).wind_torque(0)
    fs = sim.flight.sample_rate
    raw, felt = [], []
    for i, k in enumerate(DAMPINGS):
        true = sim.wind_torque[i]
        raw.append(float(np.corrcoef(wind[i], true)[0, 1]))
        d = sim.truth.get(k)
        felt.append(float(np.corrcoef(as_felt(wind[i], d, fs), as_felt(true, d, fs))[0, 1]))
    return {"cell": cell, "seed": seed, "raw": raw, "felt": felt}


def main(argv=None):
    from identification.bench.cells import BENCH_CELLS

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--cells", nargs="+", default=list(BENCH_CELLS), choices=list(BENCH_CELLS), metavar="CELL")
    args = ap.parse_args(argv)
    from tqdm import tqdm

    jobs = [(c, s, args.duration) for c in args.cells for s in range(1, args.seeds + 1)]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight"))
    print(f"\nSmoother wind vs true wind, correlation over {args.seeds} seeds of {args.duration:g} s: mean (worst "
          f"flight-axis). Command: python scripts/smoother_wind.py --seeds {args.seeds} --duration {args.duration:g}")
    print("\n| cell | raw | as felt by the aircraft (through 1/(s + k)) |")
    print("|---|---|---|")
    for c in args.cells + ["all"]:
        rs = [r for r in rows if c == "all" or r["cell"] == c]
        raw, felt = np.array([r["raw"] for r in rs]), np.array([r["felt"] for r in rs])
        print(f"| {c} | {raw.mean():.3f} ({raw.min():.3f}) | {felt.mean():.3f} ({felt.min():.3f}) |")


if __name__ == "__main__":
    main()
