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
of that PD rather than the whole law (:mod:`controllers.rl.residual_agent`); the zip then
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
from typing import NamedTuple

import numpy as np

from heli_core.files import jsonable, write_text
from heli_core.terms import AXES

from ..errors import AgentError, TrainingInterrupted
from ..pd.controller import PDController
from ..trace_split import GustCurriculum, TraceSegment, WindowSampler, as_segments, split_traces
from .agent_file import AGENT_SCHEMA, AGENT_SCHEMA_VERSION, _algo_class, _sb3
from .config import UNLIMITED_TIMESTEPS, TrainConfig, make_config
from .residual_agent import residual_metadata


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
    learning_curve : dict
        Training episode returns and held-out evaluations (mean return, p90 |attitude error| per axis)
        against timesteps (:meth:`controllers.sb3_training.LearningCurve.record`).
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
    learning_curve: dict = field(default_factory=dict, repr=False)

    @property
    def steps_per_second(self) -> float:
        return self.timesteps / self.seconds if self.seconds > 0 else math.nan



def train_agent(algo: str | None = None, model=None, timesteps: int | None = None, out="agent", *,
                config: TrainConfig | None = None, progress: bool = True, verbose: int = 0, callbacks=(),
                **settings) -> TrainingResult:
    """Train a PPO or SAC attitude agent on the training traces of a model's disturbance library.

    Parameters
    ----------
    algo : {"ppo", "sac"}, optional
        Replaces ``config.algo``.
    model : str, Path, EnvModel or None
        Model directory written by ``heli identify`` (None: the shipped model).
    timesteps : int, optional
        Replaces ``config.timesteps``: environment steps to train for (summed over the copies).
    out : str or Path
        The agent's path; ``.zip`` is added. The run folder is ``<out>_training/``.
    config : TrainConfig, optional
        The settings of the run (default ``TrainConfig()``).
    progress : bool
        tqdm bar on stderr (when it is a terminal).
    verbose : int
        SB3 verbosity.
    callbacks : sequence of BaseCallback
        Extra SB3 callbacks.
    **settings
        Fields of :class:`TrainConfig` replacing the config's, e.g. ``seed=3, n_envs=2``
        (so ``train_agent("ppo", model, 10_000, "agents/ppo", seed=3)`` needs no config).
        With ``residual``, the saved agent carries the PD and :func:`load_agent`
        returns a :class:`controllers.rl.residual_agent.ResidualAgent`.

    Returns
    -------
    TrainingResult

    Raises
    ------
    AgentError
        Unknown algorithm, bad counts, split, traces, task or episode length,
        episodes longer than the gust segments, a bad residual base or scale, or an
        ``algo_kwargs`` key the algorithm does not take.
    TypeError
        A keyword that is not a field of :class:`TrainConfig`.
    heli_env.errors.EnvModelError
        Missing or corrupt model directory.
    TrainingInterrupted
        KeyboardInterrupt during training; a checkpoint was saved first (its path is
        ``exc.checkpoint``). It is a KeyboardInterrupt.
    """
    config = make_config(config, algo, timesteps, **settings)
    from heli_env.env_model import as_env_model

    env_model = as_env_model(model)
    split, segments = _split(config, env_model)
    _check_algo_kwargs(config)
    import torch

    from threadpoolctl import threadpool_limits

    threads_before = torch.get_num_threads()
    if config.torch_threads is not None:
        torch.set_num_threads(config.torch_threads)
    # every other pool (BLAS, OpenMP) held to the same count: their idle threads spin, and two trainings
    # side by side on two cores ran at 1/10 of one alone (850 against 9,900 steps/s) until they were held
    try:
        with threadpool_limits(limits=config.torch_threads):
            return _train(config, env_model, _out_paths(out), split, segments, progress, verbose, callbacks)
    finally:
        torch.set_num_threads(threads_before)


