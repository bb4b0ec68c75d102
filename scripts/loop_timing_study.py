"""Why a flight controller faster than its log gets a servo timing: the loop itself, flown exactly.

The likelihood sees a controller's command once a logged sample; the controller moves it at every tick of its loop
in between, and the likelihood reads that motion as a servo's delay or lag (docs/method.md, "A servo timing a fast
loop makes"). This study takes the sensors and the bench's six-degree-of-freedom aircraft out of the question: per
seed, the large sluggish aircraft's yaw (``aircraft_generalisation.py``'s ``sluggish``), its loop at 800 Hz logged at
200 Hz, only the yaw excited (roll and pitch without gusts or sweeps), flown three ways:

* ``linear``: an exact linear simulation written here: eq. (21), ``r' = -k11 r + k10 u + k12 col + kd3 + gust``,
  the command a PD on the true yaw angle and rate read one tick before it (the bench's autopilot gains), held over
  its tick, plus the yaw sweep; the bench's gust and collective at 800 Hz;
* ``bench-pd``: the bench (:mod:`identification.bench.synthetic`) with that PD on the true state (``pilot="pd"``,
  one tick late, held at each tick);
* ``autopilot``: the bench's autopilot (its gyro and attitude sensors, its 20 Hz D-term low-pass).

Each log states a flight controller's commands from an 800 Hz loop and is fitted as ``heli identify`` fits it, held
input, the yaw alone, without the closed-loop check: with the timing searched (``delay="detect"``,
``servo_lag="detect"``) and without. Prints per flight the timing found, its likelihood ratio against none, and the
damping k11's error both ways.

Usage::

    python scripts/loop_timing_study.py [--seeds 2] [--first-seed 1501] [--gyro-noise 0.01] [--duration 300]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from identification.bench.aircraft import AIRCRAFT

SLUGGISH = AIRCRAFT["sluggish"]
"""The bench's large, slow helicopter (:data:`identification.bench.aircraft.AIRCRAFT`)."""

LOG_HZ, TICKS = 200.0, 4
YAW_ONLY = dict(sweep_amplitude=(0.0, 0.0, 0.08), wind_level=(0.0, 0.0, 0.03))
"""Only the yaw excited: roll and pitch fly without sweeps or gusts."""


def _config(pilot: str, gyro_noise: float, duration: float, every: int):
    from identification.bench.cells import BENCH_CELLS

    pd = dict(pilot="pd", reaction_delay=1.0 / (LOG_HZ * TICKS), held_sticks=True) if pilot == "pd" else {}
    return replace(BENCH_CELLS["broadband-autopilot"], duration=duration, sample_rate=LOG_HZ * TICKS / every,
                   log_every=every, gyro_noise=gyro_noise, **YAW_ONLY, **pd)


def linear_yaw(seed: int, gyro_noise: float, duration: float):
    """The ``linear`` flight (module docstring): the bench's PD flight at 200 Hz with its yaw gyro, angle and pedal
    replaced by the exact linear loop's."""
    from identification.bench.synthetic import simulate_flight, sweep_schedule
    from identification.flight import make_flight

    fast_cfg = _config("pd", gyro_noise, duration, 1)
    fast = simulate_flight(duration, seed=seed, config=fast_cfg, truth=SLUGGISH)
    logged = simulate_flight(duration, seed=seed, config=_config("pd", gyro_noise, duration, TICKS), truth=SLUGGISH)
    h, p = 1.0 / (LOG_HZ * TICKS), SLUGGISH
    n = fast.flight.n
    gust, col = fast.wind_torque[2], fast.flight.sticks[2]
    sweep = sweep_schedule(fast.flight.time, fast_cfg)[2]
    decay = np.exp(-p.k11 * h)
    g = (1.0 - decay) / p.k11  # the exact step of r' = -k11 r + f with f held over the tick
    kp, kd = fast_cfg.pilot_bandwidth ** 2, 1.4 * fast_cfg.pilot_bandwidth  # the bench's PD (synthetic._fly)
    trim = -(p.kd3 - p.k12 * fast_cfg.collective_trim) / p.k10
    r, psi, u = np.zeros(n), np.zeros(n), np.full(n, trim)
    for k in range(n - 1):
        u[k + 1] = -(kp * psi[k] + kd * r[k]) / p.k10 + trim + sweep[k + 1]  # read a tick before it acts
        force = p.k10 * u[k] + p.k12 * col[k] + p.kd3 + gust[k]
        r[k + 1] = decay * r[k] + g * force
        psi[k + 1] = psi[k] + g * r[k] + (h - g) / p.k11 * force
    gyro = r + gyro_noise * np.random.default_rng([seed, 99]).standard_normal(n)
    f = logged.flight
    rates, attitude, sticks = f.rates.copy(), f.attitude.copy(), f.sticks.copy()
    rates[2], sticks[3] = gyro[::TICKS][:f.n], u[::TICKS][:f.n]
    attitude[2] = np.angle(np.exp(1j * psi[::TICKS][:f.n]))
    return make_flight(f.time, rates, sticks, attitude=attitude, metadata=dict(f.metadata))


