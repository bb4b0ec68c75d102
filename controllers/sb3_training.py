"""stable-baselines3 pieces of RL training: observation scaling, progress, time budget, atomic checkpoints
and evaluations.

Imported by :mod:`controllers.rl` only when an agent is trained or loaded
(stable-baselines3 and torch are the ``rl`` extra). Agents saved by
:func:`controllers.rl.train_agent` refer to :class:`ObservationScaler` by this
module's path, so it must stay importable under this name.
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from heli_core.files import atomic_path

OBS_SCALE = np.array([math.radians(10.0)] * 3 + [math.radians(30.0)] * 6 + [1.0] * 3, dtype=np.float32)
"""Typical size of each observation of ``HeliAttitude-v0`` (attitude error 10°, rates and rate errors
30°/s, previous action 1 stick): the reward's own scales (:class:`heli_env.tasks.TaskConfig`)."""


class ObservationScaler(BaseFeaturesExtractor):
    """Divides the observation by fixed scales (:data:`OBS_SCALE`) before the policy's MLP.

    Attitude errors of a few hundredths of a radian would otherwise reach the
    network's first layer as near-zero inputs. The scaling lives in the policy,
    so a saved agent's ``predict`` takes the environment's raw observation (as a
    PD controller's does) and no normalisation statistics travel beside it.

    Parameters
    ----------
    observation_space : gymnasium.spaces.Box, shape (12,)
    scale : sequence of 12 float, optional
        Default :data:`OBS_SCALE`.
    """

    def __init__(self, observation_space: gym.spaces.Box, scale=None):
        n = int(np.prod(observation_space.shape))
        super().__init__(observation_space, features_dim=n)
        s = OBS_SCALE if scale is None else np.asarray(scale, dtype=np.float32)
        if s.shape != (n,) or not np.all(s > 0):
            raise ValueError(f"scale must be {n} positive numbers, got {scale!r}")
        self.register_buffer("inv_scale", torch.as_tensor(1.0 / s, dtype=torch.float32))

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return observations.flatten(1) * self.inv_scale


class ProgressBar(BaseCallback):
    """tqdm bar of timesteps on stderr (SB3's own ``progress_bar=True`` needs ``rich`` as well).

    Shows the last evaluation's mean return when an ``EvalCallback`` is given.
    Silent when ``show`` is False or stderr is not a terminal.
    """

    def __init__(self, total: int, show: bool = True, eval_callback=None, desc: str = "train"):
        super().__init__()
        self.total, self.show, self.eval_callback, self.desc = int(total), bool(show), eval_callback, desc
        self.bar = None
        self._last_eval = None

    def _on_training_start(self) -> None:
        from tqdm import tqdm

        self.bar = tqdm(total=self.total, desc=self.desc, unit="step", unit_scale=True, dynamic_ncols=True,
                        file=sys.stderr, disable=not self.show or not sys.stderr.isatty())

    def _on_step(self) -> bool:
        self.bar.update(self.training_env.num_envs)
        ev = self.eval_callback
        if ev is not None and ev.evaluations_timesteps and ev.evaluations_timesteps[-1] != self._last_eval:
            self._last_eval = ev.evaluations_timesteps[-1]
            self.bar.set_postfix(eval_return=f"{ev.last_mean_reward:.1f}", best=f"{ev.best_mean_reward:.1f}")
        return True

    def _on_training_end(self) -> None:
        self.close()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class WallClockLimit(BaseCallback):
    """Stops training once ``seconds`` of wall time have passed since training started."""

    def __init__(self, seconds: float):
        super().__init__()
        if not (seconds > 0 and math.isfinite(seconds)):
            raise ValueError(f"the time budget must be a positive number of seconds, got {seconds!r}")
        self.seconds = float(seconds)
        self.reached = False
        self._t0 = None

    def _on_training_start(self) -> None:
        self._t0 = time.perf_counter()

    def _on_step(self) -> bool:
        if time.perf_counter() - self._t0 >= self.seconds:
            self.reached = True
            return False
        return True