def _check_algo_kwargs(config: TrainConfig) -> None:
    """AgentError, before any work, for an ``algo_kwargs`` key the algorithm's constructor does not take."""
    import inspect

    taken = {k for k in inspect.signature(_algo_class(config.algo).__init__).parameters
             if not k.startswith("_") and k not in ("self", "policy", "env", "seed", "device", "verbose")}
    unknown = sorted(set(config.algo_kwargs or {}) - taken)
    if unknown:
        raise AgentError(f"algo_kwargs: {config.algo.upper()} takes no {', '.join(map(repr, unknown))}; it takes "
                         f"{', '.join(sorted(taken))}")


def _split(config: TrainConfig, env_model):
    """The trace split and the (training, held-out) gust segments of a run; AgentError for a bad split or traces."""
    try:
        split = split_traces(env_model.n_traces, config.held_out_fraction, config.split_seed)
        return split, (as_segments(config.train_traces, split, "train"),
                       as_segments(config.eval_traces, split, "held-out"))
    except ValueError as e:
        raise AgentError(str(e)) from e


def _train(config: TrainConfig, env_model, out, split, segments, progress, verbose, callbacks) -> TrainingResult:
    """Build the environments and the agent, then learn (:func:`_learn`); ``out`` is (agent zip, run folder, name)."""
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.utils import set_random_seed

    set_random_seed(config.seed)
    setup, task = _residual_setup(config, env_model, segments[0])
    hyper = config.hyperparameters()
    env, eval_env, dt, curriculum = _environments(config, env_model, task, segments, hyper["gamma"])
    if curriculum is not None:
        from ..sb3_training import CurriculumProgress

        callbacks = (CurriculumProgress(curriculum), *callbacks)
    _scale_observations(hyper, setup, config.stacked, config.normalize_obs)
    agent = _algo_class(config.algo)("MlpPolicy", env, seed=config.seed, device="cpu", verbose=verbose,
                                     **{**hyper, "learning_rate": config.learning_rate(hyper)})
    # SB3's own logger would make an empty SB3-<date> folder in the system's temp folder on
    # every run; its training statistics go to the run folder instead (progress.csv).
    agent.set_logger(configure(str(out[1]), ["csv"] + (["stdout"] if verbose else [])))
    metadata = _metadata(config, env_model, split, segments, task, dt, setup, hyper)
    return _learn(agent, config, out, metadata, (env, eval_env), progress, callbacks)


def residual_setup(base, env_model, segments, seed: int = 0, seconds: float = 10.0,
                   axis_balance: bool = True, reference: PDController | None = None) -> dict:
    """Reward and observation scales for residual training, from the base's errors on training gusts.

    Flies ``base`` (a PD or an LQG) for ``seconds`` on each training segment (starting at rest) and
    derives the scales listed in :mod:`controllers.rl.residual_agent`'s docstring. (It lives
    here, beside the training that uses it, so that the residual agent, which every agent
    loader needs, does not stand on the evaluation and its vector env.)

    Returns
    -------
    dict
        ``error_deg`` (E, the largest axis'), ``axis_error_deg`` (E_i per axis), ``corner_rad_s`` (ω_c),
        ``stick_p99``, ``attitude_scale`` and ``rate_scale`` [rad, rad/s] of the reward (from E),
        ``axis_weights`` (with ``axis_balance``: (E / E_i)², at most :data:`MAX_AXIS_WEIGHT`, the reward of
        each axis scaled by its own level; otherwise ones) and ``obs_scale`` (12 floats: each axis by its
        E_i with ``axis_balance``, otherwise every axis by E). With a ``reference`` PD (``axis_balance``
        only), ``axis_weights`` are (R / R_i)² of its p90s R_i on the same gusts (R the largest, the same cap)
        and ``reference_axis_error_deg`` lists the R_i; the scales still follow the base.
    """
    errors, stick, rates = _p90_errors(base, env_model, segments, seed, seconds, "residual base")
    err = max(errors)
    if isinstance(base, PDController):
        kp, kd = np.abs(base.gains.kp), np.abs(base.gains.kd)
        corner = float(np.max(np.where(kd > 0, kp / np.where(kd > 0, kd, 1.0), 0.0)))
    else:  # an LQG has no kp/kd: the largest ratio of its p90 rate error to its p90 attitude error [1/s]
        corner = max((r / e for r, e in zip(rates, errors) if e > 0), default=0.0)
    if not corner > 0.0:
        corner = 10.0  # a P-only or D-only base: weigh 1 rad/s of rate error as 0.1 rad of attitude error
    levels = _balanced(errors) if axis_balance else [err] * 3
    rad = [math.radians(v) for v in levels]
    e = math.radians(err)
    setup = {"error_deg": err, "axis_error_deg": errors, "corner_rad_s": corner, "stick_p99": stick,
             "attitude_scale": 2 * e, "rate_scale": 2 * e * corner,
             "axis_weights": _axis_weights(errors) if axis_balance else [1.0] * 3,
             "obs_scale": [4 * r for r in rad] + [4 * r * corner for r in rad] * 2 + [max(1.5 * stick, 0.05)] * 3}
    if reference is not None:
        if not axis_balance:
            raise AgentError("a reward reference weighs the axes; it needs axis_balance")
        ref, _, _ = _p90_errors(reference, env_model, segments, seed, seconds, "reward reference")
        setup["reference_axis_error_deg"] = ref
        setup["axis_weights"] = _axis_weights(ref)
    return setup


