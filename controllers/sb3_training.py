"""stable-baselines3 pieces of RL training: observation scaling and normalisation, progress, time budget,
atomic checkpoints and evaluations, the learning curve.

Imported by :mod:`controllers.rl` only when an agent is trained or loaded
(stable-baselines3 and torch are the ``rl`` extra). Agents saved by
:func:`controllers.rl.train_agent` refer to :class:`ObservationScaler` (or
:class:`ObservationNormalizer`) by this module's path, so they must stay importable under these names.
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


class ObservationNormalizer(ObservationScaler):
    """Standardises the observation by running statistics of the training rollouts, inside the policy.

    What SB3's ``VecNormalize(norm_obs=True)`` does outside it: ``clip((obs - mean) / sqrt(var + 1e-8),
    -clip, clip)``, with ``mean`` and ``var`` merged over every observation the training copies
    produced (:class:`ObservationStatistics` feeds them in at the end of each rollout, the held-out
    evaluations never). The statistics are buffers of the policy, so the saved agent's ``predict``
    takes the environment's raw observation and nothing travels beside it. Before the first update
    it is the :class:`ObservationScaler` of the same ``scale`` (mean 0, var ``scale``²).

    Parameters
    ----------
    observation_space : gymnasium.spaces.Box
    scale : sequence of float, optional
        The starting standard deviations (default :data:`OBS_SCALE`).
    clip : float
        Bound of the standardised observation, > 0 (SB3's default 10).
    """

    def __init__(self, observation_space: gym.spaces.Box, scale=None, clip: float = 10.0):
        super().__init__(observation_space, scale)
        if not (isinstance(clip, (int, float)) and clip > 0 and math.isfinite(clip)):
            raise ValueError(f"clip must be a positive number, got {clip!r}")
        self.clip = float(clip)
        inv = self.inv_scale.double()
        self.register_buffer("mean", torch.zeros_like(inv))
        self.register_buffer("var", 1.0 / inv ** 2)
        self.register_buffer("count", torch.tensor(1e-4, dtype=torch.float64))  # RunningMeanStd's start
        self._set_inverse()

    def _set_inverse(self) -> None:
        self.inv_scale.copy_((1.0 / torch.sqrt(self.var + 1e-8)).float())

    def update(self, observations: np.ndarray) -> None:
        """Merge a batch of raw observations, shape (n, *observation shape), into the statistics."""
        from stable_baselines3.common.running_mean_std import RunningMeanStd

        batch = np.asarray(observations, dtype=np.float64).reshape(len(observations), -1)
        rms = RunningMeanStd(shape=self.mean.shape)
        rms.mean, rms.var, rms.count = self.mean.numpy().copy(), self.var.numpy().copy(), float(self.count)
        rms.update(batch)
        with torch.no_grad():
            self.mean.copy_(torch.as_tensor(rms.mean))
            self.var.copy_(torch.as_tensor(rms.var))
            self.count.fill_(rms.count)
            self._set_inverse()

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        centred = observations.flatten(1) - self.mean.float()
        return torch.clamp(centred * self.inv_scale, -self.clip, self.clip)


class ObservationStatistics(BaseCallback):
    """Feeds the observations of each training rollout to the policy's :class:`ObservationNormalizer` modules.

    Observations are gathered step by step (``new_obs`` of the training copies) and merged at the
    rollout's end, so that the statistics stay fixed while a rollout is collected.
    """

    def __init__(self):
        super().__init__()
        self._batch = []

    def _on_step(self) -> bool:
        self._batch.append(np.array(self.locals["new_obs"], dtype=np.float64, copy=True))
        return True

    def _on_rollout_end(self) -> None:
        if not self._batch:
            return
        batch = np.concatenate(self._batch)
        self._batch = []
        for module in self.model.policy.modules():
            if isinstance(module, ObservationNormalizer):
                module.update(batch)


class ProgressBar(BaseCallback):
    """tqdm bar of timesteps on stderr (SB3's own ``progress_bar=True`` needs ``rich`` as well).

    Shows the last evaluation's mean return when an ``EvalCallback`` is given.
    Silent when ``show`` is False or stderr is not a terminal.
    """

    def __init__(self, total: int | None, show: bool = True, eval_callback=None, desc: str = "train"):
        super().__init__()
        # total None: no step count to reach (a time budget stops the run), the bar counts steps and their rate
        self.total = None if total is None else int(total)
        self.show, self.eval_callback, self.desc = bool(show), eval_callback, desc
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


class CurriculumProgress(BaseCallback):
    """Tells a :class:`controllers.trace_split.GustCurriculum` the timesteps taken, at every step."""

    def __init__(self, curriculum):
        super().__init__()
        self.curriculum = curriculum

    def _on_step(self) -> bool:
        self.curriculum.timesteps = self.num_timesteps
        return True


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
        self.evaluations_p90: list[list[float]] = []  # per evaluation: p90 |attitude error| roll, pitch, yaw [deg]
        self._errors: list = []

    def _log_success_callback(self, locals_: dict, globals_: dict) -> None:
        """SB3's per-step hook of ``evaluate_policy`` (episodes still counted): keeps each step's |attitude error|."""
        super()._log_success_callback(locals_, globals_)
        err = locals_["info"].get("attitude_error_deg")
        if err is not None:
            self._errors.append(np.abs(np.asarray(err, dtype=np.float64)).reshape(3))

    def _on_step(self) -> bool:
        n = len(self.evaluations_timesteps)
        self._errors = []
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
            errors = np.array(self._errors) if self._errors else np.full((1, 3), np.nan)
            self.evaluations_p90.append([float(v) for v in np.percentile(errors, 90, axis=0)])
        return go_on


class LearningCurve(BaseCallback):
    """Records the learning curve: every training episode's return, and each held-out evaluation's mean
    return and p90 |attitude error| per axis, against the timesteps taken.

    Episode returns are read from the ``"episode"`` entry SB3's ``VecMonitor`` adds to a finished episode's
    info (the raw return, before any reward normalisation); evaluations from the run's
    :class:`AtomicEvalCallback` (``evaluation``; None: none). :meth:`record` is what ``training.json``
    keeps under ``"learning_curve"``; it holds no wall time, so the same seed gives the same record.

    Parameters
    ----------
    evaluation : AtomicEvalCallback, optional
    """

    def __init__(self, evaluation=None):
        super().__init__()
        self.evaluation = evaluation
        self.episodes: list[tuple[int, float]] = []

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", ()):
            episode = info.get("episode")
            if episode is not None:
                self.episodes.append((int(self.num_timesteps), float(episode["r"])))
        return True

    def record(self) -> dict:
        """``{"episodes": [[timesteps, return], ...], "evaluations": [{"timesteps", "mean_return", "p90_deg"}]}``;
        ``p90_deg`` lists roll, pitch, yaw [deg]."""
        evaluations = []
        ev = self.evaluation
        if ev is not None:
            for t, r, p90 in zip(ev.evaluations_timesteps, ev.evaluations_results, ev.evaluations_p90):
                evaluations.append({"timesteps": int(t), "mean_return": float(np.mean(r)), "p90_deg": list(p90)})
        return {"episodes": [[t, r] for t, r in self.episodes], "evaluations": evaluations}
