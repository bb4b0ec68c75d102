"""Benchmarks of heli-env: figures and ratios measured side by side in one run.

Machines are noisy: every figure is the median of repeated runs, and ratios
are taken between figures measured in the same run.

Sections (``--only NAME`` runs one):

* ``identification`` — the integral method (Fig. 5) on a 300 s, 100 Hz flight,
  all three axes. Target: <= 10 ms median (issue #2).
* ``physics`` — the physics core: one RK4 step on the scalar path, a 300 s
  forward simulation, a batched step over 4096 states.
* ``env`` — issue #33's env figures in the default configuration (the shipped
  model's sensors on), quiet and then beside a CPU-bound neighbour process the
  section starts itself: the native vector env at 4096 copies (default thread
  choice) against Gymnasium's ``CartPoleVectorEnv(4096)`` (target >= 1.0) and
  against its own ``threads=1`` figure (target >= 0.9), and ``HeliAttitude-v0``
  through ``gym.make`` against ``Pendulum-v1`` (target >= 1.0); the envs of
  each comparison are timed in turn. Then a reset of all the vector env's
  copies, per copy and spread over an episode (the steps above end no
  episode; CartPole's own resets are in its figure), and the vector env
  against CartPole again once its copies' episodes end on different steps,
  as in a long run (two a step at 4096 copies and 30 s episodes).
* ``env-threads`` — the vector env with numba's whole pool fixed against one
  thread, quiet and busy, under the threading layer in use (run it once per
  ``NUMBA_THREADING_LAYER``).
* ``sweep`` — a 20 x 20 PD gain grid x 10 gust windows x 60 s at 100 Hz through
  ``controllers.sweep.sweep_gains`` (target <= 10 s on 2 cores, issue #5), and its
  prediction checked against fresh-wind flights (KS statistic, target <= 0.1).
* ``backends`` — the same sweep on ``local`` with 1 and 2 workers and on ``ray``
  with 2 (issue 8): scaling, Ray overhead, and a projection (stated as such) for
  a 64-core cluster.
* ``cli`` — wall time of ``heli --help`` and of every ``heli COMMAND --help``, each
  a fresh process of the installed console script (target <= 0.5 s each, issue 18).
* ``rl-seeds`` — PPO steps/s of one seed alone and of ``--seeds 0,1`` side by side on
  the local backend, each seed's ratio to the one alone (target >= 0.8 on 2 cores, issue 17).
* ``rl`` — issue #33's RL figures: the target runs' residual PPO (on the LQG baseline) alone, two seeds side by
  side (target >= 0.8 of alone) and beside a CPU-bound neighbour, in steps/s and in minutes to the steps the
  RL target was checked with (target <= 5 quiet).

Usage::

    python scripts/bench.py [--only identification] [--repeats 30]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def _median_time(fn, repeats: int) -> float:
    fn()  # warm-up: caches, imports, lazy designs
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bench_identification(repeats: int) -> dict:
    from identification.integral.method import IntegralIdentifier
    from identification.preprocess import lowpass_flight
    from identification.bench.synthetic import simulate_flight

    flight = simulate_flight(300, seed=1).flight
    filtered = lowpass_flight(flight)
    out = {
        "flight": f"{flight.duration:.0f} s, {flight.n} samples at {flight.sample_rate:.0f} Hz",
        "decoupled, 3 axes, with FIR prefilter [ms]": 1e3 * _median_time(lambda: IntegralIdentifier().fit(flight), repeats),
        "decoupled, 3 axes, prefiltered input [ms]": 1e3 * _median_time(
            lambda: IntegralIdentifier(prefilter=False).fit(filtered), repeats),
        "coupled, 3 axes, with FIR prefilter [ms]": 1e3 * _median_time(
            lambda: IntegralIdentifier(structure="coupled").fit(flight), repeats),
        "FIR prefilter alone [ms]": 1e3 * _median_time(lambda: lowpass_flight(flight), repeats),
        "decoupled, 3 axes, delay search over 51 delays [ms]": 1e3 * _median_time(
            lambda: IntegralIdentifier(delay="auto").fit(flight), max(3, repeats // 10)),
    }
    out["target (<= 10 ms, decoupled with prefilter)"] = (
        "met" if out["decoupled, 3 axes, with FIR prefilter [ms]"] <= 10.0 else "NOT met")
    from identification.diagnosis.likelihood_diagnoser import LikelihoodDiagnoser
    from identification.likelihood.axis_pool import workers_available
    from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier

    few = max(3, repeats // 20)
    one = {"workers": 1}  # one core: the axes one after another (identification.likelihood.axis_pool)
    ml = _median_time(lambda: MaximumLikelihoodIdentifier(**one).fit(flight), few)
    ml_linear = _median_time(lambda: MaximumLikelihoodIdentifier(input_hold="linear", **one).fit(flight), few)
    ml_pool = _median_time(lambda: MaximumLikelihoodIdentifier().fit(flight), few)
    ml_detect = _median_time(lambda: MaximumLikelihoodIdentifier(delay="detect", **one).fit(flight), few)
    ml_detect_pool = _median_time(lambda: MaximumLikelihoodIdentifier(delay="detect").fit(flight), few)
    delayed = simulate_flight(300, seed=2, effects=("servo_delay",)).flight
    ml_delay = _median_time(lambda: MaximumLikelihoodIdentifier(delay="auto", **one).fit(delayed), few)
    ml_delay_pool = _median_time(lambda: MaximumLikelihoodIdentifier(delay="auto").fit(delayed), few)
    identify = {**CLI_TIMING, "closed_loop": "auto"}  # heli identify's defaults, the closed-loop check included
    checked_one = _median_time(lambda: MaximumLikelihoodIdentifier(**identify, **one).fit(flight), 1)
    checked = _median_time(lambda: MaximumLikelihoodIdentifier(**identify).fit(flight), 1)
    diag_one = _median_time(lambda: LikelihoodDiagnoser(**one).fit(flight), 1)
    diag = _median_time(lambda: LikelihoodDiagnoser().fit(flight), 1)
    lagged = _median_time(lambda: MaximumLikelihoodIdentifier(delay="auto", servo_lag="auto", **one).fit(delayed), 1)
    # the check's slow path: a pilot's flight behind a noisy gyro with a fast servo on every axis, each delay found
    # tested in the delay-free loop (16 flights) and the check's flights fitted with it profiled
    from identification.bench.cells import BENCH_CELLS

    slow = simulate_flight(300, seed=11, config=BENCH_CELLS["broadband-pd-noisy-gyro"], effects=("servo_delay",),
                           effect_scale=0.25).flight
    checked_delays = _median_time(lambda: MaximumLikelihoodIdentifier(**identify).fit(slow), 1)
    out.update({
        "maximum likelihood, decoupled, 3 axes, one core, hold estimated (default) [s]": ml,
        "the same with the hold fixed linear (the default before) [s]": ml_linear,
        "hold estimated / fixed time ratio": ml / ml_linear,
        f"the default, axes side by side on {workers_available()} cores [s]": ml_pool,
        "the same with a servo delay tested (delay='detect', none found), one core [s]": ml_detect,
        "servo-delay test / no test time ratio": ml_detect / ml,
        f"the same, axes side by side on {workers_available()} cores [s]": ml_detect_pool,
        "heli identify's default: the same with the closed-loop check (8 flights flown and fitted), one core [s]":
            checked_one,
        f"heli identify's default, on {workers_available()} cores [s]": checked,
        f"heli identify's default on a pilot's flight behind a noisy gyro with servo delays found on every axis "
        f"(the check's slow path), on {workers_available()} cores [s]": checked_delays,
        "maximum likelihood with the alignment profiled over -0.6-0.5 s, 3 axes, one core [s]": ml_delay,
        f"the same, axes side by side on {workers_available()} cores (default) [s]": ml_delay_pool,
        "the same with the servo lag profiled too (10-200 ms), 3 axes, one core [s]": lagged,
        "likelihood diagnosis of the 300 s flight, every candidate, one core [s]": diag_one,
        f"likelihood diagnosis, axes side by side on {workers_available()} cores (default) [s]": diag,
        "ML / integral time ratio": ml / (out["decoupled, 3 axes, with FIR prefilter [ms]"] / 1e3),
        "target (ML with the hold estimated <= 1.5 s on one core; delay profile <= 5 s and diagnosis <= 10 s, "
        "both by default)": ", ".join(
            f"{name} {'met' if v <= lim else 'NOT met'}" for name, v, lim in
            (("ML", ml, 1.5), ("delay", ml_delay_pool, 5.0), ("diagnosis", diag, 10.0))),
    })
    return out


def bench_physics(repeats: int) -> dict:
    from heli_core.physics import initial_state, simulate, step
    from identification.bench.flight_config import PAPER_PARAMS

    x = [float(v) for v in initial_state()]
    u = [0.1, -0.05, 0.2, 0.01]
    per_step = _median_time(lambda: step(x, u, None, PAPER_PARAMS, 0.01), repeats * 100)
    t = np.arange(30001) * 0.01
    sticks = np.zeros((4, t.size))
    sticks[0] = 0.2 * np.sin(2 * np.pi * 0.5 * t)
    sim = _median_time(lambda: simulate(PAPER_PARAMS, t, sticks), max(3, repeats // 10))
    xb = initial_state(batch=(4096,))
    ub = np.zeros((4, 4096))
    batched = _median_time(lambda: step(xb, ub, None, PAPER_PARAMS, 0.01), repeats)
    return {
        "one RK4 step, scalar path [us]": 1e6 * per_step,
        "300 s forward simulation at 100 Hz [s]": sim,
        "one RK4 step over 4096 states [ms]": 1e3 * batched,
        "batched vs scalar cost per state (ratio)": per_step / (batched / 4096),
    }


def _steps_per_second(env, action, steps: int, blocks: int, vector: bool = False) -> float:
    """Median over ``blocks`` of steps per second, resetting when an episode ends."""
    rates = []
    for _ in range(blocks):
        t0 = time.perf_counter()
        for _ in range(steps):
            _, _, term, trunc, _ = env.step(action)
            if not vector and (term or trunc):
                env.reset()
        rates.append(steps / (time.perf_counter() - t0))
    return statistics.median(rates)


def _interleaved(runs: dict, steps: int, blocks: int) -> dict:
    """Median steps/s of each ``name: (env, action, copies)``, their blocks of ``steps`` taken in turn."""
    rates = {name: [] for name in runs}
    for _ in range(blocks):
        for name, (env, action, copies) in runs.items():
            rates[name].append(copies * _steps_per_second(env, action, steps, 1, vector=copies > 1))
    return {name: statistics.median(r) for name, r in rates.items()}


def _spread_episode_ends(vec, action) -> None:
    """Restart copy ``i`` of ``vec`` at step ``i % episode_steps`` of one episode's length, so that from then on
    some copies' episodes end on every step, as in a long run (a fresh vector env's copies all end together)."""
    vec.reset(seed=0)
    steps = vec.unwrapped.spec_.episode_steps
    group = np.arange(vec.num_envs) % steps
    for k in range(steps):
        mask = group == k
        if mask.any():
            vec.reset(options={"reset_mask": mask})
        vec.step(action)


def _neighbour():
    """Start a CPU-bound process (a Python busy loop, one core) beside the benchmark; the caller stops it."""
    import subprocess
    import sys

    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def _load() -> str:
    import os

    try:
        return " / ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:
        return "unknown"


class _PoolCounter:
    """Steps a vector env and counts the steps its thread choice ran on numba's pool."""

    def __init__(self, env, choice):
        self.env, self.choice, self.steps, self.pooled = env, choice, 0, 0

    def step(self, actions):
        self.steps += 1
        self.pooled += self.choice.parallel
        return self.env.step(actions)

    def share(self) -> float:
        return self.pooled / max(self.steps, 1)


