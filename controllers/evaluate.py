"""One evaluator for every agent: PD controllers and RL policies flown on the same held-out gusts.

:func:`evaluate_agent` flies any policy with stable-baselines3's
``predict(observation, deterministic=True)`` (a :class:`controllers.pd.PDController`,
an SB3 PPO or SAC model) through the native vector environment, one copy per
episode, on gust windows of chosen library traces (by default the held-out side
of :func:`controllers.trace_split.split_traces`). Windows ``(trace, offset)`` are
drawn by ``numpy.random.default_rng(seed)`` and pinned through the
environment's reset options; the environment copies are seeded with ``seed``
too, so two agents evaluated with one seed meet the very same gusts and initial
states, and one agent evaluated twice gives identical results.

Per axis (roll, pitch, yaw) the result reports the sweep's metrics
(:func:`controllers.metrics.error_metrics`): RMS and 50/90/99th percentiles of
|attitude error| [deg] and |rate error| [deg/s], stick RMS and p99, saturation
fraction and a histogram. As in the sweep, each sample is the state at the start
of a control period and the stick applied over it; by default episodes start
level and at rest, as the sweep's replays do (``init_angle_deg=0``,
``init_rate_deg=0``), so the figures measure the gust response alone.
Samples after an episode ended early (|roll| or |pitch| beyond 60°) are not
counted; the number of such episodes is reported.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from heli_core.files import jsonable, save_figure, write_text
from heli_core.terms import AXES

from .errors import AgentError
from .metrics import METRIC_NAMES, error_metrics
from .trace_split import as_segments, draw_windows, split_traces

SCHEMA = "heli-env/agent-evaluation"


def describe_agent(agent) -> tuple[str, str]:
    """(kind, description) of an agent: ("pd", "PD kp=.. kd=.."), ("ppo", "PPO"),
    ("ppo-residual", "PPO ±0.05 stick on PD kp=.. kd=.."), ..."""
    from .pd import PDController
    from .residual import ResidualAgent

    if isinstance(agent, PDController):
        kp = ", ".join(f"{v:.3g}" for v in agent.gains.kp)
        kd = ", ".join(f"{v:.3g}" for v in agent.gains.kd)
        return "pd", f"PD kp=({kp}) kd=({kd})"
    if isinstance(agent, ResidualAgent):
        kind, desc = describe_agent(agent.policy)
        return f"{kind}-residual", f"{desc} ±{agent.scale:g} stick on {describe_agent(agent.base)[1]}"
    kind = type(agent).__name__.lower()
    return kind, type(agent).__name__


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
    """

    name: str
    kind: str
    metrics: dict
    episodes: list
    settings: dict
    samples: dict = field(repr=False, default_factory=dict)

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
                         "axes": {a: {k: self.metrics[a][k] for k in METRIC_NAMES} for a in AXES}})

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
        """A report of this agent: settings, per-axis metrics, episodes."""
        st = self.settings
        lines = [f"# Evaluation of {self.name}", "",
                 f"Model `{st['model']}` (library v{st['library_version']}), task `{st['task']}`, "
                 f"{len(self.episodes)} episodes of {st['episode_seconds']:g} s at dt = {st['dt']:g} s on "
                 f"{st['traces_label']} traces {', '.join(st['trace_ids_used'])}, seed {st['seed']}; "
                 + _start_text(st['init_angle_deg'], st['init_rate_deg']), "",
                 metrics_table([self]), "",
                 f"Mean return {self.mean_return:.2f}; episodes ended early (|roll| or |pitch| > 60°): "
                 f"{self.n_terminated} of {len(self.episodes)}.", "",
                 "| episode | trace | offset [s] | steps | return | ended early |", "|---|---|---|---|---|---|"]
        sr = st["sample_rate"]
        for i, e in enumerate(self.episodes):
            lines.append(f"| {i} | {e['trace']} ({e['trace_id']}) | {e['offset'] / sr:.2f} | {e['steps']} | "
                         f"{e['return']:.2f} | {'yes' if e['terminated'] else 'no'} |")
        return "\n".join(lines) + "\n"

    def plot_episode(self, path, episode: int | None = None, others=()) -> Path:
        """PNG of one episode: attitude and reference, gust u_d and stick per axis (see :func:`plot_episode`)."""
        return plot_episode([self, *others], path, episode)


