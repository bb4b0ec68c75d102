"""The settings of one RL training run: :class:`TrainConfig`, checked once where it is made.

:func:`controllers.rl.train_agent` and :func:`controllers.rl.train_seeds` take a
``TrainConfig`` (or its fields as keywords, :func:`make_config`) instead of two
dozen loose arguments passed from function to function. What can be checked
without the model is checked in ``__post_init__``: counts, time budget, the
residual's base and bound, initial ranges. What needs the model's library (the
trace split, the traces, the task, episodes no longer than the gust segments) is
checked when training starts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from heli_core.config import configured, is_real, whole_number

from ..errors import AgentError
from .agent_file import ALGOS
from .residual_agent import RESIDUAL_INIT_DEG, RESIDUAL_SCALE, as_base, check_history, check_scale

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

RESIDUAL_SDE_KWARGS = {
    # gSDE: exploration noise that is a function of the state, resampled every 8 steps (80 ms) instead of
    # white noise at 100 Hz, which the servo lag and the airframe filter away before it shows in the error.
    # log std -2 starts it at the same action noise (std 0.37) as the default's -1 without it. Over seeds
    # 0-2 (15 min, +-0.15 stick, paired baseline) it lowered p90 / best PD on roll 1.39-1.51 -> 1.16-1.45
    # and pitch 1.05-1.12 -> 1.03-1.08 for every seed, and yaw on average 1.36 -> 1.22 (docs/controllers.md).
    "ppo": {"use_sde": True, "sde_sample_freq": 8, "policy_kwargs": {"log_std_init": -2.0}},
}
"""What residual training changes in :data:`DEFAULT_KWARGS` for its exploration, unless ``algo_kwargs`` sets
``use_sde`` itself."""

RESIDUAL_KWARGS = {
    # A sixth of the default learning rate. With 3e-4 a residual's updates stayed large to the end (clip
    # fraction 0.41-0.44, approximate KL 0.045-0.063 per update after 8 M steps) and its held-out return
    # stopped rising by 2 M steps. In 15 min (seeds 0-2, +-0.15 stick) p90 / best PD went from roll
    # 1.39 / 1.21 / 1.12, pitch 1.05 / 0.99 / 0.98, yaw 1.17 / 1.04 / 1.11 with 3e-4 to roll 1.20 / 1.14 /
    # 1.14, pitch 1.03 / 0.98 / 0.96, yaw 1.07 / 1.05 / 1.02 with 5e-5; 1e-4 gave roll and pitch within 0.02
    # of those and yaw 1.07 / 1.15 / 1.12. On another held-out trace (split seed 1) 5e-5 gave roll 1.16 / 1.16
    # / 1.04, pitch 0.98 / 0.98 / 0.99, yaw 1.14 / 1.04 / 1.36 (docs/controllers.md).
    "ppo": {"learning_rate": 5e-5},
}
"""What residual training changes in :data:`DEFAULT_KWARGS` besides exploration; ``algo_kwargs`` override it."""

RESIDUAL_REWARD_WEIGHTS = (1.0, 0.01, 0.01)
"""Attitude, rate and effort weights of a residual's reward. The task's own rate weight (0.1) charged the
best swept PD's yaw rate activity twice its attitude error, so the reward preferred a calmer, less precise
yaw than the figure compared (p90 |attitude error|); with 0.01, seeds 0-2 came out better on every axis
(yaw 1.19-1.26 -> 1.04-1.17 of the best PD; docs/controllers.md)."""

RESIDUAL_HISTORY = 4
"""Observations a residual's policy sees side by side by default (:attr:`TrainConfig.history`). With the
last one only, the residuals learned a yaw law that leans on the identified delay: 20 ms more servo delay
multiplied their yaw p90 by 2.06-3.12 (9 runs: seeds 0-2 on each of the three held-out traces); with 4,
by 1.26-1.69, at about the same nominal error (p90 / best PD, mean of the 9 runs: roll 1.15 -> 1.16,
pitch 0.98 -> 0.96, yaw 1.10 -> 1.11; docs/controllers.md)."""

DELAY_LEVELS = 4
"""Servo delays flown side by side with :attr:`TrainConfig.delay_spread` (evenly spaced over the spread)."""

MAX_DELAY_SPREAD = 0.1
"""Largest delay spread accepted [s]: beyond 100 ms the training aircraft is no longer the identified one."""

LR_SCHEDULES = ("constant", "linear")
"""Learning-rate schedules of :attr:`TrainConfig.lr_schedule`."""

UNLIMITED_TIMESTEPS = 10 ** 12
"""``timesteps`` of a run bounded by its time budget (``max_seconds``) alone: a step cap never reached (SB3
needs one); the progress bar then counts steps against the clock, not against the cap."""

INIT_DEG = 5.0
"""Default initial roll/pitch range [deg] and rate range [deg/s] of episodes without a residual (the env's)."""


@dataclass(frozen=True)
class TrainConfig:
    """Settings of one PPO or SAC training run.

    Parameters
    ----------
    algo : {"ppo", "sac"}
        The algorithm.
    timesteps : int
        Environment steps to train for, summed over the copies [steps], >= 1.
    seed : int
        Seeds Python, numpy and torch, the network, the environments (copy ``i``
        gets ``seed + i``) and the draw of gust windows.
    n_envs : int
        Environment copies stepped as one batch, >= 1.
    episode_seconds : float
        Episode length [s].
    task : str or heli_env.tasks.TaskConfig
        Environment task ("hold", "track", "rate").
    init_angle_deg : float, optional
        Initial roll/pitch range of training and evaluation episodes [deg], in
        [0, 90). Default 5 (the env's), 0.5 with ``residual``.
    init_rate_deg : float, optional
        Initial rate range [deg/s], in [0, 90). Default as ``init_angle_deg``.
    train_traces, eval_traces : None, str, or sequence of int / TraceSegment
        Gust segments of training episodes and of evaluations. Default: the
        training and held-out sides of the split.
    held_out_fraction : float
        Fraction of the library's traces held out, in (0, 1) (:func:`controllers.trace_split.split_traces`).
    split_seed : int
        Seed of the held-out choice.
    eval_freq : int
        Timesteps between held-out evaluations [steps], >= 0 (0: none).
    eval_episodes : int
        Held-out episodes per evaluation (fixed windows, the same at every evaluation), >= 1.
    checkpoint_freq : int
        Timesteps between checkpoints [steps], >= 0 (0: none besides the one an interrupt writes).
    max_seconds : float, optional
        Wall-time budget of training [s], > 0; training stops at whichever of
        ``timesteps`` and the budget comes first.
    algo_kwargs : dict, optional
        Overrides of :data:`DEFAULT_KWARGS` (``policy_kwargs`` merged key by key).
    normalize_reward : bool, optional
        Divide training rewards by a running estimate of the discounted return's
        standard deviation (SB3 ``VecNormalize(norm_obs=False)``). Default: True for PPO,
        whose value function otherwise chases returns of -1e2 to -1e5 (a spinning
        yaw costs 324 per step), False for SAC. Observations are never normalised
        (the policy scales them itself), so the saved agent needs no statistics.
    surrogates : int
        Train on this many phase-randomised surrogates of each training segment
        (:func:`heli_env.surrogates.surrogate_model`: the segments' spectra and level, new gusts)
        instead of the recorded segments themselves; 0 (default) replays the recorded ones. The
        evaluation stays on the recorded held-out segments either way.
    torch_threads : int, optional
        torch threads during training (restored after), >= 1; None leaves torch's
        setting. One is fastest for these small networks: on 2 cores shared with
        other work, two threads ran PPO 20 times slower than one (thread
        contention), and a fixed count keeps results reproducible.
    residual : PDController or path of a PD controller JSON, optional
        Train a residual on this PD instead of a whole policy
        (:mod:`controllers.rl.residual_agent`): the env receives
        ``clip(PD(obs) + residual_scale * action, -1, 1)``. Unless given, the task's
        reward scales, the observation scales (``policy_kwargs``'
        ``features_extractor_kwargs``) and the initial ranges follow the PD's own
        error level on the training gusts. A path is read here: the attribute is
        the :class:`~controllers.pd.PDController`.
    residual_scale : float
        Bound of the residual [stick], in (0, 2]; checked only with ``residual``.
    axis_balance : bool
        With ``residual`` (default True): each axis' reward and observation scales follow that
        axis' own error level under the base PD, so that every axis counts alike in the reward
        (``TaskConfig.axis_weights``); False scales every axis by the largest axis' level, which
        leaves an axis the PD already holds well (pitch beside yaw) with a tenth of the weight.
    paired_baseline : bool
        With ``residual``: every training copy has a twin that meets the same gusts, start and
        sensor noise under the base PD alone, and the residual is rewarded for the difference
        (:func:`controllers.rl.residual_agent.residual_env`, ``paired=True``); twice the
        environment copies are stepped. The held-out evaluations score the raw return.
        Default True: the residual settings measured in ``docs/controllers.md`` (False: each copy's
        own return).
    normalize_obs : bool
        Standardise observations by running statistics of the training rollouts (what SB3's
        ``VecNormalize(norm_obs=True)`` does), held inside the policy
        (:class:`controllers.sb3_training.ObservationNormalizer`, started from the fixed scales), so the
        saved agent still takes raw observations. Default False: the fixed scales alone.
    reward_weights : tuple of 3 float, optional
        Weights of the attitude, rate and control-effort terms of a named task's reward
        (:class:`heli_env.tasks.TaskConfig` ``weights``). Default: :data:`RESIDUAL_REWARD_WEIGHTS`
        with ``residual``, else the task's own ((1, 0.1, 0.01) for "hold"). For a task given as a
        ``TaskConfig``, set its ``weights`` there instead.
    stick_step_weight : float
        Weight of the squared change of the applied stick from one step to the next in a named task's reward
        (:class:`heli_env.tasks.TaskConfig` ``stick_step_weight``): charges the chatter a servo feels, which the
        effort weight charges only by its size. Default 0 (none).
    lr_schedule : {"constant", "linear"}
        The learning rate: constant (default), or falling linearly from ``learning_rate`` to 0 at
        ``timesteps`` (SB3's ``LinearSchedule``). With a time budget set ``timesteps`` to about what the
        budget allows, or the rate never gets low.
    curriculum_steps : int
        Gust curriculum: training episodes' gusts rise linearly from ``curriculum_start`` times their
        recorded level to the full level over the first ``curriculum_steps`` timesteps
        (:class:`controllers.trace_split.GustCurriculum`); 0 (default) trains at the full level
        throughout. The held-out evaluations always fly the full gusts.
    curriculum_start : float
        Gust multiplier of the first training episodes with a curriculum, in [0, 1) (default 0.5).
    history : int, optional
        With ``residual``: the policy sees the last ``history`` observations side by side (SB3's
        ``VecFrameStack``; 1 the current one only). Past actions and rates let it infer what the
        servo delay still holds and what the gust is doing, which no single observation shows. In
        [1, 16]; default :data:`RESIDUAL_HISTORY` with ``residual``, else 1 (:attr:`stacked`).
    reward_reference : PDController or path, optional
        With ``residual`` and ``axis_balance``: weigh each axis of the reward by the error this PD
        leaves on the training gusts instead of the base's own (:func:`controllers.rl.train.residual_setup`).
        With the best swept pair as reference, each axis counts by how far it is from what a PD
        can reach there, the figure the comparison reports; with the base (the default) an axis the
        base already holds well (pitch beside yaw) weighs most. A path is read here.
    delay_spread : float
        Domain randomisation of the servo delay [s], in [0, :data:`MAX_DELAY_SPREAD`]: the training copies
        are split into :data:`DELAY_LEVELS` groups (fewer with fewer copies, >= 2 needed), each flying the
        model with every axis' delay (eq. 31) shifted by one of that many evenly spaced values from
        ``-delay_spread`` to ``+delay_spread`` (a delay never below 0), so the policy cannot rely on the
        identified delay being exact. The held-out evaluations fly the model as identified. Default 0.

    Raises
    ------
    AgentError
        (a ValueError) Unknown algorithm, bad counts or time budget, initial ranges
        outside [0, 90), or a bad residual base or bound.
    FileNotFoundError
        ``residual`` names no file.
    """

    algo: str = "ppo"
    timesteps: int = 200_000
    seed: int = 0
    n_envs: int = 8
    episode_seconds: float = 30.0
    task: object = "hold"
    init_angle_deg: float | None = None
    init_rate_deg: float | None = None
    train_traces: object = None
    eval_traces: object = None
    held_out_fraction: float = 0.25
    split_seed: int = 0
    eval_freq: int = 50_000
    eval_episodes: int = 4
    checkpoint_freq: int = 100_000
    max_seconds: float | None = None
    algo_kwargs: dict | None = None
    normalize_reward: bool | None = None
    torch_threads: int | None = 1
    residual: object = None
    residual_scale: float = RESIDUAL_SCALE
    surrogates: int = 0
    axis_balance: bool = True
    paired_baseline: bool = True
    history: int | None = None
    normalize_obs: bool = False
    lr_schedule: str = "constant"
    reward_weights: tuple | None = None
    stick_step_weight: float = 0.0
    curriculum_steps: int = 0
    curriculum_start: float = 0.5
    reward_reference: object = None
    delay_spread: float = 0.0

    def __post_init__(self):
        if self.algo not in ALGOS:
            raise AgentError(f"algo must be one of {ALGOS}, got {self.algo!r}")
        for name, minimum in (("timesteps", 1), ("n_envs", 1), ("eval_freq", 0), ("checkpoint_freq", 0),
                              ("eval_episodes", 1)):
            object.__setattr__(self, name, whole_number(getattr(self, name), name, minimum, AgentError))
        object.__setattr__(self, "surrogates", whole_number(self.surrogates, "surrogates", 0, AgentError))
        object.__setattr__(self, "curriculum_steps",
                           whole_number(self.curriculum_steps, "curriculum_steps", 0, AgentError))
        if self.reward_weights is not None:
            from heli_env.tasks import three_weights

            try:  # the task's own check, before the model loads
                weights = three_weights(self.reward_weights, "reward_weights", "attitude, rate, effort")
            except ValueError as e:
                raise AgentError(str(e)) from None
            if not isinstance(self.task, str):
                raise AgentError("reward_weights are for a named task; set the weights of a TaskConfig task in it")
            object.__setattr__(self, "reward_weights", weights)
        w = self.stick_step_weight
        if isinstance(w, bool) or not (is_real(w) and w >= 0):
            raise AgentError(f"stick_step_weight must be a number >= 0, got {w!r}")
        object.__setattr__(self, "stick_step_weight", float(w))
        if w and not isinstance(self.task, str):
            raise AgentError("stick_step_weight is for a named task; set it in the TaskConfig task instead")
        if self.algo_kwargs is not None and not (isinstance(self.algo_kwargs, dict)
                                                 and all(isinstance(k, str) for k in self.algo_kwargs)):
            raise AgentError(f"algo_kwargs must be a dict of SB3 keyword arguments, got {self.algo_kwargs!r}")
        if self.lr_schedule not in LR_SCHEDULES:
            raise AgentError(f"lr_schedule must be one of {LR_SCHEDULES}, got {self.lr_schedule!r}")
        if not (is_real(self.curriculum_start) and 0.0 <= self.curriculum_start < 1.0):
            raise AgentError(f"curriculum_start must be a gust multiplier in [0, 1), got {self.curriculum_start!r}")
        if not (is_real(self.delay_spread) and 0.0 <= self.delay_spread <= MAX_DELAY_SPREAD):
            raise AgentError(f"delay_spread must be a number of seconds in [0, {MAX_DELAY_SPREAD:g}], got "
                             f"{self.delay_spread!r}")
        object.__setattr__(self, "delay_spread", float(self.delay_spread))
        if self.delay_spread and self.n_envs < 2:
            raise AgentError(f"delay_spread needs at least 2 training copies (n_envs) to fly different delays, got "
                             f"n_envs={self.n_envs}")
        if self.torch_threads is not None:
            object.__setattr__(self, "torch_threads", whole_number(self.torch_threads, "torch_threads", 1, AgentError))
        if self.max_seconds is not None and not (self.max_seconds > 0 and math.isfinite(self.max_seconds)):
            raise AgentError(f"max_seconds must be a positive number of seconds, got {self.max_seconds!r}")
        if self.residual is not None:
            object.__setattr__(self, "residual", as_base(self.residual))
            object.__setattr__(self, "residual_scale", check_scale(self.residual_scale))
        if self.history is not None:
            object.__setattr__(self, "history", check_history(self.history))
        if self.residual is None and self.stacked > 1:
            raise AgentError(f"history (observations stacked) is for residual agents; got history={self.history} "
                             "without residual")
        if self.reward_reference is not None:
            if self.residual is None or not self.axis_balance:
                raise AgentError("reward_reference weighs a residual's axes; it needs residual and axis_balance")
            object.__setattr__(self, "reward_reference", as_base(self.reward_reference, "reward_reference"))
        init = self.init_ranges
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v < 90 for v in init):
            raise AgentError(f"init_angle_deg and init_rate_deg must be numbers in [0, 90), got {init!r}")

    @property
    def init_ranges(self) -> tuple:
        """(roll/pitch range [deg], rate range [deg/s]) of the episodes' starts, defaults filled in."""
        default = RESIDUAL_INIT_DEG if self.residual is not None else INIT_DEG
        return tuple(default if v is None else v for v in (self.init_angle_deg, self.init_rate_deg))

    @property
    def stacked(self) -> int:
        """Observations the policy sees side by side (``history``, its default filled in)."""
        if self.history is not None:
            return self.history
        return RESIDUAL_HISTORY if self.residual is not None else 1

    @property
    def delay_groups(self) -> list[tuple[float, int]]:
        """(servo delay added [s], training copies) of each group flown side by side (``delay_spread``):
        ``[(0.0, n_envs)]`` without a spread."""
        if not self.delay_spread:
            return [(0.0, self.n_envs)]
        levels = min(DELAY_LEVELS, self.n_envs)
        shifts = [self.delay_spread * (2 * k / (levels - 1) - 1) for k in range(levels)]
        return [(shift, self.n_envs // levels + (k < self.n_envs % levels)) for k, shift in enumerate(shifts)]

    @property
    def task_weights(self) -> tuple | None:
        """The reward weights of a named task (``reward_weights``, its default filled in); None: the task's own."""
        if self.reward_weights is not None:
            return self.reward_weights
        return RESIDUAL_REWARD_WEIGHTS if self.residual is not None else None

    @property
    def reward_normalized(self) -> bool:
        """Whether training rewards are normalised (``normalize_reward``, its default filled in)."""
        return self.algo == "ppo" if self.normalize_reward is None else bool(self.normalize_reward)

    def learning_rate(self, hyper: dict):
        """What the algorithm takes as ``learning_rate``: ``hyper``'s number, or with ``lr_schedule="linear"``
        a function of SB3's remaining progress falling from it to 0."""
        if self.lr_schedule == "constant":
            return hyper["learning_rate"]
        from stable_baselines3.common.utils import LinearSchedule

        return LinearSchedule(hyper["learning_rate"], 0.0, 1.0)

    def hyperparameters(self) -> dict:
        """The algorithm's :data:`DEFAULT_KWARGS`, for a residual with :data:`RESIDUAL_SDE_KWARGS` (unless
        ``algo_kwargs`` sets ``use_sde``) and :data:`RESIDUAL_KWARGS` over them, then ``algo_kwargs`` over
        those (``policy_kwargs`` merged); a copy."""
        kwargs = {k: (dict(v) if isinstance(v, dict) else v) for k, v in DEFAULT_KWARGS[self.algo].items()}
        mine = self.algo_kwargs or {}
        layers = [mine]
        if self.residual is not None:
            layers[:0] = ([] if "use_sde" in mine else [RESIDUAL_SDE_KWARGS.get(self.algo, {})]) + [
                RESIDUAL_KWARGS.get(self.algo, {})]
        for layer in layers:
            for k, v in layer.items():
                kwargs[k] = {**kwargs.get(k, {}), **v} if k == "policy_kwargs" else v
        return kwargs


def make_config(config: TrainConfig | None = None, algo: str | None = None, timesteps: int | None = None,
                **settings) -> TrainConfig:
    """``config`` (default ``TrainConfig()``) with the given fields replaced and checked again.

    ``algo`` and ``timesteps`` left None keep the config's (they are the
    positional arguments of :func:`controllers.rl.train_agent`).

    Raises
    ------
    TypeError
        ``config`` is not a TrainConfig, or a keyword is not one of its fields.
    AgentError
        A bad setting (:class:`TrainConfig`).
    """
    settings.update({k: v for k, v in (("algo", algo), ("timesteps", timesteps)) if v is not None})
    return configured(TrainConfig, config, settings, "training")