ENV_COPIES = 4096


def bench_env(repeats: int) -> dict:
    """The env targets of issue #33, each measured quiet and then with a CPU-bound neighbour process.

    Every figure is the default configuration (the shipped model's sensors on). In each condition the
    native vector env at 4096 copies with its default thread choice, the same with ``threads=1`` and
    Gymnasium's ``CartPoleVectorEnv(4096)`` are timed in turn (blocks of 40 steps), then the single env
    and ``Pendulum-v1`` through ``gym.make`` (blocks of 2000 steps); medians and their ratios. "Quiet"
    is whatever else the machine runs: the load average is printed beside it.
    """
    import os

    import gymnasium as gym
    import numba
    from gymnasium.envs.classic_control.cartpole import CartPoleVectorEnv

    import heli_env  # noqa: F401  (registers HeliAttitude-v0)
    from heli_env.threads import ENV_VAR

    n = ENV_COPIES
    vec = gym.make_vec("HeliAttitude-v0", num_envs=n, vectorization_mode="vector_entry_point")
    vec1 = gym.make_vec("HeliAttitude-v0", num_envs=n, vectorization_mode="vector_entry_point", threads=1)
    spread = gym.make_vec("HeliAttitude-v0", num_envs=n, vectorization_mode="vector_entry_point")
    cart = CartPoleVectorEnv(num_envs=n)
    heli = gym.make("HeliAttitude-v0")
    pend = gym.make("Pendulum-v1")
    for env in (vec, vec1, cart, heli, pend):
        env.reset(seed=0)
    _spread_episode_ends(spread, np.zeros((n, 3), dtype=np.float32))
    a_v, a_c = np.zeros((n, 3), dtype=np.float32), np.zeros(n, dtype=np.int64)
    a_h, a_p = np.zeros(3, dtype=np.float32), np.zeros(1, dtype=np.float32)
    choice = vec.unwrapped._thread_choice
    out = {"cpus": os.cpu_count(), "numba pool": f"{numba.config.NUMBA_NUM_THREADS} threads",
           ENV_VAR: os.environ.get(ENV_VAR, "unset")}
    blocks = max(9, repeats)  # the envs of a comparison differ by a few per cent: many blocks, in turn
    for condition in ("quiet", "busy"):
        neighbour = _neighbour() if condition == "busy" else None
        try:
            time.sleep(0.5 if neighbour else 0.0)
            before = _load()
            for env, action in ((vec, a_v), (vec1, a_v), (cart, a_c)):  # warm-up; the default settles its choice
                _steps_per_second(env, action, 300 if env is vec else 20, 1, vector=True)
            counted = _PoolCounter(vec, choice)
            rates = _interleaved({"vector": (counted, a_v, n), "vector threads=1": (vec1, a_v, n),
                                  "CartPoleVectorEnv": (cart, a_c, n)}, 40, blocks)
            pooled = counted.share()
            rates.update(_interleaved({"spread": (spread, a_v, n), "CartPoleVectorEnv again": (cart, a_c, n)}, 40,
                                      blocks))
            resets = []
            for _ in range(blocks):  # a reset of every copy: what the autoresets of an episode's end cost
                t0 = time.perf_counter()
                vec1.reset()
                resets.append(time.perf_counter() - t0)
            rates.update(_interleaved({"single": (heli, a_h, 1), "Pendulum-v1": (pend, a_p, 1)}, 2000, blocks))
            after = _load()
        finally:
            if neighbour is not None:
                neighbour.terminate()
                neighbour.wait()
        c = f"{condition}"
        out[f"{c}: load average before / after (1, 5, 15 min)"] = f"{before}; {after}"
        out[f"{c}: vector env-steps/s, HeliAttitude-v0 x {n}, default threads (sensors on)"] = rates["vector"]
        out[f"{c}:   its steps on numba's pool (the rest on one thread)"] = f"{100 * pooled:.0f} %"
        out[f"{c}: vector env-steps/s, the same with threads=1"] = rates["vector threads=1"]
        out[f"{c}: vector env-steps/s, CartPoleVectorEnv x {n}"] = rates["CartPoleVectorEnv"]
        out[f"{c}: ratio vector / CartPoleVectorEnv (target >= 1.0)"] = rates["vector"] / rates["CartPoleVectorEnv"]
        out[f"{c}: ratio vector / its threads=1 figure (target >= 0.9)"] = rates["vector"] / rates["vector threads=1"]
        out[f"{c}: vector env-steps/s, episodes ending on every step (a long run's state)"] = rates["spread"]
        out[f"{c}: ratio of that / CartPoleVectorEnv"] = rates["spread"] / rates["CartPoleVectorEnv again"]
        reset_us = statistics.median(resets) / n * 1e6
        episode = vec1.unwrapped.spec_.episode_steps
        out[f"{c}: vector env reset of all {n} copies [us per copy]"] = reset_us
        out[f"{c}:   the same spread over an episode of {episode} steps [ns per copy-step]"] = reset_us * 1e3 / episode
        out[f"{c}: single env steps/s, HeliAttitude-v0 via gym.make (sensors on)"] = rates["single"]
        out[f"{c}: single env steps/s, Pendulum-v1 via gym.make"] = rates["Pendulum-v1"]
        out[f"{c}: ratio single / Pendulum-v1 (target >= 1.0)"] = rates["single"] / rates["Pendulum-v1"]
    return out


