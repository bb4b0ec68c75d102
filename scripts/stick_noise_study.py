"""Does ``heli identify``'s stick-noise test name the logs whose sticks moved between samples, and only those?

Per aircraft (:data:`identification.bench.aircraft.AIRCRAFT`, or the paper's), bench cell, log rate, ``--log-every``
(the world steps that many times per logged sample: 1 is a world at the log's rate, whose sticks the aircraft
felt as logged) and seed, a flight is identified by maximum likelihood as ``heli identify`` does (the closed-loop
check left out: the test fits its own models) and
:func:`identification.likelihood.stick_noise.check_stick_noise` run on it. Prints per row the median [largest]
likelihood gain of the neighbour-shrunk sticks per axis, how many flights name each axis, and the RMS [worst]
relative error of the gains and dampings the default fit returns: a row whose sticks moved between samples should
name the axes whose values are biased, a row at the log's rate should name none.

Usage::

    python scripts/stick_noise_study.py [--seeds 3] [--first-seed 1301] [--duration 300] [--workers 2]
        [--aircraft paper agile ...] [--cells independent ...] [--rates 100 ...] [--log-every 1 4]
        [--set FIELD=VALUE ...] [--interval-mean]

With ``--interval-mean`` each flight whose world is faster than its log is fitted once more on each stick's mean
over its sample (from the same world flown unsampled): the error left when the sticks are what the aircraft felt.
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))  # the study's aircraft and --set are aircraft_generalisation's
from aircraft_generalisation import config_field  # noqa: E402
from identification.bench.aircraft import AIRCRAFT, aircraft_truth  # noqa: E402

AXES = ("roll", "pitch", "yaw")
PARAMS = ("k2", "k3", "k6", "k7", "k10", "k11")
DEFAULT_CELLS = ("independent", "held-sticks-pd", "broadband-pd-noisy-gyro", "dryden-2Hz-pd", "broadband-pd-2x",
                 "broadband-autopilot", "default")


def _one(job):
    from threadpoolctl import threadpool_limits

    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier
    from identification.likelihood.stick_noise import check_stick_noise, refit_on_shrunk

    aircraft, cell, rate, every, seed, duration, settings, interval_mean = job
    out = {"row": (aircraft, cell, rate, every), "seed": seed}
    with threadpool_limits(limits=1, user_api="blas"):
        config = replace(BENCH_CELLS[cell], duration=duration, sample_rate=rate, log_every=every, **dict(settings))
        sim = simulate_flight(duration, seed=seed, config=config, truth=aircraft_truth(aircraft))
        truth = sim.truth.values()
        try:
            ml = MaximumLikelihoodIdentifier(**CLI_TIMING, workers=1).fit(sim.flight)
            t0 = time.perf_counter()
            check = check_stick_noise(ml)
        except Exception as exc:  # a refusal is a finding of this study, not its end
            out["error"] = f"{type(exc).__name__}: {exc}"
            return out
        out["check_s"] = time.perf_counter() - t0
    out["fit_s"] = ml.fit_time_
    values = ml.params_.values()
    out["error_pct"] = {k: 100.0 * (values[k] - truth[k]) / abs(truth[k]) for k in PARAMS}
    out["lr"], out["named"] = check.lr, check.axes
    shrunk = refit_on_shrunk(ml).params_.values()  # how far the shrunk sticks move the dampings too
    out["shrunk_pct"] = {k: 100.0 * (shrunk[k] - truth[k]) / abs(truth[k]) for k in PARAMS}
    if interval_mean and every > 1:
        out["interval_mean_pct"] = _interval_mean_errors(sim, config, aircraft, truth)
    return out


def _interval_mean_errors(sim, config, aircraft: str, truth: dict) -> dict:
    """The default fit's relative errors [%] on the same flight with each logged stick replaced by the command's
    mean over its sample (the world flown again unsampled: ``log_every`` 1 at the world's rate is the same flight
    bit for bit): what the aircraft felt, which no estimate from the logged samples alone recovers."""
    from identification.bench.synthetic import simulate_flight
    from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier

    every = config.log_every
    world = simulate_flight(config.duration, seed=sim.seed, truth=aircraft_truth(aircraft),
                            config=replace(config, sample_rate=config.sample_rate * every, log_every=1)).flight
    logged = sim.flight
    n = logged.n
    means = world.sticks[:, :(n - 1) * every].reshape(world.sticks.shape[0], n - 1, every).mean(axis=2)
    sticks = np.concatenate([means, logged.sticks[:, -1:]], axis=1)
    values = MaximumLikelihoodIdentifier(**CLI_TIMING, workers=1).fit(replace(logged, sticks=sticks)).params_.values()
    return {k: 100.0 * (values[k] - truth[k]) / abs(truth[k]) for k in PARAMS}


def _table(rows) -> None:
    groups: dict = {}
    for r in rows:
        groups.setdefault(r["row"], []).append(r)
    print(f"{'aircraft':10s} {'cell':24s} {'Hz':>4s} {'every':>5s}  "
          + "  ".join(f"{'LR ' + a + ' med [max]':>19s}" for a in AXES) + "  named r/p/y  "
          + "  ".join(f"{p:>11s}" for p in PARAMS))
    for key, rs in groups.items():
        ok = [r for r in rs if "error" not in r]
        lr = "  ".join(f"{np.median([r['lr'][a] for r in ok]):9.1f} [{max(r['lr'][a] for r in ok):7.1f}]"
                       if ok else f"{'-':>19s}" for a in AXES)
        named = "/".join(str(sum(a in r["named"] for r in ok)) for a in AXES)
        err = "  ".join(
            f"{np.sqrt(np.mean([r['error_pct'][p] ** 2 for r in ok])):4.1f} [{max(abs(r['error_pct'][p]) for r in ok):4.1f}]"
            if ok else f"{'-':>11s}" for p in PARAMS)
        refused = f"  ({len(rs) - len(ok)} refused)" if len(ok) < len(rs) else ""
        print(f"{key[0]:10s} {key[1]:24s} {key[2]:4g} {key[3]:5d}  {lr}  {named:>5s} of {len(ok):<3d} {err}{refused}")
        for label, column in (("refitted on neighbour-shrunk sticks", "shrunk_pct"),
                              ("on each sample's mean over its interval", "interval_mean_pct")):
            errs = [r[column] for r in ok if column in r]
            if errs:
                print(f"{label + ':':>121s}      " + "  ".join(
                    f"{np.sqrt(np.mean([m[p] ** 2 for m in errs])):4.1f} [{max(abs(m[p]) for m in errs):4.1f}]"
                    for p in PARAMS))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--aircraft", nargs="+", default=["paper", "agile", "sluggish"], choices=["paper", *AIRCRAFT])
    ap.add_argument("--cells", nargs="+", default=list(DEFAULT_CELLS))
    ap.add_argument("--rates", nargs="+", type=float, default=[100.0], help="log rates [Hz]")
    ap.add_argument("--log-every", nargs="+", type=int, default=[1, 4],
                    help="world steps per logged sample (1: the world at the log's rate)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=1301)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--interval-mean", action="store_true",
                    help="also fit each flight whose world is faster than its log on each stick's mean over its "
                         "sample (the world flown again unsampled; about a fit and a flight more)")
    ap.add_argument("--set", type=config_field, nargs="*", default=[], metavar="FIELD=VALUE",
                    help="FlightConfig fields changed in every cell, e.g. command_noise=0.005")
    args = ap.parse_args(argv)
    from identification.bench.cells import BENCH_CELLS

    unknown = [c for c in args.cells if c not in BENCH_CELLS]
    if unknown:
        raise SystemExit(f"unknown cells {unknown}; known: {', '.join(BENCH_CELLS)}")
    jobs = [(a, c, r, e, s, args.duration, tuple(args.set), args.interval_mean) for a in args.aircraft for c in args.cells
            for r in args.rates for e in args.log_every for s in range(args.first_seed, args.first_seed + args.seeds)]
    from tqdm import tqdm

    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight"))
    sets = " ".join(f"{k}={v!r}" for k, v in args.set)
    print(f"\nLikelihood gain of neighbour-shrunk sticks per axis (median [largest] over {args.seeds} seeds; an axis is "
          f"named above its threshold, 0.5 ln n = {0.5 * np.log(args.duration * min(args.rates)):.1f}-"
          f"{0.5 * np.log(args.duration * max(args.rates)):.1f}); the default fit's relative error (%), RMS [worst]. "
          f"Command: python scripts/stick_noise_study.py --seeds {args.seeds} --first-seed {args.first_seed} "
          f"--duration {args.duration:g} --aircraft {' '.join(args.aircraft)} --cells {' '.join(args.cells)} "
          f"--rates {' '.join(f'{r:g}' for r in args.rates)} --log-every {' '.join(map(str, args.log_every))}"
          + (f" --set {sets}" if sets else "") + (" --interval-mean" if args.interval_mean else ""))
    _table(rows)
    times = [r["check_s"] for r in rows if "check_s" in r]
    fits = [r["fit_s"] for r in rows if "fit_s" in r]
    if times:
        print(f"\nmedian time per flight on one core: the fit {np.median(fits):.2f} s, the test {np.median(times):.2f} s")


if __name__ == "__main__":
    main()
