"""Where a vector-env step's time goes: the step with one part taken out at a time, timed in turn.

The native vector env's step is one generated numba function (``heli_env.kernels.env_kernels``). This script
compiles variants of its source with one part removed or changed, swaps each into the same env (4096
copies, the shipped model's sensors on, one thread) and times blocks of 40 steps in rotation, a block of
Gymnasium's ``CartPoleVectorEnv`` after each, as ``scripts/bench.py --only env`` interleaves them. The
difference to the full step is what that part costs in the step; the variants compute wrong values and are
never used otherwise.

    python scripts/env_profile.py [--rounds 12] [--variants NAME ...] [--long-run]

Prints nanoseconds per copy-step (medians over the rounds) and each variant's ratio to CartPole. With
``--long-run`` a second env, in a long run's state (its copies' episodes ending on different steps, some on
every step: ``scripts/bench.py``'s ``_spread_episode_ends``), takes its place in the rotation with the full step:
what a long run's autoresets and its copies' differing steps cost (``--variants`` with no name times only these).
"""

from __future__ import annotations

import argparse
import re
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import heli_env.kernels as kernels  # noqa: E402
from heli_env.vector_env import HeliAttitudeVectorEnv  # noqa: E402

COPIES = 4096
LONG = "full step, a long run's state"


def _without_slow_path(lines):
    """The ziggurat's slow path skipped (about 1.5 % of the normals keep their rectangle's value)."""
    first = next(i for i, line in enumerate(lines) if "_slow = Wb[" in line) - 1
    last = next(i for i, line in enumerate(lines) if "standard_normal(" in line)
    return lines[:first] + lines[last + 1:]


def _without_normals(lines):
    """No sensor normals at all: every draw a constant (and no slow path)."""
    out = []
    for line in _without_slow_path(lines):
        if "= stream_bits(" in line:
            line = line.split("=")[0] + "= _key"
        elif "fast_normal(" in line:
            line = line.split("=")[0] + "= 0.1, False"
        out.append(line)
    return out


def _one_mixing_multiply(lines):
    """SplitMix64's two 64-bit multiplies of a word (and the position's by its gamma) replaced by one: what
    the stream's multiplies cost where the CPU has no 64-bit vector multiply (AVX2: three 32-bit ones and
    shifts each). Another stream: the noise changes, its cost alone is timed."""
    out = []
    for line in lines:
        m = re.match(r"(\s*)_b = stream_bits\(_key, (.*)\)$", line)
        if m:
            indent, position = m.groups()
            out += [f"{indent}_z = _key ^ (({position}) << np.uint64(21))",
                    f"{indent}_b = (_z ^ (_z >> np.uint64(29))) * np.uint64(0xBF58476D1CE4E5B9)"]
        else:
            out.append(line)
    return out


def _without_gyro_lines(lines):
    """The gyro vibration lines (the sensor model's sinusoids) left at zero."""
    first = next(i for i, line in enumerate(lines) if "_amp0 = line_amp[0]" in line)
    final = next(i for i, line in enumerate(lines) if i > first and line.startswith("        for l in range(_m):")
                 and lines[i + 1].strip().startswith("a0 = "))
    rows = [kernels.W[f"line{c}"] for c in range(3)]
    return (lines[:first] + ["        for l in range(_m):"]
            + [f"            Wb[{row * kernels.ROW} + l] = 0.0" for row in rows] + lines[final:])


def _without_inverse_trig(lines):
    """The Euler angles' atan2 / asin replaced by their first argument."""
    return [re.sub(r"= (atan2v|asinv)\((_e\d)(, _e\d)?\)", r"= \2", line) for line in lines]


def _library_row_fixed(lines):
    """Each copy reads the same library row every step (it stays in cache)."""
    return [line.replace("min(k[i], last[i]) * ratio", "0") for line in lines]


def _without_prefetch(lines):
    """The next step's library row not prefetched."""
    return [line for line in lines if "prefetch_row(" not in line]


VARIANTS = {"no slow path": _without_slow_path, "no normals": _without_normals,
            "one mixing multiply": _one_mixing_multiply,
            "no gyro lines": _without_gyro_lines, "no inverse trig": _without_inverse_trig,
            "library row fixed": _library_row_fixed, "no prefetch": _without_prefetch}


def step_lines(env) -> list[str]:
    """The source lines of the env's generated step function (:func:`heli_env.kernels.env_kernels`)."""
    captured = {}
    compile_module = kernels._compile_module

    def capture(functions, tag):
        captured.update(functions)
        return compile_module(functions, tag)

    kernels._compile_module = capture
    kernels.env_kernels.cache_clear()
    try:
        s = env.spec_
        kernels.env_kernels(s.model.params, s.dt, s.task.task, s.measured, s.task.axis_weighted, s.line_axis,
                            s.task.stick_step_weight > 0.0)
    finally:
        kernels._compile_module = compile_module
    return captured["step"][0]


def _compiled_variants(env, names):
    """The env's step and its variants, each compiled from the env's generated source."""
    lines = step_lines(env)
    steps = {"full step": env._step_loop}
    for name in names:
        steps[name] = kernels._compile_module({"step": (VARIANTS[name](lines), False)}, f"profile {name}").step
    return steps


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=12, help="rounds of 40-step blocks (default 12)")
    parser.add_argument("--variants", nargs="*", choices=list(VARIANTS), default=list(VARIANTS))
    parser.add_argument("--long-run", action="store_true", help="also time the full step in a long run's state")
    args = parser.parse_args(argv)
    from gymnasium.envs.classic_control.cartpole import CartPoleVectorEnv

    env = HeliAttitudeVectorEnv(COPIES, threads=1)
    env.reset(seed=0)
    steps = _compiled_variants(env, args.variants)
    cart = CartPoleVectorEnv(num_envs=COPIES)
    cart.reset(seed=0)
    actions, cart_actions = np.zeros((COPIES, 3), np.float32), np.zeros(COPIES, np.int64)

    def block(target, action, n_steps=40):
        t0 = time.perf_counter()
        for _ in range(n_steps):
            target.step(action)
        return (time.perf_counter() - t0) / n_steps / COPIES * 1e9

    for step in steps.values():  # compile and warm each
        env._step_loop = step
        block(env, actions, 5)
    envs = {name: env for name in steps}
    if args.long_run:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from bench import _spread_episode_ends

        envs[LONG] = HeliAttitudeVectorEnv(COPIES, threads=1)
        _spread_episode_ends(envs[LONG], actions)
        steps[LONG] = envs[LONG]._step_loop
    times = {name: [] for name in steps}
    times["CartPoleVectorEnv"] = []
    names = list(steps)
    for r in range(args.rounds):
        for name in names[r % len(names):] + names[:r % len(names)]:  # each variant takes each place in turn
            envs[name]._step_loop = steps[name]
            times[name].append(block(envs[name], actions))
            times["CartPoleVectorEnv"].append(block(cart, cart_actions))
    cart_ns = statistics.median(times["CartPoleVectorEnv"])
    full = statistics.median(times["full step"])
    print(f"# vector env step, {COPIES} copies, one thread: ns per copy-step (medians of {args.rounds} rounds)")
    for name, values in times.items():
        ns = statistics.median(values)
        change = "" if name in ("full step", "CartPoleVectorEnv") else f"  ({ns - full:+.1f} against the full step)"
        change += f"  (the fresh env / this {full / ns:.3f})" if name == LONG else ""
        print(f"- {name}: {ns:.1f} ns, CartPole / this {cart_ns / ns:.3f}{change}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
