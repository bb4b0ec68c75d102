"""Where a residual PPO run's training time goes: env, SB3's rollout bookkeeping, torch, the paired twin.

Trains one residual (``controllers.rl.train_agent``) for ``--steps`` environment steps with timers wrapped
around the parts of a PPO iteration, and prints each part's share of ``learn``'s wall time and the run's
steps per second of wall time and of process CPU time (on a machine shared with other work, the CPU
figure is the nearer one to a quiet core's; neither is a quiet core's). The timers cost a few per cent;
no sampling profiler is needed.

Parts (nested parts are counted once, in the innermost):

* rollout, policy forward: ``ActorCriticPolicy.forward`` at each vector step (actions, values, log-probs);
* rollout, env: the physics (``HeliAttitudeVectorEnv.step`` and its masked resets; with a paired baseline
  half of its copies are the twins), the base controller's command, the adapter's per-copy infos, and the
  SB3 wrappers around them (residual, frame stack, monitor, reward normalisation) as the rest of
  ``VecEnv.step``;
* rollout, SB3 bookkeeping: the rest of ``collect_rollouts`` (tensor conversions, buffer, callbacks, GAE);
* train: ``evaluate_actions`` (forward), ``backward``, Adam's ``step``, and the rest of ``PPO.train``
  (minibatch sampling, losses, clipping, logging).

Usage::

    python scripts/rl_profile.py --base lqg --steps 300000                       # the shipped model's LQG
    python scripts/rl_profile.py --base PD.json --steps 300000 --settings '{"n_envs": 8}'
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from collections import defaultdict
from pathlib import Path


class _Timers:
    """Accumulated wall time per part, nested parts subtracted from their parents."""

    def __init__(self):
        self.total = defaultdict(float)
        self._stack = []

    def wrap(self, owner, name: str, part: str) -> None:
        original = getattr(owner, name)
        timers = self

        def timed(*args, **kwargs):
            timers._stack.append(0.0)
            t0 = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                spent = time.perf_counter() - t0
                inner = timers._stack.pop()
                timers.total[part] += spent - inner
                if timers._stack:
                    timers._stack[-1] += spent

        static = isinstance(vars(owner).get(name), staticmethod)
        setattr(owner, name, staticmethod(timed) if static else timed)


PARTS = (
    ("rollout: policy forward", "ActorCriticPolicy.forward"),
    ("rollout: env physics (heli_env vector env; twins included)", None),
    ("rollout: base controller command", None),
    ("rollout: adapter per-copy infos", None),
    ("rollout: adapter rest (resets, window draws)", None),
    ("rollout: SB3 VecEnv wrappers (residual, frame stack, monitor, normalise)", None),
    ("rollout: SB3 bookkeeping (tensors, buffer, callbacks, GAE)", None),
    ("train: forward (evaluate_actions)", None),
    ("train: backward", None),
    ("train: Adam step", None),
    ("train: rest (minibatches, losses, clipping, logging)", None),
)


def _instrument(timers: _Timers) -> None:
    import torch
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.vec_env.base_vec_env import VecEnv
    from stable_baselines3.ppo import PPO

    from controllers.rl import residual_agent, vec_env
    from heli_env.vector_env import HeliAttitudeVectorEnv

    names = [p for p, _ in PARTS]
    timers.wrap(OnPolicyAlgorithm, "collect_rollouts", names[6])
    timers.wrap(VecEnv, "step", names[5])
    timers.wrap(ActorCriticPolicy, "forward", names[0])
    timers.wrap(vec_env.GymnasiumVecEnv, "step_wait", names[4])
    timers.wrap(vec_env.GymnasiumVecEnv, "_split_infos", names[3])
    timers.wrap(HeliAttitudeVectorEnv, "step", names[1])
    timers.wrap(HeliAttitudeVectorEnv, "reset", names[1])
    timers.wrap(residual_agent, "base_step", names[2])
    timers.wrap(PPO, "train", names[10])
    timers.wrap(ActorCriticPolicy, "evaluate_actions", names[7])
    timers.wrap(torch.Tensor, "backward", names[8])
    timers.wrap(torch.optim.Adam, "step", names[9])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", default="lqg", help="the residual's base: 'lqg' (the shipped model's LQG baseline, "
                    "designed here) or a PD/LQG controller JSON (default lqg)")
    ap.add_argument("--steps", type=int, default=300_000, help="environment steps (default 300000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--settings", default="{}", help="TrainConfig fields as JSON, e.g. '{\"n_envs\": 8}'")
    args = ap.parse_args(argv)
    from controllers.rl import train_agent
    from heli_env import load_env_model

    model = load_env_model()
    if args.base == "lqg":
        from controllers.lqg.design import design_lqg

        base = design_lqg(model).controller()
    else:
        base = args.base
    settings = {"eval_freq": 0, "checkpoint_freq": 0, **json.loads(args.settings)}
    timers = _Timers()
    _instrument(timers)
    from stable_baselines3.common.callbacks import BaseCallback

    class Clock(BaseCallback):
        def _on_training_start(self):  # what the set-up spent (the base flown, the first resets) is not learn's
            timers.total.clear()
            self.t0, self.c0 = time.perf_counter(), time.process_time()

        def _on_step(self):
            return True

        def _on_training_end(self):
            self.wall, self.cpu = time.perf_counter() - self.t0, time.process_time() - self.c0

    clock = Clock()
    with tempfile.TemporaryDirectory() as tmp:
        res = train_agent("ppo", model, args.steps, Path(tmp) / "agent", residual=base, seed=args.seed,
                          progress=False, callbacks=[clock], **settings)
    print(f"Command: python scripts/rl_profile.py --base {args.base} --steps {args.steps} --seed {args.seed}"
          f" --settings '{args.settings}'\n")
    print(f"{res.timesteps} steps; learn: {clock.wall:.1f} s wall ({res.timesteps / clock.wall:.0f} steps/s), "
          f"{clock.cpu:.1f} s CPU ({res.timesteps / clock.cpu:.0f} steps per CPU second)\n")
    print("| part | share of learn's wall time | µs per env step |")
    print("|---|---|---|")
    counted = 0.0
    for part, _ in PARTS:
        t = timers.total.get(part, 0.0)
        counted += t
        print(f"| {part} | {100 * t / clock.wall:.1f} % | {1e6 * t / res.timesteps:.1f} |")
    rest = clock.wall - counted
    print(f"| outside these (callbacks' own, learn's loop) | {100 * rest / clock.wall:.1f} % "
          f"| {1e6 * rest / res.timesteps:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
