"""Training an RL attitude agent with stable-baselines3 on the vector env: settings, checkpoints, record.

:func:`train_agent` trains PPO or SAC on the native vector environment
(:class:`heli_env.vector_env.HeliAttitudeVectorEnv`) seen through SB3's
``VecEnv`` API (:class:`controllers.rl.vec_env.GymnasiumVecEnv`). Episodes
replay gust windows of the *training* traces only (:func:`split_traces`); an
``EvalCallback`` scores the deterministic policy on fixed windows of the
*held-out* traces during training. Every file below is written atomically
(checkpoints, best model and evaluation log included), and an interrupt (Ctrl-C)
saves one more checkpoint before it propagates
(:class:`controllers.errors.TrainingInterrupted`).

Files written for ``out="agents/ppo"``::

    agents/ppo.zip                      the final agent (SB3 zip + heli_agent.json: algo, split, settings)
    agents/ppo_training/training.json   settings, timing, evaluation history, checkpoints
    agents/ppo_training/best_model.zip  the best agent on the held-out evaluations (+ heli_agent.json)
    agents/ppo_training/evaluations.npz SB3's evaluation log (timesteps, results, ep_lengths)
    agents/ppo_training/checkpoints/ppo_<timesteps>_steps.zip

The final agent, not the best one, is what a comparison should use: the best
was chosen on the held-out traces it would be compared on.

With ``residual=`` a PD controller, the agent learns a bounded correction on top
of that PD rather than the whole law (:mod:`controllers.rl.residual`); the zip then
carries the PD and :func:`load_agent` returns the combined agent.

Reproducibility: one ``seed`` seeds Python, numpy and torch
(``set_random_seed``), the network initialisation, the environments (copy
``i`` gets ``seed + i``) and the draw of gust windows, so the same seed, library,
settings and torch thread count give the same agent (checked by the tests on
CPU).

stable-baselines3 and torch are the ``rl`` extra, imported when needed.
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from heli_core.files import jsonable, write_text

from ..errors import AgentError, TrainingInterrupted
from ..trace_split import WindowSampler, as_segments, split_traces
from .agent_file import AGENT_SCHEMA, AGENT_SCHEMA_VERSION, ALGOS, _algo_class, _sb3
from .residual import RESIDUAL_INIT_DEG, RESIDUAL_SCALE, residual_metadata

DEFAULT_KWARGS = {
    # A rollout of 512 steps x 8 copies (41 s of flight), a 1 s horizon (gamma 0.99 at 100 Hz),
    # an initial action noise of std 0.37 stick (log std -1) rather than SB3's 1.
    "ppo": {"n_steps": 512, "batch_size": 256, "n_epochs": 10, "learning_rate": 3e-4, "gamma": 0.99,
            "gae_lambda": 0.95, "clip_range": 0.2, "ent_coef": 0.0,
            "policy_kwargs": {"net_arch": [64, 64], "log_std_init": -1.0}},
    # One gradient step per vector step (8 transitions); small networks for a 12-dimensional state.
    "sac": {"buffer_size": 200_000, "learning_starts": 2_000, "batch_size": 256, "learning_rate": 3e-4,
            "gamma": 0.99, "tau": 0.005, "train_freq": 1, "gradient_steps": 1,
            "policy_kwargs": {"net_arch": [64, 64]}},
}
"""Hyperparameters :func:`train_agent` starts from; ``algo_kwargs`` override them (``policy_kwargs`` merged)."""



def _out_paths(out) -> tuple[Path, Path, str]:
    """(agent zip, run folder, name) for ``out`` ("agents/ppo" or "agents/ppo.zip")."""
    out = Path(out)
    stem = out.with_suffix("") if out.suffix == ".zip" else out
    return stem.with_name(stem.name + ".zip"), stem.with_name(stem.name + "_training"), stem.name


@dataclass(eq=False)
class TrainingResult:
    """What :func:`train_agent` did.

    Attributes
    ----------
    path : Path
        The final agent (zip).
    algo : str
    timesteps : int
        Environment steps taken (all copies).
    seconds : float
        Wall time of ``learn`` [s].
    stopped_by_time : bool
        The time budget ended training before ``timesteps`` were reached.
    run_dir : Path
        Folder of the training record, SB3's training statistics (``progress.csv``),
        best model, evaluations and checkpoints.
    checkpoints : list of Path
    best_model : Path or None
    evaluations : list of (timesteps, mean return, std return)
        Held-out evaluations during training.
    metadata : dict
        What the agent's zip carries in ``heli_agent.json``.
    agent : PPO or SAC
        The trained model (the one saved at ``path``).
    """

    path: Path
    algo: str
    timesteps: int
    seconds: float
    stopped_by_time: bool
    run_dir: Path
    checkpoints: list = field(default_factory=list)
    best_model: Path | None = None
    evaluations: list = field(default_factory=list)
    metadata: dict = field(default_factory=dict)
    agent: object = field(default=None, repr=False)

    @property
    def steps_per_second(self) -> float:
        return self.timesteps / self.seconds if self.seconds > 0 else math.nan


def _check_count(value, name, minimum=1):
    whole = isinstance(value, numbers.Integral) or (isinstance(value, float) and value.is_integer())
    if isinstance(value, bool) or not whole or value < minimum:
        raise AgentError(f"{name} must be a whole number >= {minimum}, got {value!r}")
    return int(value)


def train_agent(algo: str = "ppo", model=None, timesteps: int = 200_000, out="agent", seed: int = 0,
                n_envs: int = 8, eval_freq: int = 50_000, checkpoint_freq: int = 100_000, progress: bool = True,
                train_traces=None, eval_traces=None, held_out_fraction: float = 0.25, split_seed: int = 0,
                eval_episodes: int = 4, episode_seconds: float = 30.0, task="hold", max_seconds: float | None = None,
                algo_kwargs: dict | None = None, normalize_reward: bool | None = None, callbacks=(),
                torch_threads: int | None = 1, verbose: int = 0, residual=None,
                residual_scale: float = RESIDUAL_SCALE, init_angle_deg: float | None = None,
                init_rate_deg: float | None = None) -> TrainingResult:
    """Train a PPO or SAC attitude agent on the training traces of a model's disturbance library.

    Parameters
    ----------
    algo : {"ppo", "sac"}
    model : str, Path, EnvModel or None
        Model directory written by ``heli identify`` (None: the shipped model).
    timesteps : int
        Environment steps to train for (summed over the copies).
    out : str or Path
        The agent's path; ``.zip`` is added. The run folder is ``<out>_training/``.
    seed : int
        Seeds everything (see the module docstring).
    n_envs : int
        Environment copies stepped as one batch.
    eval_freq : int
        Timesteps between held-out evaluations (0: none).
    checkpoint_freq : int
        Timesteps between checkpoints (0: none besides the one an interrupt writes).
    progress : bool
        tqdm bar on stderr (when it is a terminal).
    train_traces, eval_traces : None, str, or sequence of int / TraceSegment
        Gust segments of training episodes and of evaluations. Default: the
        training and held-out sides of ``split_traces(n_traces, held_out_fraction, split_seed)``.
    held_out_fraction, split_seed :
        The split (:func:`split_traces`).
    eval_episodes : int
        Held-out episodes per evaluation (fixed windows, the same at every evaluation).
    episode_seconds : float
        Episode length [s].
    task : str or TaskConfig
        Environment task ("hold", "track", "rate").
    max_seconds : float, optional
        Wall-time budget of training [s]; training stops at whichever of
        ``timesteps`` and the budget comes first.
    algo_kwargs : dict, optional
        Overrides of :data:`DEFAULT_KWARGS` (``policy_kwargs`` merged key by key).
    normalize_reward : bool, optional
        Divide training rewards by a running estimate of the discounted return's
        standard deviation (SB3 ``VecNormalize(norm_obs=False)``). Default: True for PPO,
        whose value function otherwise chases returns of -1e2 to -1e5 (a spinning
        yaw costs 324 per step), False for SAC. Observations are never normalised
        (the policy scales them itself), so the saved agent needs no statistics.
    callbacks : sequence of BaseCallback
        Extra SB3 callbacks.
    torch_threads : int or None
        torch threads during training (restored after); None leaves torch's setting.
        One is fastest for these small networks: on 2 cores shared with other work,
        two threads ran PPO 20 times slower than one (thread contention), and a
        fixed count keeps results reproducible.
    verbose : int
        SB3 verbosity.
    residual : PDController or path of a PD controller JSON, optional
        Train a residual on this PD instead of a whole policy
        (:mod:`controllers.rl.residual`): the env receives
        ``clip(PD(obs) + residual_scale * action, -1, 1)``. Unless given, the task's
        reward scales, the observation scales (``policy_kwargs``'
        ``features_extractor_kwargs``) and the initial ranges follow the PD's own
        error level on the training gusts; the saved agent carries the PD and
        :func:`load_agent` returns a :class:`controllers.rl.residual.ResidualAgent`.
    residual_scale : float
        Bound of the residual [stick] (default 0.05).
    init_angle_deg, init_rate_deg : float, optional
        Initial roll/pitch range [deg] and rate range [deg/s] of training and
        evaluation episodes. Default 5 and 5 (the env's), 0.5 and 0.5 with ``residual``.

    Returns
    -------
    TrainingResult

    Raises
    ------
    AgentError
        Unknown algorithm, bad counts, split, traces, task or episode length,
        episodes longer than the gust segments, or a bad residual base or scale.
    heli_env.errors.EnvModelError
        Missing or corrupt model directory.
    TrainingInterrupted
        KeyboardInterrupt during training; a checkpoint was saved first (its path is
        ``exc.checkpoint``). It is a KeyboardInterrupt.
    """
    if algo not in ALGOS:
        raise AgentError(f"algo must be one of {ALGOS}, got {algo!r}")
    timesteps = _check_count(timesteps, "timesteps")
    n_envs = _check_count(n_envs, "n_envs")
    eval_freq = _check_count(eval_freq, "eval_freq", 0)
    checkpoint_freq = _check_count(checkpoint_freq, "checkpoint_freq", 0)
    eval_episodes = _check_count(eval_episodes, "eval_episodes")
    if torch_threads is not None:
        torch_threads = _check_count(torch_threads, "torch_threads")
    if max_seconds is not None and not (max_seconds > 0 and math.isfinite(max_seconds)):
        raise AgentError(f"max_seconds must be a positive number of seconds, got {max_seconds!r}")
    base = None
    if residual is not None:
        from .residual import as_base, check_scale

        base, residual_scale = as_base(residual), check_scale(residual_scale)
    init = RESIDUAL_INIT_DEG if base is not None else 5.0
    init = tuple(init if v is None else v for v in (init_angle_deg, init_rate_deg))
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v < 90 for v in init):
        raise AgentError(f"init_angle_deg and init_rate_deg must be numbers in [0, 90), got {init!r}")

    from heli_env.model_dir import EnvModel, load_env_model

    env_model = model if isinstance(model, EnvModel) else load_env_model(model)
    try:
        split = split_traces(env_model.n_traces, held_out_fraction, split_seed)
        train_seg = as_segments(train_traces, split, "train")
        eval_seg = as_segments(eval_traces, split, "held-out")
    except ValueError as e:
        raise AgentError(str(e)) from e

    _sb3()
    import torch

    path, run_dir, name = _out_paths(out)
    threads_before = torch.get_num_threads()
    if torch_threads is not None:
        torch.set_num_threads(torch_threads)
    try:
        return _train(algo, env_model, timesteps, path, run_dir, name, seed, n_envs, eval_freq, checkpoint_freq,
                      progress, split, train_seg, eval_seg, eval_episodes, episode_seconds, task, max_seconds,
                      algo_kwargs, algo == "ppo" if normalize_reward is None else bool(normalize_reward), callbacks,
                      verbose, (base, residual_scale), init)
    finally:
        torch.set_num_threads(threads_before)


def _train(algo, env_model, timesteps, path, run_dir, name, seed, n_envs, eval_freq, checkpoint_freq, progress,
           split, train_seg, eval_seg, eval_episodes, episode_seconds, task, max_seconds, algo_kwargs,
           normalize_reward, callbacks, verbose, residual, init) -> TrainingResult:
    sb3 = _sb3()
    from stable_baselines3.common.callbacks import CallbackList
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from heli_env.tasks import TaskConfig
    from heli_env.vector_env import HeliAttitudeVectorEnv

    from ..sb3_training import (AtomicCheckpoint, AtomicEvalCallback, ObservationScaler, ProgressBar, WallClockLimit,
                               save_atomically)
    from .vec_env import GymnasiumVecEnv

    set_random_seed(seed)
    base, residual_scale = residual
    setup = None
    if base is not None:
        from .residual import residual_env, residual_setup

        setup = residual_setup(base, env_model, train_seg, seed)
        if isinstance(task, str):
            try:
                task = TaskConfig(task=task, attitude_scale=setup["attitude_scale"], rate_scale=setup["rate_scale"])
            except ValueError as e:
                raise AgentError(str(e)) from e
    try:  # bad task or episode length; episodes longer than the gust segments
        kw = {"model": env_model, "task": task, "episode_seconds": episode_seconds, "init_angle_deg": init[0],
              "init_rate_deg": init[1]}
        venv = HeliAttitudeVectorEnv(n_envs, **kw)
        needed = venv.spec_.needed
        train_sampler = WindowSampler(env_model, train_seg, needed)
        eval_sampler = WindowSampler(env_model, eval_seg, needed)
        eval_venv = HeliAttitudeVectorEnv(eval_episodes, **kw)
    except ValueError as e:
        raise AgentError(str(e)) from e
    gamma = (algo_kwargs or {}).get("gamma", DEFAULT_KWARGS[algo]["gamma"])
    env = GymnasiumVecEnv(venv, episode_options=train_sampler)
    eval_env = GymnasiumVecEnv(eval_venv, episode_options=eval_sampler, fixed_seed=seed + 1000)
    if base is not None:
        env, eval_env = residual_env(env, base, residual_scale), residual_env(eval_env, base, residual_scale)
    env, eval_env = VecMonitor(env), VecMonitor(eval_env)  # monitors the raw returns
    if normalize_reward:  # the eval env is wrapped alike (EvalCallback syncs wrappers) but left raw
        env = VecNormalize(env, norm_obs=False, norm_reward=True, gamma=gamma)
        eval_env = VecNormalize(eval_env, training=False, norm_obs=False, norm_reward=False)

    kwargs = {k: (dict(v) if isinstance(v, dict) else v) for k, v in DEFAULT_KWARGS[algo].items()}
    for k, v in (algo_kwargs or {}).items():
        kwargs[k] = {**kwargs.get(k, {}), **v} if k == "policy_kwargs" else v
    kwargs["policy_kwargs"].setdefault("features_extractor_class", ObservationScaler)
    if setup is not None and kwargs["policy_kwargs"]["features_extractor_class"] is ObservationScaler:
        kwargs["policy_kwargs"].setdefault("features_extractor_kwargs", {"scale": setup["obs_scale"]})
    agent = _algo_class(algo)("MlpPolicy", env, seed=seed, device="cpu", verbose=verbose, **kwargs)
    # SB3's own logger would make an empty SB3-<date> folder in the system's temp folder on
    # every run; its training statistics go to the run folder instead (progress.csv).
    from stable_baselines3.common.logger import configure

    agent.set_logger(configure(str(run_dir), ["csv"] + (["stdout"] if verbose else [])))

    metadata = jsonable({
        "schema": AGENT_SCHEMA, "schema_version": AGENT_SCHEMA_VERSION, "algo": algo, "seed": seed,
        "model": str(env_model.path), "library_version": env_model.library_version,
        "trace_ids": list(env_model.trace_ids), "split": split.to_dict(),
        "train_segments": [s.to_dict() for s in train_seg], "eval_segments": [s.to_dict() for s in eval_seg],
        "task": task if isinstance(task, str) else dataclasses.asdict(task), "episode_seconds": episode_seconds,
        "dt": venv.spec_.dt, "n_envs": n_envs, "normalize_reward": normalize_reward,
        "init_angle_deg": init[0], "init_rate_deg": init[1],
        "residual": None if base is None else residual_metadata(base, residual_scale, setup),
        "hyperparameters": _plain(kwargs),
        "versions": {"stable_baselines3": sb3.__version__, "torch": _torch_version()},
    })
    eval_cb = None
    cbs = []
    if eval_freq:
        eval_cb = AtomicEvalCallback(eval_env, run_dir, metadata, n_eval_episodes=eval_episodes,
                                     eval_freq=max(eval_freq // n_envs, 1), deterministic=True, verbose=0, warn=False)
        cbs.append(eval_cb)
    ckpt = AtomicCheckpoint(checkpoint_freq or 2 ** 62, run_dir / "checkpoints", name, metadata)
    bar = ProgressBar(timesteps, progress, eval_cb, desc=f"{algo} {name}")
    clock = WallClockLimit(max_seconds) if max_seconds is not None else None
    cbs += [ckpt, bar] + ([clock] if clock else []) + list(callbacks)

    t0 = time.perf_counter()
    try:
        agent.learn(total_timesteps=timesteps, callback=CallbackList(cbs), progress_bar=False)
    except KeyboardInterrupt as e:
        seconds = time.perf_counter() - t0
        saved = ckpt.save("_interrupted")
        _write_record(run_dir, metadata, agent, seconds, eval_cb, ckpt, clock, interrupted=True, path=None)
        raise TrainingInterrupted(saved, int(agent.num_timesteps)) from e
    finally:
        bar.close()
        env.close()
        eval_env.close()
    seconds = time.perf_counter() - t0
    metadata = {**metadata, "timesteps": int(agent.num_timesteps), "train_seconds": seconds}
    save_atomically(agent, path, metadata)
    record = _write_record(run_dir, metadata, agent, seconds, eval_cb, ckpt, clock, interrupted=False, path=path)
    best = run_dir / "best_model.zip"
    return TrainingResult(path, algo, int(agent.num_timesteps), seconds, bool(clock and clock.reached), run_dir,
                          list(ckpt.paths), best if best.exists() else None, record["evaluations"], metadata, agent)


def _plain(value):
    """``value`` with anything JSON cannot hold (classes, schedules) as its ``str``."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if value is None or isinstance(value, (str, bool, int, float, numbers.Number)):
        return value
    return str(value)


def _torch_version() -> str:
    import torch

    return f"{torch.__version__} ({torch.get_num_threads()} threads)"


def _write_record(run_dir, metadata, agent, seconds, eval_cb, ckpt, clock, interrupted, path) -> dict:
    evals = []
    if eval_cb is not None:
        for t, r in zip(eval_cb.evaluations_timesteps, eval_cb.evaluations_results):
            evals.append([int(t), float(sum(r) / len(r)), float(_std(r))])
    record = jsonable({
        **metadata, "agent": None if path is None else str(path), "timesteps_done": int(agent.num_timesteps),
        "seconds": seconds, "steps_per_second": agent.num_timesteps / seconds if seconds > 0 else None,
        "cpu_count": os.cpu_count(), "interrupted": interrupted, "stopped_by_time": bool(clock and clock.reached),
        "evaluations": evals, "checkpoints": [str(p) for p in ckpt.paths],
    })
    write_text(Path(run_dir) / "training.json", json.dumps(record, indent=1, allow_nan=False) + "\n")
    return record


def _std(values) -> float:
    m = sum(values) / len(values)
    return math.sqrt(sum((v - m) ** 2 for v in values) / len(values))