def flight_of(kind: str, seed: int, gyro_noise: float, duration: float):
    """One flight of ``kind`` (module docstring), its log stating a flight controller's commands from its loop."""
    from identification.bench.synthetic import simulate_flight

    if kind == "linear":
        flight = linear_yaw(seed, gyro_noise, duration)
    else:
        pilot = "pd" if kind == "bench-pd" else "autopilot"
        flight = simulate_flight(duration, seed=seed, config=_config(pilot, gyro_noise, duration, TICKS),
                                 truth=SLUGGISH).flight
    return flight.with_metadata(input_source="flight controller commands", loop_rate_hz=LOG_HZ * TICKS)


def _one(job) -> dict:
    from threadpoolctl import threadpool_limits

    from identification.likelihood.estimator import MaximumLikelihoodIdentifier

    kind, seed, gyro_noise, duration = job
    flight = flight_of(kind, seed, gyro_noise, duration)
    out = {"kind": kind, "seed": seed}
    with threadpool_limits(limits=1, user_api="blas"):
        for label, timing in (("timed", "detect"), ("none", None)):
            ml = MaximumLikelihoodIdentifier(input_hold="zoh", delay=timing, servo_lag=timing, axes=("yaw",),
                                             workers=1).fit(flight)
            fit = ml.axes_["yaw"]
            out[label] = {"k11": 100.0 * (fit.params["k11"] / SLUGGISH.k11 - 1.0), "delay": fit.delay,
                          "lag": fit.lag, "nll": fit.nll, "shift": fit.input_shift}
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--first-seed", type=int, default=1501)
    ap.add_argument("--gyro-noise", type=float, default=0.01, help="white gyro noise [rad/s] (the bench's 0.01)")
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    if args.seeds < 1 or args.workers < 1 or args.duration <= 0 or args.gyro_noise < 0:
        ap.error(f"expected --seeds and --workers >= 1, --duration > 0 and --gyro-noise >= 0; got {args.seeds}, "
                 f"{args.workers}, {args.duration:g} and {args.gyro_noise:g}")
    from concurrent.futures import ProcessPoolExecutor

    from tqdm import tqdm

    jobs = [(kind, s, args.gyro_noise, args.duration) for kind in ("linear", "bench-pd", "autopilot")
            for s in range(args.first_seed, args.first_seed + args.seeds)]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight"))
    print(f"\nThe sluggish aircraft's yaw, its loop at {LOG_HZ * TICKS:g} Hz logged at {LOG_HZ:g} Hz, fitted held "
          f"without the check. Command: python scripts/loop_timing_study.py --seeds {args.seeds} --first-seed "
          f"{args.first_seed} --gyro-noise {args.gyro_noise:g} --duration {args.duration:g}\n")
    print("| flight | seed | timing found (delay / lag, ms) | LR against none | k11 with it | k11 without |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        t, none = r["timed"], r["none"]
        lr = max(2.0 * (none["nll"] - t["nll"]), 0.0)
        delay = t["delay"] + t["shift"]  # a negative alignment is recorded as the stick's shift
        print(f"| {r['kind']} | {r['seed']} | {1000 * delay:.1f} / {1000 * t['lag']:.1f} | {lr:.1f} | "
              f"{t['k11']:+.1f} % | {none['k11']:+.1f} % |")


if __name__ == "__main__":
    main()