def _p90_errors(pd, env_model, segments, seed: int, seconds: float, role: str):
    """(p90 |attitude error| per axis [deg], largest p99 |stick|, p90 |rate error| per axis [deg/s]) of the
    controller ``pd`` (a PD or an LQG) flying ``seconds`` on each segment."""
    from ..evaluate import evaluate_agent

    res = evaluate_agent(pd, env_model, traces=list(segments), episodes_per_trace=1, episode_seconds=seconds,
                         seed=seed, name=role)
    errors = [float(res.metrics[a]["att_p90_deg"]) for a in AXES]
    if not (all(math.isfinite(v) for v in errors) and max(errors) > 0.0):
        raise AgentError(f"the {role} PD gives no usable error level on the training gusts (p90 {errors!r} "
                         "deg); is it stable on this model?")
    return (errors, max(float(res.metrics[a]["stick_p99"]) for a in AXES),
            [float(res.metrics[a]["rate_p90_dps"]) for a in AXES])


def _balanced(errors) -> list:
    """Each axis' error level for balancing: its own, at least the largest / sqrt(:data:`MAX_AXIS_WEIGHT`)."""
    return [max(e_i, max(errors) / math.sqrt(MAX_AXIS_WEIGHT)) for e_i in errors]


def _axis_weights(errors) -> list:
    """Each axis' reward weight, (E / E_i)² of the balanced levels E_i (:func:`_balanced`), E the largest."""
    return [(max(errors) / v) ** 2 for v in _balanced(errors)]


MAX_AXIS_WEIGHT = 100.0
"""Largest reward weight of an axis relative to the worst-held one (an axis the base holds ten times better
than the worst counts ten times, not more: a near-perfect axis would otherwise drown the others)."""


def _residual_setup(config: TrainConfig, env_model, train_seg):
    """(scales, task): the residual's scales from its base's errors on the training gusts (None without a
    residual), and the task: a named one with its reward scaled by those scales (per axis with
    ``config.axis_balance``) and weighted by ``config.task_weights`` (and ``config.stick_step_weight``), else
    ``config.task`` itself."""
    setup = None
    if config.residual is not None:
        setup = residual_setup(config.residual, env_model, train_seg, config.seed, axis_balance=config.axis_balance,
                               reference=config.reward_reference)
    task = config.task
    if isinstance(task, str) and (setup is not None or config.task_weights is not None or config.stick_step_weight):
        from heli_env.tasks import TaskConfig

        fields = {} if setup is None else {"attitude_scale": setup["attitude_scale"],
                                           "rate_scale": setup["rate_scale"],
                                           "axis_weights": tuple(setup["axis_weights"])}
        if config.task_weights is not None:
            fields["weights"] = config.task_weights
        if config.stick_step_weight:
            fields["stick_step_weight"] = config.stick_step_weight
        try:
            task = TaskConfig(task=task, **fields)
        except ValueError as e:
            raise AgentError(str(e)) from e
    return setup, task


