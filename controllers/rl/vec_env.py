"""A Gymnasium vector environment seen through stable-baselines3's ``VecEnv`` API.

SB3 (2.x) trains on its own ``VecEnv`` and does not take a
:class:`gymnasium.vector.VectorEnv`. The two differ in three ways, which
:class:`GymnasiumVecEnv` bridges:

* **Reset timing.** The native env (:class:`heli_env.vector_env.HeliAttitudeVectorEnv`)
  autoresets ``NEXT_STEP``: the step that ends an episode returns its last
  observation, and the *next* step resets the copy (reward 0, action ignored).
  SB3 expects a *same-step* reset: the step that ends an episode returns
  ``done=True`` with the first observation of the next episode, and the last
  observation in ``infos[i]["terminal_observation"]``. The adapter resets the
  finished copies itself with ``reset(options={"reset_mask": ...})`` right after
  the step, so the native autoreset never fires and no step is wasted.
* **Truncation.** ``terminated``/``truncated`` become SB3's ``dones`` and
  ``infos[i]["TimeLimit.truncated"]`` (truncated and not terminated), which PPO
  and SAC use to bootstrap the value of time-limited episodes.
* **Infos.** Gymnasium's dict of arrays (with ``_name`` masks) becomes SB3's
  list of per-copy dicts.

Per-episode reset options (a pinned gust window, :mod:`controllers.trace_split`)
come from ``episode_options(i, rng)``, called for copy ``i`` at every reset with
the adapter's own random generator, seeded with the environments.

With ``twins=True`` the second half of the copies mirrors the first: copy ``h + i``
(``h`` = half the copies) gets copy ``i``'s seed and episode options and ends and
restarts with it, so the two meet the same gusts, start from the same state and read
the same sensor noise. What differs between them is only what they are told to do:
:func:`controllers.rl.residual_agent.residual_env` flies the base PD alone on the twin
and rewards the residual for the difference (a paired baseline).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv


class GymnasiumVecEnv(VecEnv):
    """SB3 ``VecEnv`` over a Gymnasium ``VectorEnv`` with ``NEXT_STEP`` autoreset and ``reset_mask``.

    Parameters
    ----------
    env : gymnasium.vector.VectorEnv
        Must autoreset ``NEXT_STEP`` and accept ``reset(options={"reset_mask": mask})``
        (as :class:`heli_env.vector_env.HeliAttitudeVectorEnv`).
    episode_options : callable, optional
        ``episode_options(i, rng) -> dict`` of reset options for copy ``i``'s next
        episode (e.g. ``{"trace": 2, "offset": 1234}``), drawn from ``rng``, the
        adapter's ``numpy.random.Generator``.
    fixed_seed : int, optional
        Every :meth:`reset` reseeds the environments and ``rng`` with this seed, so
        every call replays the same episodes (evaluation environments).
    twins : bool
        Copies ``h .. 2h - 1`` mirror copies ``0 .. h - 1`` (seeds, episode options, episode
        ends); needs an even number of copies. A copy whose twin's episode ended is ended
        with it (``TimeLimit.truncated`` unless it terminated itself).
    """

    def __init__(self, env, episode_options: Callable[[int, np.random.Generator], dict] | None = None,
                 fixed_seed: int | None = None, twins: bool = False):
        mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        if mode != AutoresetMode.NEXT_STEP:
            raise ValueError(f"GymnasiumVecEnv needs a NEXT_STEP autoreset vector env, got {mode}")
        if twins and env.num_envs % 2:
            raise ValueError(f"twins need an even number of copies, got {env.num_envs}")
        self.twins = bool(twins)
        self._twin_options = {}
        self.env = env
        self.episode_options = episode_options
        self.fixed_seed = fixed_seed
        self._rng = np.random.default_rng(fixed_seed)
        self._obs = None
        self._actions = None
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)

    # ------------------------------------------------------------------ reset
    def reset(self):
        n = self.num_envs
        seeds = self._seeds
        if self.fixed_seed is not None:
            seeds = [self.fixed_seed + i for i in range(n)]
        seed = None if seeds[0] is None else [int(s) for s in seeds]
        if seed is not None and self.twins:
            seed = seed[:n // 2] * 2
        if seed is not None:
            self._rng = np.random.default_rng(seed[0])
        options = self._options
        if self.episode_options is None and all(o == options[0] for o in options):
            obs, info = self.env.reset(seed=seed, options=dict(options[0]) or None)
            self.reset_infos = self._split_infos(info, range(n))
        else:
            obs, info = self.env.reset(seed=seed)
            obs = self._reset_copies(np.arange(n), obs, per_copy=options)
        self._reset_seeds()
        self._reset_options()
        self._obs = obs
        return obs.copy()

    def _reset_copies(self, which, obs, per_copy=None):
        """Reset copies ``which`` (one masked reset per copy when options differ); returns the observations."""
        n = self.num_envs
        if self.episode_options is None and not per_copy:
            mask = np.zeros(n, dtype=bool)
            mask[which] = True
            obs, info = self.env.reset(options={"reset_mask": mask})
            for i, d in zip(which, self._split_infos(info, which)):
                self.reset_infos[i] = d
            return obs
        for i in which:  # ascending: a copy resets before its twin
            mask = np.zeros(n, dtype=bool)
            mask[i] = True
            j = int(i) - n // 2 if self.twins and i >= n // 2 else int(i)  # the copy whose options it takes
            opts = dict(per_copy[j]) if per_copy else {}
            if j != i:
                opts = self._twin_options.pop(j, opts)
            elif self.episode_options is not None:
                opts.update(self.episode_options(int(i), self._rng))
                if self.twins:
                    self._twin_options[int(i)] = opts
            new_obs, info = self.env.reset(options={"reset_mask": mask, **opts})
            obs = obs.copy()
            obs[i] = new_obs[i]
            self.reset_infos[i] = self._split_infos(info, [i])[0]
        return obs

    # ------------------------------------------------------------------- step
    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rew, terminated, truncated, info = self.env.step(self._actions)
        dones = np.logical_or(terminated, truncated)
        if self.twins:  # a copy ends with its twin
            half = dones[:self.num_envs // 2] | dones[self.num_envs // 2:]
            truncated = np.logical_or(truncated, np.concatenate([half, half]) & ~dones)
            dones = np.concatenate([half, half])
        infos = self._split_infos(info, range(self.num_envs))
        for d, flag in zip(infos, (np.asarray(truncated, dtype=bool) & ~np.asarray(terminated, dtype=bool)).tolist()):
            d["TimeLimit.truncated"] = flag
        if dones.any():
            which = np.flatnonzero(dones)
            for i in which:
                infos[i]["terminal_observation"] = obs[i].copy()
            obs = self._reset_copies(which, obs)
        self._obs = obs
        return obs.copy(), np.asarray(rew, dtype=np.float32), dones, infos

    @staticmethod
    def _split_infos(info: dict, which) -> list[dict[str, Any]]:
        """Gymnasium's vector info (dict of arrays with ``_name`` masks) as one dict per copy in ``which``.

        Column by column (one ``tolist`` per key rather than one ``item`` per key and copy): at 8 copies the
        per-copy form took more of a training step than the physics did.
        """
        rows = np.fromiter(which, dtype=np.intp)
        out = [{} for _ in range(rows.size)]
        for k, v in info.items():
            if k.startswith("_"):
                continue
            if isinstance(v, np.ndarray):
                values = list(v[rows]) if v.ndim > 1 else v[rows].tolist()  # rows: copies, not views
            else:
                values = [v] * rows.size
            mask = info.get("_" + k)
            if mask is None:
                for d, value in zip(out, values):
                    d[k] = value
            else:
                for d, value, present in zip(out, values, np.asarray(mask)[rows].tolist()):
                    if present:
                        d[k] = value
        return out

    # --------------------------------------------------------------- plumbing
    def close(self) -> None:
        self.env.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        """The vector env's attribute, once per copy (the copies share one object)."""
        value = getattr(self.env, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.env, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        result = getattr(self.env, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self):
        return [self.env.render()] + [None] * (self.num_envs - 1)


class ConcatVecEnv(VecEnv):
    """Several SB3 ``VecEnv`` with the same spaces seen as one: the first's copies, then the second's, ...

    Used to train on several aircraft at once (:attr:`controllers.rl.config.TrainConfig.delay_spread`:
    one group of copies per servo delay), each group a whole SB3 ``VecEnv`` with its own wrappers (a
    paired residual's twins stay within their group). Seeds and reset options go to the group that holds
    each copy: ``seed(s)`` seeds copy ``i`` of the whole with ``s + i``, as one ``VecEnv`` would.
    """

    def __init__(self, envs):
        self.envs = list(envs)
        if not self.envs:
            raise ValueError("ConcatVecEnv needs at least one VecEnv")
        first = self.envs[0]
        for e in self.envs[1:]:
            if e.observation_space != first.observation_space or e.action_space != first.action_space:
                raise ValueError("ConcatVecEnv: every VecEnv must have the first one's observation and action spaces")
        ends = np.cumsum([e.num_envs for e in self.envs])
        self._slices = [slice(int(stop - e.num_envs), int(stop)) for e, stop in zip(self.envs, ends)]
        super().__init__(int(ends[-1]), first.observation_space, first.action_space)

    def _where(self, indices) -> list[tuple[int, int]]:
        """(group, index within it) of each of ``indices`` (all copies for None)."""
        out = []
        for i in self._get_indices(indices):
            k = next(k for k, s in enumerate(self._slices) if s.start <= i < s.stop)
            out.append((k, i - self._slices[k].start))
        return out

    def seed(self, seed: int | None = None):
        base = super().seed(seed)[0]  # SB3's own: the given base, or a random one for None
        return [s for e, part in zip(self.envs, self._slices) for s in e.seed(base + part.start)]

    def set_options(self, options=None) -> None:
        per_copy = options if isinstance(options, list) else [options] * self.num_envs
        for e, part in zip(self.envs, self._slices):
            e.set_options(per_copy[part])

    def reset(self):
        obs = np.concatenate([e.reset() for e in self.envs])
        self.reset_infos = [d for e in self.envs for d in e.reset_infos]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        for e, part in zip(self.envs, self._slices):
            e.step_async(actions[part])

    def step_wait(self):
        results = [e.step_wait() for e in self.envs]
        return (np.concatenate([r[0] for r in results]), np.concatenate([r[1] for r in results]),
                np.concatenate([r[2] for r in results]), [info for r in results for info in r[3]])

    def close(self) -> None:
        for e in self.envs:
            e.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [self.envs[k].get_attr(attr_name, [j])[0] for k, j in self._where(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        for k, j in self._where(indices):
            self.envs[k].set_attr(attr_name, value, [j])

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        return [self.envs[k].env_method(method_name, *method_args, indices=[j], **method_kwargs)[0]
                for k, j in self._where(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [self.envs[k].env_is_wrapped(wrapper_class, [j])[0] for k, j in self._where(indices)]
