"""Reports of agent evaluations (:mod:`controllers.evaluate`): Markdown tables and the episode figure.

Presentation only: the numbers come from :class:`controllers.evaluate.EvaluationResult`
(per-axis metrics, episodes, recorded samples). Three significant digits, as the
errors range from 1e-4 to 10 degrees; matplotlib is imported when a figure is drawn.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from heli_core.files import save_figure
from heli_core.terms import AXES

from .servo_activity import activity_table


def evaluation_markdown(result) -> str:
    """A report of one agent's evaluation: settings, per-axis metrics, episodes."""
    st = result.settings
    lines = [f"# Evaluation of {result.name}", "",
             f"Model `{st['model']}` (library v{st['library_version']}), task `{st['task']}`, "
             f"{len(result.episodes)} episodes of {st['episode_seconds']:g} s at dt = {st['dt']:g} s on "
             f"{st['traces_label']} traces {', '.join(st['trace_ids_used'])}, seed {st['seed']}; "
             + _start_text(st['init_angle_deg'], st['init_rate_deg']), "",
             metrics_table([result]), "",
             "Servo activity (the stick's increment per control period shows chatter that the errors hide):", "",
             activity_table([result]), "",
             f"Mean return {result.mean_return:.2f}; episodes ended early (|roll| or |pitch| > 60°): "
             f"{result.n_terminated} of {len(result.episodes)}.", "",
             "| episode | trace | offset [s] | steps | return | ended early |", "|---|---|---|---|---|---|"]
    sr = st["sample_rate"]
    for i, e in enumerate(result.episodes):
        lines.append(f"| {i} | {e['trace']} ({e['trace_id']}) | {e['offset'] / sr:.2f} | {e['steps']} | "
                     f"{e['return']:.2f} | {'yes' if e['terminated'] else 'no'} |")
    return "\n".join(lines) + "\n"


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

    from .evaluate import EvaluationResult

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