def _environments(config: TrainConfig, env_model, task, segments, gamma: float):
    """The training and evaluation ``VecEnv`` (residual, monitor and reward-normalising wrappers), dt [s] and
    the training gusts' :class:`~controllers.trace_split.GustCurriculum` (None without one).

    Training copies replay windows of the training segments; the evaluation copies replay
    fixed windows of the held-out ones (``fixed_seed``), the same at every evaluation.
    """
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from heli_env.env_model import perturbed
    from heli_env.vector_env import HeliAttitudeVectorEnv

    from .vec_env import ConcatVecEnv, GymnasiumVecEnv

    init = config.init_ranges
    try:  # bad task or episode length; episodes longer than the gust segments
        kw = {"model": env_model, "task": task, "episode_seconds": config.episode_seconds,
              "init_angle_deg": init[0], "init_rate_deg": init[1]}
        train_model, train_segments = _training_gusts(config, env_model, segments[0])
        paired = config.residual is not None and config.paired_baseline
        venvs = [HeliAttitudeVectorEnv(copies * (2 if paired else 1),
                                       **{**kw, "model": perturbed(train_model, shift) if shift else train_model})
                 for shift, copies in config.delay_groups]  # one group per servo delay flown (delay_spread)
        venv = venvs[0]
        needed = venv.spec_.needed
        train_sampler = WindowSampler(train_model, train_segments, needed)
        curriculum = (GustCurriculum(train_sampler, config.curriculum_start, config.curriculum_steps)
                      if config.curriculum_steps else None)
        eval_sampler = WindowSampler(env_model, segments[1], needed)
        eval_venv = HeliAttitudeVectorEnv(config.eval_episodes, **kw)
    except ValueError as e:
        raise AgentError(str(e)) from e
    envs = [GymnasiumVecEnv(v, episode_options=curriculum or train_sampler, twins=paired) for v in venvs]
    eval_env = GymnasiumVecEnv(eval_venv, episode_options=eval_sampler, fixed_seed=config.seed + 1000)
    if config.residual is not None:
        from .residual_agent import residual_env

        base, scale = config.residual, config.residual_scale
        envs, eval_env = [residual_env(e, base, scale, paired) for e in envs], residual_env(eval_env, base, scale)
    env = envs[0] if len(envs) == 1 else ConcatVecEnv(envs)  # a paired residual's twins stay within their group
    if config.stacked > 1:  # a residual's (TrainConfig refuses a history without one)
        from stable_baselines3.common.vec_env import VecFrameStack

        env, eval_env = VecFrameStack(env, config.stacked), VecFrameStack(eval_env, config.stacked)
    env, eval_env = VecMonitor(env), VecMonitor(eval_env)  # monitors the raw returns
    if config.reward_normalized:  # the eval env is wrapped alike (EvalCallback syncs wrappers) but left raw
        env = VecNormalize(env, norm_obs=False, norm_reward=True, gamma=gamma)
        eval_env = VecNormalize(eval_env, training=False, norm_obs=False, norm_reward=False)
    return env, eval_env, venv.spec_.dt, curriculum


def _scale_observations(hyper: dict, setup, history: int = 1, normalize: bool = False) -> None:
    """Put :class:`controllers.sb3_training.ObservationScaler` (``normalize``: its running form,
    :class:`~controllers.sb3_training.ObservationNormalizer`) in front of the policy unless another feature
    extractor is asked for; a residual's scaler takes the observation scales of its ``setup``, once per
    stacked observation."""
    from ..sb3_training import ObservationNormalizer, ObservationScaler

    own = ObservationNormalizer if normalize else ObservationScaler
    hyper["policy_kwargs"].setdefault("features_extractor_class", own)
    if setup is not None and hyper["policy_kwargs"]["features_extractor_class"] is own:
        hyper["policy_kwargs"].setdefault("features_extractor_kwargs", {"scale": list(setup["obs_scale"]) * history})