# --------------------------------------------------------------------- evaluation
def evaluate_agent(agent, model=None, traces=None, episodes_per_trace: int = 2, episode_seconds: float = 30.0,
                   seed: int = 0, task="hold", split=None, init_angle_deg: float = 0.0, init_rate_deg: float = 0.0,
                   name: str | None = None) -> EvaluationResult:
    """Fly an agent on gust windows of the library and measure its error distributions.

    Parameters
    ----------
    agent : object with ``predict(observation, deterministic=True) -> (action, state)``
        A PD controller, an SB3 PPO/SAC model, or any policy of that interface;
        it receives the batch of observations ``(episodes, 12)``.
    model : str, Path, EnvModel or None
        Model directory (None: the shipped model).
    traces : None, str, or sequence of int / TraceSegment
        Gust segments: None or "held-out" the held-out side of ``split``, "train",
        "all", or explicit trace indices / segments.
    episodes_per_trace : int
        Episodes per segment, at distinct offsets where the segment has room.
    episode_seconds : float
        Episode length [s].
    seed : int
        Seeds the window draw and the environment copies.
    task : str or TaskConfig
        Environment task; "hold" by default (the sweep's).
    split : TraceSplit, optional
        Default ``split_traces(n_traces)`` (fraction 0.25, seed 0).
    init_angle_deg, init_rate_deg : float
        Initial roll/pitch and rate ranges [deg], [deg/s] (default 0: start at rest).
    name : str, optional
        Label in reports (default from the agent).

    Returns
    -------
    EvaluationResult

    Raises
    ------
    AgentError
        Bad ``episodes_per_trace``, traces, task or episode length, or episodes
        longer than a gust segment.
    heli_env.errors.EnvModelError
        Missing or corrupt model directory.
    """
    from heli_env.model_dir import EnvModel, load_env_model
    from heli_env.vector_env import HeliAttitudeVectorEnv

    if int(episodes_per_trace) != episodes_per_trace or episodes_per_trace < 1:
        raise AgentError(f"episodes_per_trace must be a whole number >= 1, got {episodes_per_trace!r}")
    t0 = time.perf_counter()
    env_model = model if isinstance(model, EnvModel) else load_env_model(model)
    label = traces if isinstance(traces, str) else ("held-out" if traces is None else "chosen")
    kind, desc = describe_agent(agent)
    try:
        split = split_traces(env_model.n_traces) if split is None else split
        segments = as_segments(traces, split, "held-out")
        E = len(segments) * int(episodes_per_trace)  # draw_windows(per_segment=) gives that many, in order
        env = HeliAttitudeVectorEnv(E, model=env_model, task=task, episode_seconds=episode_seconds,
                                    init_angle_deg=init_angle_deg, init_rate_deg=init_rate_deg)
        windows = draw_windows(env_model, segments, env.spec_.needed, np.random.default_rng(seed),
                               per_segment=int(episodes_per_trace))
    except ValueError as e:  # bad traces, task or episode length; episodes longer than the segments
        raise AgentError(str(e)) from e
    obs, info = env.reset(seed=seed)
    for i, (trace, offset) in enumerate(windows):
        mask = np.zeros(E, dtype=bool)
        mask[i] = True
        obs, info = env.reset(options={"reset_mask": mask, "trace": trace, "offset": offset})
    rec = _fly(agent, env, obs, info)
    seconds = time.perf_counter() - t0

    steps = rec["steps"]
    valid = np.arange(rec["reward"].shape[0])[:, None] < steps[None, :]  # (n, E)
    metrics = {}
    for j, ax in enumerate(AXES):
        metrics[ax] = error_metrics(rec["att_err_deg"][..., j][valid], rec["rate_err_deg_s"][..., j][valid],
                                    rec["action"][..., j][valid])
    returns = np.where(valid, rec["reward"], 0.0).sum(axis=0)
    episodes = [{"trace": int(t), "trace_id": env_model.trace_ids[t], "offset": int(o), "return": float(returns[i]),
                 "steps": int(steps[i]), "terminated": bool(rec["terminated"][i])} for i, (t, o) in enumerate(windows)]
    used = sorted({s.trace for s in segments})
    settings = {
        "model": str(env_model.path), "library_version": env_model.library_version, "seed": int(seed),
        "task": task if isinstance(task, str) else task.task, "dt": env.spec_.dt,
        "episode_seconds": float(episode_seconds), "episodes_per_trace": int(episodes_per_trace),
        "init_angle_deg": float(init_angle_deg), "init_rate_deg": float(init_rate_deg),
        "traces_label": label, "segments": [s.to_dict() for s in segments],
        "trace_ids_used": [env_model.trace_ids[t] for t in used], "split": split.to_dict(),
        "sample_rate": env_model.sample_rate, "seconds": seconds, "agent": desc,
    }
    return EvaluationResult(name or desc, kind, metrics, episodes, settings, rec)


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
    torch = sys.modules.get("torch")
    threads = torch.get_num_threads() if torch is not None else None
    if torch is not None:
        torch.set_num_threads(1)  # small batches: one thread is fastest and keeps results reproducible
    try:
        for k in range(n):
            att[k] = info["attitude_error_deg"]
            rate[k] = info["rate_error_deg_s"]
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


# ------------------------------------------------------------------------ reports
def _fmt(v, spec=".3g"):  # three significant digits: errors range from 1e-4 to 10 degrees
    return "—" if v is None or not math.isfinite(v) else format(v, spec)


