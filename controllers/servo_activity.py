"""Servo activity: how hard a controller works its sticks, as numbers and as a figure.

A controller can hold attitude well and still chatter: a PD whose D term sees the
raw gyro rate puts ``kd`` times the gyro noise on the stick every period, and the
servos follow it at the control rate. Error percentiles do not show that; the
stick's *increment per control period* does. Per axis:

* ``stick_rms`` — RMS of the stick offset from trim [stick];
* ``stick_step_rms`` — RMS of the increment ``u[k] - u[k-1]`` [stick per period]:
  about ``sqrt(2)`` times the stick's RMS for white chatter, near 0 for a smooth stick;
* ``stick_step_p99`` — 99th percentile of ``|u[k] - u[k-1]|`` [stick per period];
* ``stick_hf_fraction`` — the share of the stick's variance above :data:`HF_HZ`
  (Welch spectrum), the part a servo can barely follow.

Computed from an evaluation's recorded episodes (:class:`controllers.evaluate.EvaluationResult`
``samples``), each episode up to its own end. :func:`plot_servo_activity` draws a stretch
of the stick of one episode and its spectrum per axis for one or more agents flown on the
same gusts; matplotlib is imported when a figure is drawn.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from heli_core.files import save_figure
from heli_core.terms import AXES

ACTIVITY_NAMES = ("stick_rms", "stick_step_rms", "stick_step_p99", "stick_hf_fraction")
"""Per-axis figures of :func:`stick_activity`, in report order."""
HF_HZ = 10.0
"""Frequency above which the stick's variance counts as high-frequency activity [Hz]."""
ZOOM_SECONDS = 2.0
"""Length of the stretch of stick the figure draws [s] (a whole episode at 100 Hz hides the chatter)."""


def _episodes(action, steps):
    """Each episode's stick ``(n_e, 3)`` up to its end, for an action array ``(n, E, 3)`` and ``steps (E,)``."""
    action = np.asarray(action, dtype=np.float64)
    steps = np.asarray(steps, dtype=np.int64)
    if action.ndim != 3 or action.shape[2] != 3 or steps.shape != (action.shape[1],):
        raise ValueError(f"action must be (steps, episodes, 3) with one length per episode, got {action.shape} "
                         f"and steps {steps.shape}")
    return [action[:int(n), e] for e, n in enumerate(steps)]


def stick_spectrum(action, steps, dt: float, nperseg: int = 256):
    """Welch power spectral density of the stick per axis, averaged over episodes weighted by their length.

    Parameters
    ----------
    action : ndarray, shape (n, E, 3)
        Stick offsets from trim [stick], per period, episode and axis.
    steps : ndarray of int, shape (E,)
        Each episode's length in periods.
    dt : float
        Control period [s].
    nperseg : int
        Welch segment length (shorter episodes use their own length).

    Returns
    -------
    freq : ndarray (nf,)
        [Hz], 0 to the Nyquist frequency.
    psd : ndarray (3, nf)
        [stick²/Hz]; NaN when no episode has 8 periods.
    """
    from scipy.signal import welch

    eps = [e for e in _episodes(action, steps) if e.shape[0] >= 8]
    nps = int(min([nperseg] + [e.shape[0] for e in eps])) if eps else nperseg
    freq = np.fft.rfftfreq(nps, dt)
    if not eps:
        return freq, np.full((3, freq.size), np.nan)
    total, weight = 0.0, 0
    for e in eps:
        f, p = welch(e.T, fs=1.0 / dt, nperseg=nps, axis=-1)
        total, weight = total + e.shape[0] * p, weight + e.shape[0]
    return f, total / weight