def _training_gusts(config: TrainConfig, env_model, segments):
    """The model and segments the training copies replay: the recorded training segments, or with
    ``config.surrogates`` a library of that many surrogates of each (seeded by ``config.seed``)."""
    if not config.surrogates:
        return env_model, segments
    from heli_env.surrogates import surrogate_model

    pieces = [(s.trace, *s.samples(int(env_model.lengths[s.trace]))) for s in segments]
    model = surrogate_model(env_model, copies=config.surrogates, seed=config.seed, pieces=pieces)
    return model, [TraceSegment(t) for t in range(model.n_traces)]


def _metadata(config: TrainConfig, env_model, split, segments, task, dt: float, setup, hyper: dict) -> dict:
    """What the agent's zip carries in ``heli_agent.json``: algo, seed, model, split, settings, versions."""
    sb3 = _sb3()
    init = config.init_ranges
    return jsonable({
        "schema": AGENT_SCHEMA, "schema_version": AGENT_SCHEMA_VERSION, "algo": config.algo, "seed": config.seed,
        "model": str(env_model.path), "library_version": env_model.library_version,
        "trace_ids": list(env_model.trace_ids), "split": split.to_dict(),
        "train_segments": [s.to_dict() for s in segments[0]], "eval_segments": [s.to_dict() for s in segments[1]],
        "task": task if isinstance(task, str) else dataclasses.asdict(task),
        "episode_seconds": config.episode_seconds, "dt": dt, "n_envs": config.n_envs,
        "normalize_reward": config.reward_normalized, "init_angle_deg": init[0], "init_rate_deg": init[1],
        "surrogates": config.surrogates, "axis_balance": config.axis_balance, "normalize_obs": config.normalize_obs,
        "lr_schedule": config.lr_schedule, "delay_spread": config.delay_spread,
        "delay_groups": [{"added_delay_s": shift, "copies": copies} for shift, copies in config.delay_groups],
        "curriculum": ({"start": config.curriculum_start, "steps": config.curriculum_steps}
                       if config.curriculum_steps else None),
        "paired_baseline": config.residual is not None and config.paired_baseline,
        "reward_reference": None if config.reward_reference is None else config.reward_reference.document(),
        "residual": None if config.residual is None else residual_metadata(config.residual, config.residual_scale,
                                                                            setup, config.stacked),
        "hyperparameters": _plain(hyper),
        "versions": {"stable_baselines3": sb3.__version__, "torch": _torch_version()},
    })


class _Callbacks(NamedTuple):
    """The SB3 callbacks of one run: held-out evaluation (or None), checkpoints, progress bar, time budget
    (or None), the learning curve, and all of them in the order they run, the caller's last."""

    evaluation: object
    checkpoint: object
    bar: object
    clock: object
    curve: object
    all: list


