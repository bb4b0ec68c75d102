"""One evaluator for every agent: PD controllers and RL policies flown on the same held-out gusts.

:func:`evaluate_agent` flies any policy with stable-baselines3's
``predict(observation, deterministic=True)`` (a :class:`controllers.pd.PDController`,
an SB3 PPO or SAC model; an agent whose ``predict`` also takes SB3's ``state`` and
``episode_start`` gets them, so one with memory flies as it trained) through the native vector environment, one copy per
episode, on gust windows of chosen library traces (by default the held-out side
of :func:`controllers.trace_split.split_traces`). Windows ``(trace, offset)`` are
drawn by ``numpy.random.default_rng(seed)`` and pinned through the
environment's reset options; the environment copies are seeded with ``seed``
too, so two agents evaluated with one seed meet the very same gusts and initial
states, and one agent evaluated twice gives identical results.

Per axis (roll, pitch, yaw) the result reports the sweep's metrics
(:func:`controllers.metrics.error_metrics`): RMS and 50/90/99th percentiles of
|attitude error| [deg] and |rate error| [deg/s], stick RMS and p99, saturation
fraction and a histogram; and how hard the agent works its servos
(:func:`controllers.servo_activity.stick_activity`: the stick's RMS increment per
control period and its variance above 10 Hz). As in the sweep, each sample is the state at the start
of a control period and the stick applied over it; by default episodes start
level and at rest, as the sweep's replays do (``init_angle_deg=0``,
``init_rate_deg=0``), so the figures measure the gust response alone.
Samples after an episode ended early (|roll| or |pitch| beyond 60°) are not
counted; the number of such episodes is reported.

The Markdown reports and the episode figure are in :mod:`controllers.evaluate_report`.
"""

from __future__ import annotations

import inspect
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from heli_core.config import check, configured, is_real, whole_number
from heli_core.deprecation import module_getattr, moved_method
from heli_core.files import jsonable, write_text
from heli_core.terms import AXES

from .agent_description import describe_agent
from .errors import AgentError
from .metrics import METRIC_NAMES, error_metrics
from .servo_activity import stick_activity
from .trace_split import TraceSplit, as_segments, draw_windows, split_traces

SCHEMA = "heli-env/agent-evaluation"