def save_atomically(model, path, metadata: dict | None = None) -> Path:
    """``model.save`` to a temporary file beside ``path``, then moved over it (never a half-written zip).

    ``metadata`` is added to the zip as ``heli_agent.json`` (SB3's loader ignores it;
    :func:`controllers.rl.load_agent` reads it).
    """
    import json
    import zipfile

    path = Path(path)
    with atomic_path(path, suffix=".zip") as tmp:
        model.save(tmp)
        if metadata is not None:
            with zipfile.ZipFile(tmp, "a") as z:
                z.writestr("heli_agent.json", json.dumps(metadata, indent=1, allow_nan=False))
    return path


class AtomicCheckpoint(BaseCallback):
    """Saves the model every ``every`` timesteps to ``folder/{prefix}_{timesteps}_steps.zip``, atomically.

    SB3's ``CheckpointCallback`` writes the zip in place; interrupted mid-write it
    would leave a corrupt last checkpoint. ``paths`` lists what was written.
    """

    def __init__(self, every: int, folder, prefix: str = "agent", metadata: dict | None = None):
        super().__init__()
        if int(every) < 1:
            raise ValueError(f"checkpoint frequency must be >= 1 timestep, got {every!r}")
        self.every, self.folder, self.prefix, self.metadata = int(every), Path(folder), prefix, metadata
        self.paths: list[Path] = []
        self._next = self.every

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self.save()
            while self._next <= self.num_timesteps:
                self._next += self.every
        return True

    def save(self, tag: str = "") -> Path:
        path = self.folder / f"{self.prefix}{tag}_{self.model.num_timesteps}_steps.zip"
        save_atomically(self.model, path, self.metadata)
        self.paths.append(path)
        return path


class SaveBest(BaseCallback):
    """``callback_on_new_best`` of an ``EvalCallback``: saves the model to ``path`` atomically."""

    def __init__(self, path, metadata: dict | None = None):
        super().__init__()
        self.path, self.metadata = Path(path), metadata

    def _on_step(self) -> bool:
        save_atomically(self.model, self.path, self.metadata)
        return True


class AtomicEvalCallback(EvalCallback):
    """SB3's ``EvalCallback`` writing ``folder/best_model.zip`` and ``folder/evaluations.npz`` atomically.

    SB3 saves both in place (``model.save``, ``np.savez``), so an interrupt mid-write
    would leave them corrupt. Here the best model goes through :func:`save_atomically`
    (with ``metadata`` as ``heli_agent.json``), and SB3's ``np.savez`` of the
    evaluations is pointed at a temporary file in ``folder`` that is moved over
    ``evaluations.npz`` once complete. The files' names and the npz's arrays
    (``timesteps``, ``results``, ``ep_lengths``) are SB3's. SB3 fills
    ``evaluations_timesteps`` / ``evaluations_results`` / ``evaluations_length`` only
    when it has a log path, hence the redirection rather than ``log_path=None``.

    Parameters
    ----------
    eval_env : VecEnv
    folder : str or Path
        Where the two files go.
    metadata : dict, optional
        Added to the best model's zip.
    **kwargs
        Further ``EvalCallback`` arguments (not ``log_path``, ``best_model_save_path``
        or ``callback_on_new_best``).
    """

    def __init__(self, eval_env, folder, metadata: dict | None = None, **kwargs):
        folder = Path(folder)
        super().__init__(eval_env, callback_on_new_best=SaveBest(folder / "best_model.zip", metadata),
                         log_path=str(folder), best_model_save_path=None, **kwargs)
        self.npz_path = folder / "evaluations.npz"
        self.log_path = str(folder / f".evaluations.npz.{os.getpid()}.tmp")  # np.savez appends ".npz"
        self._tmp = Path(self.log_path + ".npz")

    def _on_step(self) -> bool:
        n = len(self.evaluations_timesteps)
        try:
            go_on = super()._on_step()
        except BaseException:
            if len(self.evaluations_timesteps) > n:  # np.savez may have been cut short
                self._tmp.unlink(missing_ok=True)
            raise
        if len(self.evaluations_timesteps) > n:
            with open(self._tmp, "rb+") as fh:
                os.fsync(fh.fileno())
            os.replace(self._tmp, self.npz_path)
        return go_on