def _callbacks(config: TrainConfig, eval_env, out, metadata: dict, progress: bool, extra) -> _Callbacks:
    """The run's callbacks: evaluations every ``eval_freq`` timesteps, checkpoints, bar, time budget, ``extra``."""
    from ..sb3_training import AtomicCheckpoint, AtomicEvalCallback, LearningCurve, ProgressBar, WallClockLimit

    _, run_dir, name = out
    eval_cb = None
    cbs = []
    if config.eval_freq:
        eval_cb = AtomicEvalCallback(eval_env, run_dir, metadata, n_eval_episodes=config.eval_episodes,
                                     eval_freq=max(config.eval_freq // config.n_envs, 1), deterministic=True,
                                     verbose=0, warn=False)
        cbs.append(eval_cb)
    ckpt = AtomicCheckpoint(config.checkpoint_freq or 2 ** 62, run_dir / "checkpoints", name, metadata)
    by_time = config.max_seconds is not None and config.timesteps >= UNLIMITED_TIMESTEPS
    bar = ProgressBar(None if by_time else config.timesteps, progress, eval_cb,
                      desc=f"train {config.algo.upper()}" + (f" for {config.max_seconds / 60:g} min" if by_time else ""))
    clock = WallClockLimit(config.max_seconds) if config.max_seconds is not None else None
    if config.normalize_obs:  # first, so a callback acting at a rollout's end sees the merged statistics
        from ..sb3_training import ObservationStatistics

        cbs.insert(0, ObservationStatistics())
    curve = LearningCurve(eval_cb)
    cbs += [ckpt, bar, curve] + ([clock] if clock else []) + list(extra)
    return _Callbacks(eval_cb, ckpt, bar, clock, curve, cbs)


def _learn(agent, config: TrainConfig, out, metadata: dict, envs, progress: bool, extra) -> TrainingResult:
    """``agent.learn`` with the run's callbacks, then the agent and the record saved; on Ctrl-C a checkpoint
    and the record are saved first and :class:`TrainingInterrupted` raised."""
    from stable_baselines3.common.callbacks import CallbackList

    from ..sb3_training import save_atomically

    path, run_dir, _ = out
    cb = _callbacks(config, envs[1], out, metadata, progress, extra)
    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        agent.learn(total_timesteps=config.timesteps, callback=CallbackList(cb.all), progress_bar=False)
    except KeyboardInterrupt as e:
        seconds = time.perf_counter() - t0
        saved = cb.checkpoint.save("_interrupted")
        _write_record(run_dir, metadata, agent, (seconds, time.process_time() - cpu0), cb, interrupted=True, path=None)
        raise TrainingInterrupted(saved, int(agent.num_timesteps)) from e
    finally:
        cb.bar.close()
        for env in envs:
            env.close()
        _close_logger(agent)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    metadata = {**metadata, "timesteps": int(agent.num_timesteps), "train_seconds": seconds}
    save_atomically(agent, path, metadata)
    record = _write_record(run_dir, metadata, agent, (seconds, cpu), cb, interrupted=False, path=path)
    best = run_dir / "best_model.zip"
    return TrainingResult(path, config.algo, int(agent.num_timesteps), seconds, bool(cb.clock and cb.clock.reached),
                          run_dir, list(cb.checkpoint.paths), best if best.exists() else None, record["evaluations"],
                          metadata, agent, record["learning_curve"])


def _close_logger(agent) -> None:
    """Close the run's SB3 logger (``progress.csv`` complete and its file released) and leave the agent a
    logger that writes nothing, so that a further ``agent.learn`` neither fails on the closed file nor
    truncates the run's statistics by opening it again."""
    from stable_baselines3.common.logger import Logger

    agent.logger.close()
    agent.set_logger(Logger(folder=None, output_formats=[]))


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


def _write_record(run_dir, metadata, agent, times, cb: _Callbacks, interrupted, path) -> dict:
    """Write ``training.json``: settings, timing, held-out evaluations, checkpoints; returns what it wrote.

    ``times`` is (wall, process CPU) seconds of ``learn``: on a machine shared with other work the steps per CPU
    second are the nearer figure to what one quiet core would do (``steps_per_cpu_second``)."""
    seconds, cpu = times
    evals = []
    if cb.evaluation is not None:
        for t, r in zip(cb.evaluation.evaluations_timesteps, cb.evaluation.evaluations_results):
            evals.append([int(t), float(sum(r) / len(r)), float(_std(r))])
    record = jsonable({
        **metadata, "agent": None if path is None else str(path), "timesteps_done": int(agent.num_timesteps),
        "seconds": seconds, "steps_per_second": agent.num_timesteps / seconds if seconds > 0 else None,
        "cpu_seconds": cpu, "steps_per_cpu_second": agent.num_timesteps / cpu if cpu > 0 else None,
        "cpu_count": os.cpu_count(), "interrupted": interrupted,
        "stopped_by_time": bool(cb.clock and cb.clock.reached), "evaluations": evals,
        "learning_curve": cb.curve.record(), "checkpoints": [str(p) for p in cb.checkpoint.paths],
    })
    write_text(Path(run_dir) / "training.json", json.dumps(record, indent=1, allow_nan=False) + "\n")
    return record


def _std(values) -> float:
    m = sum(values) / len(values)
    return math.sqrt(sum((v - m) ** 2 for v in values) / len(values))

