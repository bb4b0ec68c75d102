"""Benchmarks of heli-env: figures and ratios measured side by side in one run.

Machines are noisy: every figure is the median of repeated runs, and ratios
are taken between figures measured in the same run.

Sections (``--only NAME`` runs one):

* ``identification`` — the integral method (Fig. 5) on a 300 s, 100 Hz flight,
  all three axes. Target: <= 10 ms median (issue #2).
* ``physics`` — the physics core: one RK4 step on the scalar path, a 300 s
  forward simulation, a batched step over 4096 states.
* ``env`` — ``HeliAttitude-v0`` steps/s through ``gym.make`` against
  ``Pendulum-v1`` (target ratio >= 1.0), and the native vector env's
  env-steps/s at 4096 copies against Gymnasium's ``CartPoleVectorEnv``
  (target ratio >= 1.0); the two of each pair are timed interleaved.

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
    from identification.integral_method import IntegralIdentifier
    from identification.preprocess import lowpass_flight
    from identification.synthetic import simulate_flight

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
    return out


def bench_physics(repeats: int) -> dict:
    from identification.model import initial_state, simulate, step
    from identification.synthetic import PAPER_PARAMS

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


def bench_env(repeats: int) -> dict:
    import gymnasium as gym
    from gymnasium.envs.classic_control.cartpole import CartPoleVectorEnv

    import heli_env  # noqa: F401  (registers HeliAttitude-v0)

    out = {}
    heli = gym.make("HeliAttitude-v0")
    pend = gym.make("Pendulum-v1")
    heli.reset(seed=0)
    pend.reset(seed=0)
    a_h = np.zeros(3, dtype=np.float32)
    a_p = np.zeros(1, dtype=np.float32)
    # interleave the two so that machine noise hits both alike
    h_rates, p_rates = [], []
    for _ in range(max(5, repeats // 3)):
        h_rates.append(_steps_per_second(heli, a_h, 2000, 1))
        p_rates.append(_steps_per_second(pend, a_p, 2000, 1))
    h, p = statistics.median(h_rates), statistics.median(p_rates)
    out["single env steps/s, HeliAttitude-v0 via gym.make"] = h
    out["single env steps/s, Pendulum-v1 via gym.make"] = p
    out["single env ratio heli / Pendulum (target >= 1.0)"] = h / p
    n = 4096
    venv = gym.make_vec("HeliAttitude-v0", num_envs=n, vectorization_mode="vector_entry_point")
    cart = CartPoleVectorEnv(num_envs=n)
    venv.reset(seed=0)
    cart.reset(seed=0)
    a_v = np.zeros((n, 3), dtype=np.float32)
    a_c = np.zeros(n, dtype=np.int64)
    v_rates, c_rates = [], []
    for _ in range(max(5, repeats // 3)):
        v_rates.append(n * _steps_per_second(venv, a_v, 100, 1, vector=True))
        c_rates.append(n * _steps_per_second(cart, a_c, 100, 1, vector=True))
    v, c = statistics.median(v_rates), statistics.median(c_rates)
    out[f"vector env-steps/s at {n} envs, HeliAttitude-v0 native vector env"] = v
    out[f"vector env-steps/s at {n} envs, CartPoleVectorEnv"] = c
    out["vector ratio heli / CartPole (target >= 1.0)"] = v / c
    return out


SECTIONS = {"identification": bench_identification, "physics": bench_physics, "env": bench_env}


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


if __name__ == "__main__":
    main()