def metrics_table(results) -> str:
    """Markdown table of the per-axis metrics of one or more results (rows: agent × axis)."""
    head = ("| agent | axis | RMS att [°] | p50 att [°] | p90 att [°] | p99 att [°] | RMS rate [°/s] | "
            "p90 rate [°/s] | p99 rate [°/s] | stick RMS | stick p99 | saturation |")
    lines = [head, "|" + "---|" * 12]
    for r in results:
        for ax in AXES:
            m = r.metrics[ax]
            lines.append(f"| {r.name} | {ax} | {_fmt(m['att_rms_deg'])} | {_fmt(m['att_p50_deg'])} | "
                         f"{_fmt(m['att_p90_deg'])} | {_fmt(m['att_p99_deg'])} | {_fmt(m['rate_rms_dps'])} | "
                         f"{_fmt(m['rate_p90_dps'])} | {_fmt(m['rate_p99_dps'])} | {_fmt(m['stick_rms'])} | "
                         f"{_fmt(m['stick_p99'])} | {_fmt(100 * m['saturation'], '.1f')} % |")
    return "\n".join(lines)


def plot_episode(results, path, episode: int | None = None) -> Path:
    """PNG of one episode flown by one or more agents on the same gust (saved atomically).

    Columns roll, pitch, yaw; rows: attitude with its reference [deg], the
    replayed gust u_d [stick] and the stick offset each agent applied [stick].
    For the "hold" task the attitude is minus the attitude error and the
    reference is 0; for other tasks the environment's info carries no reference,
    so the attitude error is drawn instead.

    Parameters
    ----------
    results : EvaluationResult or sequence of them
        Evaluated with the same windows and seed (checked), so episode ``i`` is
        the same gust for all.
    episode : int, optional
        Default: the first result's :meth:`EvaluationResult.representative_episode`.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = [results] if isinstance(results, EvaluationResult) else list(results)
    first = results[0]
    key = [(e["trace"], e["offset"]) for e in first.episodes]
    for r in results[1:]:
        if [(e["trace"], e["offset"]) for e in r.episodes] != key or r.settings["seed"] != first.settings["seed"]:
            raise ValueError(f"{r.name} was evaluated on other gust windows than {first.name}; use one seed and "
                             "one set of traces")
    ep = first.representative_episode() if episode is None else int(episode)
    if not 0 <= ep < len(key):
        raise ValueError(f"episode must be in [0, {len(key)}), got {episode!r}")
    dt = first.settings["dt"]
    hold = first.settings["task"] == "hold"
    fig, axs = plt.subplots(3, 3, figsize=(14, 8), sharex=True)
    for j, ax_name in enumerate(AXES):
        for c, r in enumerate(results):
            n = int(r.samples["steps"][ep])
            t = np.arange(n) * dt
            e = r.samples["att_err_deg"][:n, ep, j]
            axs[0, j].plot(t, -e if hold else e, color=f"C{c}", lw=1.0, label=r.name)
            axs[2, j].plot(t, r.samples["action"][:n, ep, j], color=f"C{c}", lw=0.8, label=r.name)
        n = int(first.samples["steps"][ep])
        t = np.arange(n) * dt
        axs[0, j].axhline(0.0, color="k", ls="--", lw=0.8, label="reference" if hold else "zero error")
        axs[1, j].plot(t, first.samples["disturbance"][:n, ep, j], color="k", lw=0.8)
        axs[0, j].set_title(ax_name)
        axs[2, j].set_xlabel("time [s]")
        for row in axs[:, j]:
            row.grid(True, alpha=0.3)
    axs[0, 0].set_ylabel("attitude [deg]" if hold else "attitude error [deg]")
    axs[1, 0].set_ylabel("gust u_d [stick]")
    axs[2, 0].set_ylabel("stick offset [stick]")
    axs[0, 0].legend(fontsize=8, loc="upper right")
    e = first.episodes[ep]
    fig.suptitle(f"episode {ep}: trace {e['trace']} ({e['trace_id']}) from "
                 f"{e['offset'] / first.settings['sample_rate']:.1f} s, task {first.settings['task']}", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=100)


def comparison_markdown(results, title: str = "Agents on the same held-out gusts", notes=()) -> str:
    """Markdown comparing agents evaluated on the same windows: per-axis metrics, returns, p90 ranking."""
    first = results[0]
    st = first.settings
    lines = [f"# {title}", "",
             f"Model `{st['model']}` (library v{st['library_version']}), task `{st['task']}`; "
             f"{len(first.episodes)} episodes of {st['episode_seconds']:g} s on {st['traces_label']} traces "
             f"{', '.join(st['trace_ids_used'])} (windows drawn with seed {st['seed']}); every agent met the same "
             f"gusts and initial states.", "", metrics_table(results), "",
             "| agent | mean return | episodes ended early | p90 att roll/pitch/yaw [°] |", "|---|---|---|---|"]
    for r in results:
        p90 = " / ".join(_fmt(r.metrics[a]["att_p90_deg"]) for a in AXES)
        lines.append(f"| {r.name} | {r.mean_return:.2f} | {r.n_terminated} of {len(r.episodes)} | {p90} |")
    lines += [""] + [f"{n}" for n in notes]
    return "\n".join(lines) + "\n"


def _start_text(angle_deg: float, rate_deg: float) -> str:
    """How the episodes start, in words: level and at rest, or drawn within the given bounds."""
    if angle_deg == 0 and rate_deg == 0:
        return "episodes start level and at rest (the gust response alone, as the sweep's replays)."
    return f"episodes start within ±{angle_deg:g}° and ±{rate_deg:g}°/s of rest."