def stick_activity(action, steps, dt: float) -> dict:
    """Per-axis servo activity (:data:`ACTIVITY_NAMES`) of recorded episodes.

    Parameters as :func:`stick_spectrum`.

    Returns
    -------
    dict of str -> dict of str -> float
        ``{"roll": {"stick_rms": ..., "stick_step_rms": ..., ...}, ...}``; NaN where there is nothing to measure.
    """
    eps = _episodes(action, steps)
    sticks = np.concatenate(eps) if eps else np.zeros((0, 3))
    increments = np.concatenate([np.diff(e, axis=0) for e in eps]) if eps else np.zeros((0, 3))
    freq, psd = stick_spectrum(action, steps, dt)
    high = freq > HF_HZ
    out = {}
    for j, ax in enumerate(AXES):
        var = float(np.sum(psd[j]))
        out[ax] = {
            "stick_rms": float(np.sqrt(np.mean(sticks[:, j] ** 2))) if sticks.size else float("nan"),
            "stick_step_rms": float(np.sqrt(np.mean(increments[:, j] ** 2))) if increments.size else float("nan"),
            "stick_step_p99": float(np.percentile(np.abs(increments[:, j]), 99)) if increments.size else float("nan"),
            "stick_hf_fraction": float(np.sum(psd[j][high]) / var) if var > 0 else float("nan"),
        }
    return out


def activity_table(results) -> str:
    """Markdown table of the servo activity of evaluated agents (rows: agent × axis)."""
    lines = ["| agent | axis | stick RMS | RMS stick step per period | p99 of abs(stick step) | "
             f"variance above {HF_HZ:g} Hz |", "|---|---|---|---|---|---|"]
    for r in results:
        for ax in AXES:
            a = r.activity[ax]
            lines.append(f"| {r.name} | {ax} | {a['stick_rms']:.3g} | {a['stick_step_rms']:.3g} | "
                         f"{a['stick_step_p99']:.3g} | {100 * a['stick_hf_fraction']:.1f} % |")
    return "\n".join(lines)


def plot_servo_activity(results, path, episode: int | None = None) -> Path:
    """PNG of the sticks of one or more agents flown on the same gusts (saved atomically).

    Columns roll, pitch, yaw. Top row: :data:`ZOOM_SECONDS` of the stick of one episode from its middle
    [stick]; bottom row: the stick's Welch spectrum over every episode [stick²/Hz], each agent labelled
    with its RMS stick step per period.

    Parameters
    ----------
    results : sequence of EvaluationResult
        Evaluated on the same windows (episode ``i`` is the same gust for all).
    path : str or Path
    episode : int, optional
        Default: the first result's representative episode.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = list(results)
    first = results[0]
    dt = first.settings["dt"]
    ep = first.representative_episode() if episode is None else int(episode)
    n = int(min(r.samples["steps"][ep] for r in results))
    zoom = max(2, min(n, int(round(ZOOM_SECONDS / dt))))
    k0 = max(0, n // 2 - zoom // 2)
    fig, axs = plt.subplots(2, 3, figsize=(14, 6.5))
    for c, r in enumerate(results):
        freq, psd = stick_spectrum(r.samples["action"], r.samples["steps"], dt)
        for j, ax_name in enumerate(AXES):
            t = (k0 + np.arange(zoom)) * dt
            axs[0, j].step(t, r.samples["action"][k0:k0 + zoom, ep, j], where="post", color=f"C{c}", lw=0.9,
                           label=r.name)
            label = f"{r.name}: step RMS {r.activity[ax_name]['stick_step_rms']:.3g}"
            axs[1, j].loglog(freq[1:], np.maximum(psd[j][1:], 1e-16), color=f"C{c}", lw=1.0, label=label)
    for j, ax_name in enumerate(AXES):
        axs[0, j].set_title(f"{ax_name}: stick, {zoom * dt:g} s of episode {ep}", fontsize=9)
        axs[0, j].set_xlabel("time [s]")
        axs[1, j].axvline(HF_HZ, color="0.5", ls=":", lw=0.8)
        axs[1, j].set_xlabel("frequency [Hz]")
        axs[1, j].legend(fontsize=7, loc="lower left")
        for row in axs[:, j]:
            row.grid(True, which="both", alpha=0.3)
    axs[0, 0].set_ylabel("stick offset [stick]")
    axs[1, 0].set_ylabel("stick PSD [stick²/Hz]")
    axs[0, 0].legend(fontsize=8, loc="upper right")
    fig.suptitle(f"servo activity at dt = {dt:g} s (RMS stick step per period in the legend)", fontsize=10)
    # Fixed margins, not tight_layout: its extra draw of the log axes' ticks was about half the figure's time.
    fig.subplots_adjust(left=0.06, right=0.99, top=0.9, bottom=0.08, wspace=0.2, hspace=0.32)
    return save_figure(fig, path, dpi=100)
