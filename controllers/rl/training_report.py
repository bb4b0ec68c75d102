"""What a training run gave: the agent against a PD on the same held-out gusts, the learning curve, the report.

A trained agent is worth flying only where it holds attitude better than the PD the project
designs in a second. After a run, :func:`compare_with_pd` flies the final agent and a PD
(by default ``heli design``'s, :func:`reference_pd`) through the one evaluator
(:func:`controllers.evaluate.evaluate_agent`) on the run's held-out segments, same windows and
seed for both, and :class:`PDComparison` says per axis which holds the smaller p90 |attitude
error| — and, loudly, where the agent is worse (:meth:`PDComparison.warning`). After one minute
of PPO on the shipped model an agent held pitch at p90 37° against the PD's 0.09°, and nothing
said so.

:func:`plot_learning_curve` draws the run's learning curve (:class:`controllers.sb3_training.LearningCurve`):
training episode returns and held-out evaluation returns against timesteps, and the held-out p90
per axis with the PD's p90 as a line to beat. :func:`training_markdown` is the run's ``report.md``.
Presentation and evaluation only: nothing here trains.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from heli_core.files import jsonable, save_figure
from heli_core.terms import AXES

COMPARISON_EPISODES_PER_TRACE = 4
"""Episodes per held-out segment flown by both agents (``heli evaluate``'s default)."""


def reference_pd(env_model, dt: float | None = None):
    """The PD ``heli design`` writes for a model with its defaults (bandwidth, 45° margin, D filter, and the
    control period: the environment's for the model unless ``dt``)."""
    from heli_core.control_period import default_dt

    from ..pd.controller import PDController
    from ..pd.design import DEFAULT_D_FILTER, design_gains

    dt = default_dt(env_model.sample_rate) if dt is None else dt
    gains = design_gains(env_model.params, dt=dt, d_filter_hz=DEFAULT_D_FILTER)
    return PDController.from_model(env_model.params, gains, dt)


@dataclass(eq=False)
class PDComparison:
    """The final agent and a PD flown on the same held-out windows.

    Attributes
    ----------
    agent, pd : controllers.evaluate.EvaluationResult
    pd_label : str
        Where the PD came from ("heli design's defaults", a file).
    base_kind : str
        What the compared controller is, for the messages: "PD", or "LQG" when a residual's base (or
        ``--compare-pd``) is an LQG controller (``heli design --lqg``).
    """

    agent: object
    pd: object
    pd_label: str
    base_kind: str = "PD"

    def p90(self, which: str) -> list:
        """p90 |attitude error| per axis [deg] of ``"agent"`` or ``"pd"``."""
        res = self.agent if which == "agent" else self.pd
        return [float(res.metrics[a]["att_p90_deg"]) for a in AXES]

    @property
    def ratios(self) -> list:
        """Agent p90 / PD p90 per axis (inf where the PD's is 0 and the agent's is not)."""
        out = []
        for a, p in zip(self.p90("agent"), self.p90("pd")):
            out.append(a / p if p > 0 else (1.0 if a == 0 else math.inf))
        return out

    @property
    def worse_axes(self) -> list:
        """Axes where the agent's p90 is larger than the PD's, or where it ended episodes early and the PD did not."""
        worse = [ax for ax, r in zip(AXES, self.ratios) if not r <= 1.0]  # NaN (nothing measured) counts as worse
        if self.agent.n_terminated > self.pd.n_terminated and not worse:
            worse = list(AXES)
        return worse

    def warning(self) -> str | None:
        """One line naming every axis the agent holds worse than the PD, with both p90s; None if none."""
        worse = self.worse_axes
        if not worse:
            return None
        a, p = dict(zip(AXES, self.p90("agent"))), dict(zip(AXES, self.p90("pd")))
        kind = self.base_kind
        axes = ", ".join(f"{ax} p90 {a[ax]:.3g}° against the {kind}'s {p[ax]:.3g}° (x{_ratio(a[ax], p[ax])})"
                         for ax in worse)
        early = (f"; it ended {self.agent.n_terminated} of {len(self.agent.episodes)} episodes early"
                 if self.agent.n_terminated else "")
        return (f"WARNING: the agent holds attitude worse than the {kind} ({self.pd_label}) on the held-out gusts: "
                f"{axes}{early}. Fly the {kind}, or train longer / as a residual on it (--residual).")

    def table(self) -> str:
        """Markdown: per axis the agent's and the PD's p90 |attitude error|, their ratio and which is better."""
        kind = self.base_kind
        lines = [f"| axis | agent p90 [°] | {kind} p90 [°] | agent / {kind} | better |", "|---|---|---|---|---|"]
        for ax, a, p, r in zip(AXES, self.p90("agent"), self.p90("pd"), self.ratios):
            better = "agent" if r < 1.0 else (kind if not r <= 1.0 else "equal")
            lines.append(f"| {ax} | {a:.4g} | {p:.4g} | {_ratio(a, p)} | {better} |")
        lines.append(f"| episodes ended early | {self.agent.n_terminated} of {len(self.agent.episodes)} | "
                     f"{self.pd.n_terminated} of {len(self.pd.episodes)} | | |")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready: the PD, both p90s, ratios, the axes the agent is worse on, the windows' settings."""
        st = self.agent.settings
        return jsonable({"pd": self.pd_label, "pd_agent": self.pd.settings["agent"], "base_kind": self.base_kind,
                         "agent_p90_deg": dict(zip(AXES, self.p90("agent"))),
                         "pd_p90_deg": dict(zip(AXES, self.p90("pd"))), "ratio": dict(zip(AXES, self.ratios)),
                         "worse_axes": self.worse_axes, "agent_terminated": self.agent.n_terminated,
                         "pd_terminated": self.pd.n_terminated, "episodes": len(self.agent.episodes),
                         "episode_seconds": st["episode_seconds"], "seed": st["seed"],
                         "segments": st["segments"], "trace_ids": st["trace_ids_used"]})


def _ratio(a: float, p: float) -> str:
    if not (math.isfinite(a) and math.isfinite(p)):
        return "—"
    return f"{a / p:.3g}" if p > 0 else ("1" if a == 0 else "∞")


def compare_with_pd(agent, pd, env_model, segments, seed: int, episode_seconds: float, task="hold",
                    pd_label: str = "heli design's defaults",
                    episodes_per_trace: int = COMPARISON_EPISODES_PER_TRACE) -> PDComparison:
    """Fly ``agent`` and ``pd`` through the one evaluator on the same windows of ``segments``.

    Parameters
    ----------
    agent : object with SB3's ``predict``
        The trained agent as :func:`controllers.rl.load_agent` returns it (a residual with its base).
    pd : controllers.pd.PDController
    env_model : heli_env.env_model.EnvModel
    segments : sequence of TraceSegment
        The run's held-out segments.
    seed : int
        Seeds the windows and the environment copies (the run's seed): same seed, same comparison.
    episode_seconds : float
        Episode length [s] (the run's).
    task : str or TaskConfig
        The run's task.
    pd_label : str
        Where the PD came from, for the report and the warning.
    episodes_per_trace : int
        Episodes per segment.

    Returns
    -------
    PDComparison
    """
    from ..evaluate import EvaluationConfig, evaluate_agent

    config = EvaluationConfig(traces=list(segments), episodes_per_trace=episodes_per_trace,
                              episode_seconds=episode_seconds, seed=seed, task=task)
    kind = base_kind(pd)
    return PDComparison(evaluate_agent(agent, env_model, config, name="agent"),
                        evaluate_agent(pd, env_model, config, name=kind), pd_label, kind)


def base_kind(controller) -> str:
    """What the messages call the compared controller, asked of it (:func:`controllers.agent_description.
    describe_agent`): "PD", "LQG", ..."""
    from ..agent_description import describe_agent

    return describe_agent(controller)[0].upper()


def plot_learning_curve(curve: dict, path, comparison: PDComparison | None = None, timesteps: int | None = None,
                        title: str = "learning curve") -> Path:
    """PNG of a run's learning curve (saved atomically).

    Top: each training episode's return (dots) and its running mean over 20 episodes, and the held-out
    evaluations' mean return, against timesteps. Bottom: the held-out evaluations' p90 |attitude error|
    per axis (log scale), with the final comparison's agent p90 at ``timesteps`` (crosses) and the PD's as
    dashed lines: the level to beat.

    Parameters
    ----------
    curve : dict
        :meth:`controllers.sb3_training.LearningCurve.record`.
    path : str or Path
    comparison : PDComparison, optional
    timesteps : int, optional
        Where the final comparison stands on the x axis (the run's timesteps).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_r, ax_e) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    episodes = np.asarray(curve.get("episodes") or np.zeros((0, 2)), dtype=float).reshape(-1, 2)
    evals = curve.get("evaluations") or []
    errors = []  # every p90 drawn: a log scale when all are positive
    if episodes.size:
        ax_r.plot(episodes[:, 0], episodes[:, 1], ".", ms=3, color="0.6", label="training episode")
        k = min(20, len(episodes))
        mean = np.convolve(episodes[:, 1], np.ones(k) / k, mode="valid")
        ax_r.plot(episodes[k - 1:, 0], mean, color="C0", label=f"running mean of {k}")
    if evals:
        t = [e["timesteps"] for e in evals]
        ax_r.plot(t, [e["mean_return"] for e in evals], "o-", color="C3", label="held-out evaluation")
        p90 = np.array([e["p90_deg"] for e in evals], dtype=float)
        errors += list(p90.ravel())
        for j, ax_name in enumerate(AXES):
            ax_e.plot(t, p90[:, j], "o-", color=f"C{j}", label=f"{ax_name} (held-out evaluations)")
    if comparison is not None:
        x = timesteps if timesteps is not None else (evals[-1]["timesteps"] if evals else 0)
        errors += comparison.p90("agent") + comparison.p90("pd")
        for j, (ax_name, a, p) in enumerate(zip(AXES, comparison.p90("agent"), comparison.p90("pd"))):
            ax_e.plot([x], [a], "x", ms=9, mew=2, color=f"C{j}", label=f"{ax_name}: final agent")
            ax_e.axhline(p, color=f"C{j}", ls="--", lw=1, label=f"{ax_name}: {comparison.base_kind} {p:.3g}°")
    if not (episodes.size or evals or comparison is not None):
        ax_r.text(0.5, 0.5, "no episode finished and no evaluation ran", transform=ax_r.transAxes, ha="center")
    ax_r.set_ylabel("episode return")
    ax_e.set_ylabel("p90 |attitude error| [deg]")
    ax_e.set_xlabel("timesteps")
    if errors and np.all(np.isfinite(errors)) and min(errors) > 0:
        ax_e.set_yscale("log")
    for ax in (ax_r, ax_e):
        ax.grid(True, which="both", alpha=0.3)
        if ax.has_data():
            ax.legend(fontsize=7, loc="best", ncol=2)
    ax_r.set_title(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=100)


def training_markdown(result, comparison: PDComparison | None, figure: str | None = "learning_curve.png") -> str:
    """The run's ``report.md``: the warning first (if any), the comparison with the PD, the learning curve."""
    meta = result.metadata
    why = " (time budget reached)" if result.stopped_by_time else ""
    lines = [f"# Training of {result.path.name}", ""]
    if comparison is not None and comparison.warning():
        lines += [f"**{comparison.warning()}**", ""]
    lines += [f"{result.algo.upper()} on model `{meta.get('model')}` (library v{meta.get('library_version')}), seed "
              f"{meta.get('seed')}, {meta.get('n_envs')} environment copies: {result.timesteps} timesteps in "
              f"{result.seconds:.1f} s{why}.", ""]
    if comparison is not None:
        c = comparison.to_dict()
        kind = comparison.base_kind
        lines += [f"## The agent against the {kind}", "",
                  f"The final agent and the {kind} ({comparison.pd_label}: {c['pd_agent']}) flown by the one evaluator "
                  f"on the same {c['episodes']} held-out episodes of {c['episode_seconds']:g} s (traces "
                  f"{', '.join(c['trace_ids'])}, seed {c['seed']}), p90 |attitude error|:", "",
                  comparison.table(), ""]
    curve = result.learning_curve or {}
    evals = curve.get("evaluations") or []
    lines += ["## Learning curve", "",
              f"{len(curve.get('episodes') or [])} training episodes finished; {len(evals)} held-out evaluations"
              + (f", the last at {evals[-1]['timesteps']} timesteps: mean return {evals[-1]['mean_return']:.3g}, p90 "
                 + ", ".join(f"{a} {v:.3g}°" for a, v in zip(AXES, evals[-1]['p90_deg'])) if evals else "")
              + ".", ""]
    if evals and comparison is not None:
        lines += ["The evaluations during training fly windows of the same held-out segments drawn with their own "
                  f"seed, starting as training episodes do (within ±{meta.get('init_angle_deg', 0):g}° and "
                  f"±{meta.get('init_rate_deg', 0):g}°/s); the comparison above starts at rest, as `heli evaluate` "
                  "does, so their p90s differ.", ""]
    if figure:
        lines += [f"![learning curve]({figure})", ""]
    return "\n".join(lines)