@dataclass(eq=False)
class EvaluationResult:
    """Error distributions of one agent over a set of gust episodes.

    Attributes
    ----------
    name : str
        Label of the agent in reports.
    kind : str
        "pd", "ppo", "sac", or the agent's class name.
    metrics : dict of str -> dict
        Per axis ("roll", "pitch", "yaw"): :data:`controllers.metrics.METRIC_NAMES`
        (floats), ``n_samples``, ``hist_edges``, ``hist_counts``, ``hist_overflow``.
    episodes : list of dict
        Per episode: ``trace``, ``trace_id``, ``offset`` [sample], ``return``,
        ``steps``, ``terminated``.
    settings : dict
        Model, library version, seed, task, dt, episode length, segments, timing.
    samples : dict of ndarray
        ``att_err_deg``, ``rate_err_deg_s``, ``action``, ``disturbance`` of shape
        (steps, episodes, 3), ``reward`` (steps, episodes), ``steps`` (episodes,):
        the recorded episodes (not written to JSON).
    activity : dict of str -> dict
        Per axis, the servo activity (:func:`controllers.servo_activity.stick_activity`).
    """

    name: str
    kind: str
    metrics: dict
    episodes: list
    settings: dict
    samples: dict = field(repr=False, default_factory=dict)
    activity: dict = field(default_factory=dict)

    @property
    def mean_return(self) -> float:
        return float(np.mean([e["return"] for e in self.episodes]))

    @property
    def n_terminated(self) -> int:
        return int(sum(e["terminated"] for e in self.episodes))

    def summary(self) -> dict:
        """Scalar metrics per axis, mean return and early ends (JSON-ready)."""
        return jsonable({"name": self.name, "kind": self.kind, "mean_return": self.mean_return,
                         "terminated_episodes": self.n_terminated, "episodes": len(self.episodes),
                         "axes": {a: {k: self.metrics[a][k] for k in METRIC_NAMES} for a in AXES},
                         "servo_activity": self.activity})

    def representative_episode(self) -> int:
        """The episode whose RMS attitude error (three axes) is the median of the episodes' (lower median)."""
        s = self.samples
        steps = s["steps"]
        rms = np.array([np.sqrt(np.mean(s["att_err_deg"][:n, e] ** 2)) for e, n in enumerate(steps)])
        order = np.argsort(rms, kind="stable")
        return int(order[(len(order) - 1) // 2])

    def to_dict(self) -> dict:
        doc = {"schema": SCHEMA, "schema_version": 1, "name": self.name, "kind": self.kind,
               "settings": self.settings, "summary": self.summary(), "episodes": self.episodes,
               "histograms": {a: {"quantity": "|attitude error| [deg]", "edges": self.metrics[a]["hist_edges"],
                                  "counts": self.metrics[a]["hist_counts"],
                                  "overflow": self.metrics[a]["hist_overflow"]} for a in AXES}}
        return jsonable(doc)

    def to_json(self, path) -> Path:
        """Write settings, metrics, episodes and histograms as JSON (NaN as null), atomically."""
        return write_text(path, json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n")

    def markdown(self) -> str:
        """Deprecated: :func:`controllers.evaluate_report.evaluation_markdown` renders the report."""
        return moved_method("EvaluationResult.markdown", "controllers.evaluate_report", "evaluation_markdown", self)

    def plot_episode(self, path, episode: int | None = None, others=()) -> Path:
        """Deprecated: :func:`controllers.evaluate_report.plot_episode` draws the episode."""
        return moved_method("EvaluationResult.plot_episode", "controllers.evaluate_report", "plot_episode",
                            [self, *others], path, episode)

    def plot_servo_activity(self, path, episode: int | None = None, others=()) -> Path:
        """PNG of the stick's stretch and spectrum per axis
        (:func:`controllers.servo_activity.plot_servo_activity`), ``others`` flown on the same gusts beside it."""
        from .servo_activity import plot_servo_activity

        return plot_servo_activity([self, *others], path, episode)


# --------------------------------------------------------------------- evaluation
@dataclass(frozen=True)
class EvaluationConfig:
    """Settings of :func:`evaluate_agent`: which gust episodes an agent flies (all but the agent and the model).

    ``evaluate_agent(agent, model, config)`` flies them; keyword settings replace its fields
    (``evaluate_agent(agent, model, config, seed=3)``). One config flies several agents on the very same
    episodes.

    Attributes
    ----------
    traces : None, str, or sequence of int / TraceSegment
        Gust segments: None or "held-out" the held-out side of ``split``, "train",
        "all", or explicit trace indices / segments.
    episodes_per_trace : int
        Episodes per segment, at distinct offsets where the segment has room, >= 1.
    episode_seconds : float
        Episode length [s], > 0.
    seed : int
        Seeds the window draw and the environment copies, >= 0.
    task : str or TaskConfig
        Environment task; "hold" by default (the sweep's).
    split : TraceSplit, optional
        Default ``split_traces(n_traces)`` (fraction 0.25, seed 0).
    init_angle_deg, init_rate_deg : float
        Initial roll/pitch and rate ranges [deg], [deg/s], >= 0 (default 0: start at rest).
    dt : float, optional
        Control period the environment runs at [s], > 0 and a whole number of the gust traces' sample periods;
        None (default): a PD or LQG controller's own ``dt`` (the period it was designed for), for any other agent
        the environment's 0.01 s. A PD is flown at the period it was designed for, its D filter's pole with it (an
        LQG's matrices are sampled at it); a model identified from a 50 Hz log can only be flown at 0.02 s or a
        multiple.

    Raises
    ------
    AgentError
        (a ValueError) A field out of range; the message names it, what was expected and what came. The
        traces, the task and episodes longer than a gust segment are checked against the model, by
        :func:`evaluate_agent`.
    """

    traces: object = None
    episodes_per_trace: int = 2
    episode_seconds: float = 30.0
    seed: int = 0
    task: object = "hold"
    split: TraceSplit | None = None
    init_angle_deg: float = 0.0
    init_rate_deg: float = 0.0
    dt: float | None = None

    def __post_init__(self):
        for name, minimum in (("episodes_per_trace", 1), ("seed", 0)):
            object.__setattr__(self, name, whole_number(getattr(self, name), name, minimum, AgentError))
        check(is_real(self.episode_seconds) and self.episode_seconds > 0, "episode_seconds",
              "a positive number of seconds", self.episode_seconds, AgentError)
        for name in ("init_angle_deg", "init_rate_deg"):
            value = getattr(self, name)
            check(is_real(value) and value >= 0, name, "a number >= 0", value, AgentError)
        check(self.split is None or isinstance(self.split, TraceSplit), "split", "a TraceSplit or None", self.split,
              AgentError)
        check(self.dt is None or (is_real(self.dt) and self.dt > 0), "dt", "None or a positive control period in s",
              self.dt, AgentError)


def evaluate_agent(agent, model=None, config: EvaluationConfig | None = None, *, name: str | None = None,
                   **settings) -> EvaluationResult:
    """Fly an agent on gust windows of the library and measure its error distributions.

    Parameters
    ----------
    agent : object with ``predict(observation, deterministic=True) -> (action, state)``
        A PD controller, an SB3 PPO/SAC model, or any policy of that interface;
        it receives the batch of observations ``(episodes, 12)``.
    model : str, Path, EnvModel or None
        Model directory (None: the shipped model).
    config : EvaluationConfig, optional
        The episodes flown (default ``EvaluationConfig()``), described there.
    name : str, optional
        Label in reports (default from the agent).
    **settings
        :class:`EvaluationConfig` fields replacing the config's (``traces="all", episodes_per_trace=4, ...``).

    Returns
    -------
    EvaluationResult

    Raises
    ------
    AgentError
        Bad settings, traces, task or episode length, or episodes longer than a gust segment.
    TypeError
        ``config`` is not an EvaluationConfig, or a keyword is not one of its fields.
    heli_env.errors.EnvModelError
        Missing or corrupt model directory.
    """
    from heli_env.env_model import as_env_model
    from heli_env.vector_env import HeliAttitudeVectorEnv

    cfg = configured(EvaluationConfig, config, settings, "evaluation")
    t0 = time.perf_counter()
    env_model = as_env_model(model)
    traces = cfg.traces
    label = traces if isinstance(traces, str) else ("held-out" if traces is None else "chosen")
    kind, desc = describe_agent(agent)
    try:
        split = split_traces(env_model.n_traces) if cfg.split is None else cfg.split
        segments = as_segments(traces, split, "held-out")
        E = len(segments) * cfg.episodes_per_trace  # draw_windows(per_segment=) gives that many, in order
        dt = cfg.dt if cfg.dt is not None else (agent.dt if kind in ("pd", "lqg") else None)
        env = HeliAttitudeVectorEnv(E, model=env_model, task=cfg.task, episode_seconds=cfg.episode_seconds,
                                    init_angle_deg=cfg.init_angle_deg, init_rate_deg=cfg.init_rate_deg,
                                    **({"dt": float(dt)} if is_real(dt) else {}))
        windows = draw_windows(env_model, segments, env.spec_.needed, np.random.default_rng(cfg.seed),
                               per_segment=cfg.episodes_per_trace)
    except ValueError as e:  # bad traces, task or episode length; episodes longer than the segments
        raise AgentError(str(e)) from e
    rec = _fly(agent, env, *_reset_on(env, windows, cfg.seed))
    seconds = time.perf_counter() - t0
    metrics, episodes = _tally(rec, windows, env_model.trace_ids)
    used = sorted({s.trace for s in segments})
    settings = {
        "model": str(env_model.path), "library_version": env_model.library_version, "seed": cfg.seed,
        "task": cfg.task if isinstance(cfg.task, str) else cfg.task.task, "dt": env.spec_.dt,
        "episode_seconds": float(cfg.episode_seconds), "episodes_per_trace": cfg.episodes_per_trace,
        "init_angle_deg": float(cfg.init_angle_deg), "init_rate_deg": float(cfg.init_rate_deg),
        "traces_label": label, "segments": [s.to_dict() for s in segments],
        "trace_ids_used": [env_model.trace_ids[t] for t in used], "split": split.to_dict(),
        "sample_rate": env_model.sample_rate, "seconds": seconds, "agent": desc,
    }
    activity = stick_activity(rec["action"], rec["steps"], env.spec_.dt)
    return EvaluationResult(name or desc, kind, metrics, episodes, settings, rec, activity)


def _reset_on(env, windows, seed: int):
    """Reset every copy with ``seed``, then copy ``i`` on gust window ``windows[i]``; the last (obs, info)."""
    obs, info = env.reset(seed=seed)
    for i, (trace, offset) in enumerate(windows):
        mask = np.zeros(env.num_envs, dtype=bool)
        mask[i] = True
        obs, info = env.reset(options={"reset_mask": mask, "trace": trace, "offset": offset})
    return obs, info


def _tally(rec: dict, windows, trace_ids) -> tuple[dict, list]:
    """Per-axis metrics over the recorded samples of the episodes (up to each one's end), and the episodes' rows."""
    steps = rec["steps"]
    valid = np.arange(rec["reward"].shape[0])[:, None] < steps[None, :]  # (n, E)
    metrics = {}
    for j, ax in enumerate(AXES):
        metrics[ax] = error_metrics(rec["att_err_deg"][..., j][valid], rec["rate_err_deg_s"][..., j][valid],
                                    rec["action"][..., j][valid])
    returns = np.where(valid, rec["reward"], 0.0).sum(axis=0)
    episodes = [{"trace": int(t), "trace_id": trace_ids[t], "offset": int(o), "return": float(returns[i]),
                 "steps": int(steps[i]), "terminated": bool(rec["terminated"][i])} for i, (t, o) in enumerate(windows)]
    return metrics, episodes


def _takes_memory(agent) -> bool:
    """Whether ``agent.predict`` takes SB3's ``state`` and ``episode_start`` (SB3 models, the PD, a residual with
    a history); a plain ``predict(observation, deterministic=True)`` is called without them."""
    try:
        params = inspect.signature(agent.predict).parameters
    except (TypeError, ValueError):  # a builtin or C-level predict: no signature to read
        return False
    return {"state", "episode_start"} <= set(params) or any(p.kind is p.VAR_KEYWORD for p in params.values())


def _fly(agent, env, obs, info) -> dict:
    """Step all copies with the agent until every episode has ended once; record the first episodes."""
    E, n = env.num_envs, env.spec_.episode_steps
    att = np.zeros((n, E, 3))
    rate = np.zeros((n, E, 3))
    act = np.zeros((n, E, 3))
    dist = np.zeros((n, E, 3))
    rew = np.zeros((n, E))
    steps = np.full(E, n, dtype=np.int64)
    terminated = np.zeros(E, dtype=bool)
    alive = np.ones(E, dtype=bool)
    state = None  # an agent with memory (a stacked history, a recurrent policy) carries it here
    memory = _takes_memory(agent)
    torch = sys.modules.get("torch")
    threads = torch.get_num_threads() if torch is not None else None
    if torch is not None:
        torch.set_num_threads(1)  # small batches: one thread is fastest and keeps results reproducible
    try:
        for k in range(n):
            att[k] = info["attitude_error_deg"]
            rate[k] = info["rate_error_deg_s"]
            if memory:
                a, state = agent.predict(obs, state=state, episode_start=np.full(E, k == 0), deterministic=True)
            else:
                a, _ = agent.predict(obs, deterministic=True)
            a = np.clip(np.asarray(a, dtype=np.float64).reshape(E, 3), -1.0, 1.0)  # the env clips the same way
            act[k] = a
            obs, r, term, trunc, info = env.step(a)
            dist[k] = info["disturbance"]  # the gust of the period just flown
            rew[k] = r
            ended = alive & (term | trunc)
            terminated |= alive & term
            steps[ended] = k + 1
            alive &= ~ended
            if not alive.any():
                break
    finally:
        if torch is not None:
            torch.set_num_threads(threads)
    return {"att_err_deg": att, "rate_err_deg_s": rate, "action": act, "disturbance": dist, "reward": rew,
            "steps": steps, "terminated": terminated}


__getattr__ = module_getattr(__name__)
"""The report's tables this module re-exported (deprecated: :mod:`controllers._deprecated`)."""
