"""Does ``heli identify``'s default find a servo delay (and lag) where there is one, and leave the fit alone where there is none?

Per bench cell, size of the catalogue's servo dynamics (``--effects``: the delay 80 / 80 / 50 ms roll / pitch /
yaw, the first-order lag 40 / 40 / 30 ms; times ``--scales``, 0: none), aircraft
(:data:`identification.bench.aircraft.AIRCRAFT`, or the paper's) and seed, a 300 s flight is identified by maximum
likelihood twice on one core: without servo dynamics (``delay=None``, the default before) and with
``delay="detect", servo_lag="detect"`` (``heli identify``'s default now). Prints per row the RMS [worst]
relative error of the dampings (k3, k7, k11) both ways, how many axes with a true delay got one within 5 ms
(and how many without one got any), how many axes with a true lag kept one (and how many without one did),
whether the detect fit equals the undelayed one bit for bit on effect-free flights, and the median fit times.

Usage::

    python scripts/delay_detection.py [--seeds 3] [--cells independent ...] [--scales 0 0.125 1] [--workers 2]
        [--aircraft paper agile ...] [--effects servo_delay servo_lag]
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np

from identification.bench.aircraft import AIRCRAFT, aircraft_truth

DAMPINGS = ("k3", "k7", "k11")
AXES = ("roll", "pitch", "yaw")
DEFAULT_CELLS = ("independent", "held-sticks-pd", "broadband-autopilot", "dryden-2Hz-pd", "default",
                 "broadband-pd-noisy-gyro")


def _one(job):
    from threadpoolctl import threadpool_limits

    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier

    cell, scale, aircraft, seed, duration, effects = job
    with threadpool_limits(limits=1, user_api="blas"):
        config = replace(BENCH_CELLS[cell], duration=duration)
        sim = simulate_flight(duration, seed=seed, config=config, truth=aircraft_truth(aircraft),
                              effects=tuple(effects) if scale else (), effect_scale=scale or 1.0)
        truth = sim.truth
        fits, seconds = {}, {}
        for name, setting in (("none", None), ("detect", "detect")):
            t0 = time.perf_counter()
            fits[name] = MaximumLikelihoodIdentifier(delay=setting, servo_lag=setting, workers=1).fit(sim.flight)
            seconds[name] = time.perf_counter() - t0
    t = truth.values()
    out = {"cell": cell, "scale": scale, "aircraft": aircraft, "seed": seed, "seconds": seconds,
           "true_delay": list(truth.taus), "true_lag": list(truth.lags)}
    for name, ml in fits.items():
        v = ml.params_.values()
        out[name] = {"damping": [100.0 * (v[d] - t[d]) / t[d] for d in DAMPINGS],
                     "delay": [ml.axes_[a].delay for a in AXES], "lag": [ml.axes_[a].lag for a in AXES]}
    out["same"] = fits["none"].params_.values() == fits["detect"].params_.values()
    return out


def _table(rows) -> None:
    keys = sorted({(r["aircraft"], r["cell"], r["scale"]) for r in rows}, key=str)
    print("\n| aircraft | cell | servo delay / lag (ms) | dampings, no delay: RMS % [worst] | dampings, detect | "
          "delays found within 5 ms | delays found where none | lags kept | lags kept where none | "
          "detect = no delay, bit for bit | time none / detect (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for key in keys:
        rs = [r for r in rows if (r["aircraft"], r["cell"], r["scale"]) == key]
        cells = []
        for name in ("none", "detect"):
            e = np.array([r[name]["damping"] for r in rs])
            cells.append(f"{np.sqrt(np.mean(e ** 2)):.1f} [{np.abs(e).max():.1f}]")
            if name == "detect":
                worst = max(worst, float(np.sqrt(np.mean(e ** 2, axis=0)).max()))
        true = np.array([r["true_delay"] for r in rs])
        found = np.array([r["detect"]["delay"] for r in rs])
        has = true > 0
        hit = f"{int(np.sum(np.abs(found - true)[has] <= 0.005))}/{int(has.sum())}" if has.any() else "-"
        false = f"{int(np.sum((found != 0)[~has]))}/{int((~has).sum())}" if (~has).any() else "-"
        lag, kept = np.array([r["true_lag"] for r in rs]) > 0, np.array([r["detect"]["lag"] for r in rs]) > 0
        lags = f"{int(kept[lag].sum())}/{int(lag.sum())}" if lag.any() else "-"
        false_lags = f"{int(kept[~lag].sum())}/{int((~lag).sum())}"
        same = f"{sum(r['same'] for r in rs)}/{len(rs)}" if not has.any() and not lag.any() else "-"
        ms = "/".join(f"{1e3 * v:.0f}" for v in true[0]) + " / " + "/".join(f"{1e3 * v:.0f}" for v in rs[0]["true_lag"])
        times = (f"{np.median([r['seconds']['none'] for r in rs]):.2f} / "
                 f"{np.median([r['seconds']['detect'] for r in rs]):.2f}")
        print(f"| {key[0]} | {key[1]} | {ms} | {cells[0]} | {cells[1]} | {hit} | {false} | {lags} | {false_lags} | "
              f"{same} | {times} |")
    print(f"\nWorst damping RMS with detect (any row): {worst:.1f} %")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cells", nargs="+", default=list(DEFAULT_CELLS))
    ap.add_argument("--scales", nargs="+", type=float, default=[0.0, 0.125, 0.25, 1.0],
                   help="the servo dynamics as a multiple of the catalogue's (delay 80/80/50 ms, lag 40/40/30 ms; "
                   "0: none)")
    ap.add_argument("--aircraft", nargs="+", default=["paper"])
    ap.add_argument("--effects", nargs="+", default=["servo_delay"], choices=["servo_delay", "servo_lag"],
                    help="the servo dynamics hidden at each scale (default: the delay)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    from identification.bench.cells import BENCH_CELLS

    unknown = [c for c in args.cells if c not in BENCH_CELLS]
    if unknown:
        raise SystemExit(f"unknown cells {unknown}; known: {', '.join(BENCH_CELLS)}")
    known = ["paper", *AIRCRAFT]
    if any(a not in known for a in args.aircraft):
        raise SystemExit(f"unknown aircraft {[a for a in args.aircraft if a not in known]}; known: {', '.join(known)}")
    jobs = [(c, s, a, seed, args.duration, tuple(args.effects)) for a in args.aircraft for c in args.cells for s in args.scales
            for seed in range(args.first_seed, args.first_seed + args.seeds)]
    from tqdm import tqdm

    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight"))
    print(f"\nServo delay: the default fit with and without the test, {args.seeds} seeds x {args.duration:g} s, one core "
          f"each. Command: python scripts/delay_detection.py --seeds {args.seeds} --cells {' '.join(args.cells)} "
          f"--scales {' '.join(f'{s:g}' for s in args.scales)} --aircraft {' '.join(args.aircraft)} "
          f"--effects {' '.join(args.effects)}")
    _table(rows)


if __name__ == "__main__":
    main()