def bench_env_threads(repeats: int) -> dict:
    """The vector env (4096 copies, sensors on) with numba's pool fixed (``threads=`` all of it) against
    ``threads=1``, quiet and beside a CPU-bound neighbour, under the threading layer numba uses
    (``NUMBA_THREADING_LAYER=omp|workqueue|tbb`` chooses it; unset, heli_env asks for workqueue)."""
    import os

    import numba

    from heli_env.vector_env import HeliAttitudeVectorEnv

    n, most = ENV_COPIES, numba.config.NUMBA_NUM_THREADS
    envs = {f"threads={most}": HeliAttitudeVectorEnv(n, threads=most), "threads=1": HeliAttitudeVectorEnv(n, threads=1)}
    for env in envs.values():
        env.reset(seed=0)
    action = np.zeros((n, 3), dtype=np.float32)
    for env in envs.values():
        _steps_per_second(env, action, 50, 1, vector=True)
    out = {"cpus": os.cpu_count(), "threading layer": numba.threading_layer(),
           "NUMBA_THREADING_LAYER": os.environ.get("NUMBA_THREADING_LAYER", "unset")}
    for condition in ("quiet", "busy"):
        neighbour = _neighbour() if condition == "busy" else None
        try:
            time.sleep(0.5 if neighbour else 0.0)
            load = _load()
            rates = _interleaved({k: (env, action, n) for k, env in envs.items()}, 40, max(9, repeats // 2))
        finally:
            if neighbour is not None:
                neighbour.terminate()
                neighbour.wait()
        out[f"{condition}: load average (1, 5, 15 min)"] = load
        for k, v in rates.items():
            out[f"{condition}: vector env-steps/s, {k}"] = v
        out[f"{condition}: ratio threads={most} / threads=1"] = rates[f"threads={most}"] / rates["threads=1"]
    return out


def bench_sweep(repeats: int) -> dict:
    """Gain sweep (issue #5): 20 x 20 Kp x Kd grid x 10 gust windows x 60 s at 100 Hz (target <= 10 s, 2 cores).

    The shipped model has 3 traces of 200 s; the 10 windows are 10 distinct (trace, offset)
    windows of 60 s drawn from them (``windows=10``, seed 0). Then the prediction is checked
    against fresh-wind flights of the truth model at 8 stable pairs spread over the grid
    (10 flights of 60 s each; truth = the model's own parameters, then the paper's).
    """
    import os

    from controllers.flight_test import validate_against_flights
    from controllers.sweep import sweep_gains, sweep_pairs
    from controllers.sweep_report import default_pairs

    kp, kd = np.linspace(0.5, 10.0, 20), np.linspace(0.0, 3.0, 20)

    def run():
        return sweep_gains(None, kp, kd, duration=60.0, dt=0.01, windows=10, seed=0, progress=False, extend=False)

    t0 = time.perf_counter()
    result = run()  # cold: imports python-control and scipy.signal, compiles the model
    cold = time.perf_counter() - t0
    runs = [run() for _ in range(max(3, repeats // 10))]
    totals = sorted(r.settings["seconds"]["total"] for r in runs)
    med = runs[[r.settings["seconds"]["total"] for r in runs].index(totals[len(totals) // 2])].settings["seconds"]
    n_stable = int(result.stable.sum())
    out = {
        "cpus": os.cpu_count(),
        "grid": f"{kp.size} x {kd.size} pairs ({n_stable} stable) x {result.settings['n_windows']} windows x "
                f"{result.settings['duration']:g} s at {1 / result.settings['dt']:g} Hz",
        "sweep, cold first call incl. imports [s]": cold,
        "sweep, median total [s]": med["total"],
        "  time domain (replay + statistics) [s]": med["time_domain"],
        "  frequency domain (poles + Welch + |H|^2) [s]": med["frequency_domain"],
        "replay cost per pair-window-step [ns]": 1e9 * med["time_domain"] / (
            n_stable * result.settings["n_windows"] * result.settings["steps"]),
        "target (<= 10 s)": "met" if med["total"] <= 10.0 else "NOT met",
        "pairs where time and frequency domain disagree (p90 > 20 %)": int(result.table["disagree"].sum()),
        "largest |p90 time/frequency - 1|, attitude": float(np.nanmax(np.abs(result.table["att_p90_rel_diff"]))),
    }
    pairs = default_pairs(result, 8)
    prediction = sweep_pairs(None, pairs, duration=None, keep_samples=True, progress=False)
    for truth in ("model", "paper"):
        t0 = time.perf_counter()
        ft = validate_against_flights(None, pairs, n_flights=10, duration=60.0, seed=0, truth=truth,
                                      prediction=prediction, progress=False)
        ks = np.asarray(ft.table["ks_att"], dtype=float)
        t = f"truth={truth}"
        out[f"flight tests, {t}: 8 pairs x 10 flights x 60 s [s]"] = time.perf_counter() - t0
        out[f"  {t}: KS |attitude error| vs time domain, max / median"] = (
            f"{np.nanmax(ks):.3f} / {np.nanmedian(ks):.3f}")
        out[f"  {t}: KS |rate error| vs time domain, max"] = float(
            np.nanmax(np.asarray(ft.table["ks_rate"], dtype=float)))
        out[f"  {t}: KS |attitude error| vs frequency-domain half-normal, max"] = float(
            np.nanmax(np.asarray(ft.table["ks_att_gauss"], dtype=float)))
        out[f"  {t}: largest |p90 predicted (time domain) / measured - 1|, attitude"] = float(
            np.nanmax(np.abs(np.asarray(ft.table["att_p90_err_td"], dtype=float))))
        out[f"  {t}: target KS <= 0.1"] = "met" if ft.target_met else "NOT met"
    return out


def _noop(item, shared):
    return item


def bench_backends(repeats: int) -> dict:
    """Backends (issue 8): the ``sweep`` section's sweep on ``local`` with 1 and 2 workers and on ``ray`` with 2.

    The 20 x 20 grid x 10 windows x 60 s sweep splits into 4 tasks of 1024 pair-window
    states (``controllers.sweep.TASK_STATES``), whatever the backend. Figures are medians
    of the repeats, the backends interleaved so that machine noise hits them alike; the
    first call of each (pool or Ray start-up) is reported apart. The per-task overhead
    is the median cost of an empty task in a map of 64. The 64-core figures are a
    projection from these measurements, not a measurement.
    """
    import math
    import os
    import pickle

    from controllers.sweep import sweep_gains
    from controllers.sweep_replay import TASK_STATES, chunks
    from heli_core.backends import LocalBackend, RayBackend

    kp, kd = np.linspace(0.5, 10.0, 20), np.linspace(0.0, 3.0, 20)
    n_rep = max(3, repeats // 10)

    def run(backend):
        return sweep_gains(None, kp, kd, duration=60.0, dt=0.01, windows=10, seed=0, progress=False, backend=backend,
                           extend=False)

    ref = run(None)  # warm-up and the reference table
    ray_be = RayBackend(num_cpus=2)
    t0 = time.perf_counter()
    ray_be.workers  # starts the local Ray instance
    ray_start = time.perf_counter() - t0
    backends = {"local, 1 worker": LocalBackend(1), "local, 2 workers": LocalBackend(2), "ray, 2 workers": ray_be}
    first, totals, td = {}, {k: [] for k in backends}, {k: [] for k in backends}
    try:
        for name, be in backends.items():
            t0 = time.perf_counter()
            res = run(be)
            first[name] = time.perf_counter() - t0
            same = all(np.array_equal(np.asarray(ref.table[c]), np.asarray(res.table[c]),
                                      equal_nan=np.asarray(ref.table[c]).dtype.kind == "f") for c in ref.table)
            if not (same and np.array_equal(ref.hist_counts, res.hist_counts)):
                raise AssertionError(f"{name}: the sweep differs from the single-process one")
        for _ in range(n_rep):
            for name, be in backends.items():
                t0 = time.perf_counter()
                res = run(be)
                totals[name].append(time.perf_counter() - t0)
                td[name].append(res.settings["seconds"]["time_domain"])
        overhead = {}
        for name in ("local, 2 workers", "ray, 2 workers"):
            be = backends[name]
            be.map(_noop, range(64))  # warm
            times = []
            for _ in range(n_rep):
                t0 = time.perf_counter()
                be.map(_noop, range(64))
                times.append((time.perf_counter() - t0) / 64)
            overhead[name] = statistics.median(times)
    finally:
        ray_be.close()
    med = {k: statistics.median(v) for k, v in totals.items()}
    med_td = {k: statistics.median(v) for k, v in td.items()}
    fd = ref.settings["seconds"]["frequency_domain"]
    n_tasks = len(chunks(int(ref.stable.sum()), ref.settings["n_windows"], None))
    from controllers.sweep_inputs import prepare

    rp = prepare(None, "roll", 60.0, 0.01, 0, None, 10)
    import dataclasses

    shared_mb = len(pickle.dumps(dataclasses.replace(rp, env_model=None))) / 1e6
    one, two, ray2 = med["local, 1 worker"], med["local, 2 workers"], med["ray, 2 workers"]
    out = {
        "cpus": os.cpu_count(),
        "sweep": f"{kp.size} x {kd.size} pairs x {ref.settings['n_windows']} windows x 60 s at 100 Hz, "
                 f"{n_tasks} tasks of <= {TASK_STATES} pair-window states; results equal the single-process "
                 "sweep bit for bit on every backend (checked)",
        "data shared once per worker (windows' torque, trim, collective) [MB]": shared_mb,
        f"medians of {n_rep} interleaved runs": "",
    }
    for name in backends:
        out[f"  {name}: total [s]"] = med[name]
        out[f"  {name}: time domain (the distributed part) [s]"] = med_td[name]
        out[f"  {name}: first call (pool / workers start) [s]"] = first[name]
    out["frequency domain, on the driver for every backend [s]"] = fd
    out["Ray instance start-up, once per session [s]"] = ray_start
    out["speed-up local 2 workers vs 1 (total)"] = one / two
    out["speed-up local 2 workers vs 1 (time domain)"] = med_td["local, 1 worker"] / med_td["local, 2 workers"]
    out["Ray overhead: ray 2 / local 2 workers (total, ratio)"] = ray2 / two
    out["Ray overhead: ray 2 - local 2 workers (total) [s]"] = ray2 - two
    out["per-task overhead, empty task, local 2 workers [ms]"] = 1e3 * overhead["local, 2 workers"]
    out["per-task overhead, empty task, ray 2 workers [ms]"] = 1e3 * overhead["ray, 2 workers"]
    # Projection (stated as such): cores like these, the measured per-task overhead, the
    # shared data sent to each of 8 nodes once (1 Gbit/s), the frequency domain serial on the driver.
    t_task = med_td["local, 1 worker"] / n_tasks
    over = overhead["ray, 2 workers"]
    for label, scale in (("this sweep", 1), ("a 64x larger grid (160 x 160 pairs, 256 tasks)", 64)):
        tasks = n_tasks * scale
        serial = fd * scale + med_td["local, 1 worker"] * scale
        waves = math.ceil(tasks / 64)
        proj = fd * scale + waves * t_task + tasks * over / 64 + 8 * shared_mb * 8 / 1e3
        out[f"PROJECTION, 64 cores (8 nodes x 8), ray: {label} [s]"] = proj
        out[f"PROJECTION, 64 cores: {label}, speed-up vs 1 core"] = serial / proj
    out["PROJECTION note"] = ("this sweep has only 4 tasks, so 64 cores cannot beat 4; a grid with >= 64 tasks "
                              "keeps them busy and the serial frequency-domain part on the driver "
                              f"({1e3 * fd / ref.n_pairs:.2f} ms per pair) becomes the limit (Amdahl)")
    return out


def _process_seconds(argv: list, runs: int) -> float:
    """Median wall time of ``runs`` new processes running ``argv`` (their output discarded)."""
    import subprocess

    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bench_cli(repeats: int) -> dict:
    """``heli --help`` and each ``heli COMMAND --help`` as a user runs them: a new process each time,
    median of ``max(5, repeats // 6)`` runs (5 at the default 30)."""
    import sys
    from pathlib import Path

    from heli_cli.main import command_names

    heli = Path(sys.executable).with_name("heli")
    if not heli.exists():
        return {"skipped": f"no console script at {heli} (pip install -e .)"}
    commands = [""] + command_names()
    runs = max(5, repeats // 6)
    out = {}
    for command in commands:
        argv = [str(heli)] + ([command] if command else []) + ["--help"]
        out[f"heli {command + ' ' if command else ''}--help [s]"] = _process_seconds(argv, runs)
    worst = max(out.values())
    out["target (<= 0.5 s each)"] = f"{'met' if worst <= 0.5 else 'NOT met'} (slowest {worst:.3f} s)"
    return out


_FIRST_STEP = """
import gymnasium as gym, numpy as np
{imports}
env = {make}
env.reset(seed=0)
env.step(np.zeros(env.action_space.shape, dtype=env.action_space.dtype))
"""


def bench_startup(repeats: int) -> dict:
    """A new process to its first step, as a subprocess env worker or a command meets it: ``HeliAttitude-v0``
    (single) and its native vector env (16 copies, the compiled step cached by a first run), beside
    ``Pendulum-v1`` in the same run; median of ``max(5, repeats // 6)`` runs."""
    import subprocess
    import sys

    cases = {
        "Pendulum-v1": ("", "gym.make('Pendulum-v1')"),
        "HeliAttitude-v0": ("import heli_env", "gym.make('HeliAttitude-v0')"),
        "HeliAttitude-v0 vector (16)": ("import heli_env", "gym.make_vec('HeliAttitude-v0', num_envs=16, "
                                        "vectorization_mode='vector_entry_point')"),
    }
    runs = max(5, repeats // 6)
    out = {}
    for label, (imports, make) in cases.items():
        argv = [sys.executable, "-c", _FIRST_STEP.format(imports=imports, make=make)]
        subprocess.run(argv, check=True)  # the compiled code cached, as for a user
        out[f"{label}: new process to its first step [s]"] = _process_seconds(argv, runs)
    out["single ÷ Pendulum-v1 (time)"] = out["HeliAttitude-v0: new process to its first step [s]"] / out[
        "Pendulum-v1: new process to its first step [s]"]
    return out


def bench_rl_seeds(repeats: int) -> dict:
    """PPO steps/s of one training alone, then of ``--seeds 0,1`` on the local backend (2 workers), each with
    the same wall-time budget (``max(20, repeats)`` seconds): the per-seed ratio (target >= 0.8 on 2 cores)."""
    import json
    import os
    import tempfile
    from pathlib import Path

    from controllers.rl import train_agent, train_seeds

    kw = dict(algo="ppo", timesteps=10**9, max_seconds=max(20.0, float(repeats)), progress=False)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        train_agent(out=Path(tmp) / "one", seed=0, **kw)
        alone = json.loads((Path(tmp) / "one_training" / "training.json").read_text())["steps_per_second"]
        train_seeds(out=Path(tmp) / "two", seeds=(0, 1), backend="local", **kw)
        side = [json.loads((Path(tmp) / f"two_seed{s}_training" / "training.json").read_text())["steps_per_second"]
                for s in (0, 1)]
    out["one seed alone [steps/s]"] = alone
    for s, v in zip((0, 1), side):
        out[f"--seeds 0,1, seed {s} [steps/s]"] = v
    worst = min(side) / alone
    out["per-seed ratio, worst (target >= 0.8 on 2 cores)"] = worst
    out["cores"] = f"{os.cpu_count()}; {'met' if worst >= 0.8 else 'NOT met'}"
    return out


RL_TARGET_STEPS = 2_000_000
"""Environment steps of the residual runs that met issue #33's RL target (docs/rl-experiments.md, seventh
session, runs t0-t2): ``bench_rl`` turns its steps/s into minutes to that target."""
RL_TARGET_SETTINGS = {"n_envs": 32, "delay_spread": 0.02, "stick_step_weight": 0.5,
                      "algo_kwargs": {"n_steps": 128, "batch_size": 1024, "learning_rate": 1e-4}}
"""The settings of those runs besides the residual's defaults (``train_compare.py --n-envs 32 --delay-spread 0.02
--stick-step-weight 0.5 --algo-kwargs ...``; the stick-step term since the ninth session's runs w0-w2)."""


def bench_rl(repeats: int) -> dict:
    """Issue #33's RL figures: the residual PPO of the target's runs (on the shipped model's LQG baseline, with
    :data:`RL_TARGET_SETTINGS`) trained for ``max(30, repeats)`` s of wall time, quiet (after 5 s untimed, which
    compile the env's kernels and warm torch): one seed alone,
    then seeds 0 and 1 side by side (``train_seeds``, local backend, 2 workers) and each one's ratio to the one
    alone (target >= 0.8); then one alone beside a CPU-bound neighbour process. Steps/s are ``learn``'s (the
    set-up, which flies the base on the training gusts, is outside), and the minutes are those the target's
    :data:`RL_TARGET_STEPS` take at that rate."""
    import json
    import os
    import tempfile
    from pathlib import Path

    from controllers.lqg.design import design_lqg
    from controllers.rl import train_agent, train_seeds
    from heli_env import load_env_model

    model = load_env_model()
    base = design_lqg(model).controller()
    kw = dict(algo="ppo", model=model, timesteps=10**9, max_seconds=max(30.0, float(repeats)), residual=base,
              eval_freq=0, checkpoint_freq=0, progress=False, **RL_TARGET_SETTINGS)

    def rate(folder: Path, key: str = "steps_per_second") -> float:
        return json.loads((folder / "training.json").read_text())[key]

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        # a few seconds first, not timed: the first training of a process compiles (or loads) the env's kernels
        # and warms torch, which made 'alone' 20 % slower than each of two side by side (2026-12-02, Zen 5)
        train_agent(out=Path(tmp) / "warm", seed=0, **{**kw, "max_seconds": 5.0})
        before = _load()
        train_agent(out=Path(tmp) / "one", seed=0, **kw)
        alone, alone_cpu = rate(Path(tmp) / "one_training"), rate(Path(tmp) / "one_training", "steps_per_cpu_second")
        train_seeds(out=Path(tmp) / "two", seeds=(0, 1), backend="local", **kw)
        side = [rate(Path(tmp) / f"two_seed{s}_training") for s in (0, 1)]
        side_cpu = [rate(Path(tmp) / f"two_seed{s}_training", "steps_per_cpu_second") for s in (0, 1)]
        after = _load()
        neighbour = _neighbour()
        try:
            busy_before = _load()
            train_agent(out=Path(tmp) / "busy", seed=0, **kw)
            busy = rate(Path(tmp) / "busy_training")
            busy_after = _load()
        finally:
            neighbour.terminate()
            neighbour.wait()
    out["cores"] = os.cpu_count()
    out["quiet: load average before / after (1, 5, 15 min)"] = f"{before}; {after}"
    out["quiet: residual PPO on the LQG, one seed alone [steps/s]"] = alone
    out["quiet: the same, per second of its process' CPU time [steps/s]"] = alone_cpu
    out[f"quiet: minutes to the target's {RL_TARGET_STEPS / 1e6:g} M steps, one seed alone"] = (
        RL_TARGET_STEPS / alone / 60)
    for s, v in zip((0, 1), side):
        out[f"quiet: seeds 0,1 side by side, seed {s} [steps/s]"] = v
    worst = min(side) / alone
    out["quiet: side by side / alone, worst seed (target >= 0.8)"] = worst
    out["quiet: the same per CPU second (what each gets of a core it has; other work's share left out)"] = (
        min(side_cpu) / alone_cpu)
    out["quiet: minutes to the target's steps, slower seed side by side"] = RL_TARGET_STEPS / min(side) / 60
    out["busy: load average before / after"] = f"{busy_before}; {busy_after}"
    out["busy: one seed beside a CPU-bound neighbour [steps/s]"] = busy
    out["busy: minutes to the target's steps"] = RL_TARGET_STEPS / busy / 60
    out["targets"] = (f"side by side {'met' if worst >= 0.8 else 'NOT met'}; minutes to target quiet "
                      f"{'<=' if RL_TARGET_STEPS / alone <= 300 else '>'} 5")
    return out


SECTIONS = {"identification": bench_identification, "physics": bench_physics, "env": bench_env,
            "env-threads": bench_env_threads, "sweep": bench_sweep,
            "backends": bench_backends, "cli": bench_cli, "startup": bench_startup, "rl-seeds": bench_rl_seeds, "rl": bench_rl}


def main(argv=None):
    ap = argparse.ArgumentParser(description="heli-env benchmarks (medians; ratios from the same run)")
    ap.add_argument("--only", choices=sorted(SECTIONS), action="append")
    ap.add_argument("--repeats", type=int, default=30)
    args = ap.parse_args(argv)
    try:
        from threadpoolctl import threadpool_info

        blas = ", ".join(f"{i['internal_api']} {i.get('architecture', '')} threads={i['num_threads']}"
                         for i in threadpool_info())
    except ImportError:
        blas = "threadpoolctl not installed"
    print(f"# heli-env benchmarks — numpy {np.__version__}; BLAS: {blas}")
    for name in args.only or SECTIONS:
        print(f"\n## {name}")
        for key, value in SECTIONS[name](args.repeats).items():
            print(f"- {key}: {value:.3f}" if isinstance(value, float) else f"- {key}: {value}")


if __name__ == "__main__":  # the guard the local backend's worker processes need
    main()
