"""Figures of a PD design: closed-loop step responses and the Bode plot of one axis' loop.

Presentation only: every number drawn comes from
:func:`controllers.pd.analysis.loop_analysis`. matplotlib is imported when a
figure is drawn.
"""

from __future__ import annotations

import math
from pathlib import Path

import control
import numpy as np

from heli_core.files import save_figure
from heli_core.params import ModelParams
from heli_core.terms import AXES

from .analysis import loop_analysis
from .controller import PDGains


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_step_responses(params: ModelParams, gains: PDGains, path, dt: float = 0.01, delay_steps: int = 0,
                        t_final: float | None = None) -> Path:
    """Closed-loop attitude step responses of the three axes (:func:`control.step_response`).

    Solid: a step of the reference angle with zero reference rate (derivative on
    the measured rate, the "track" task's steps). Dashed: ``T = L/(1+L)``, where
    the reference rate is fed too. Saved atomically.

    Parameters
    ----------
    params : ModelParams
    gains : PDGains
    path : str or Path
        PNG file.
    dt, delay_steps
        As :func:`loop_analysis`.
    t_final : float, optional
        Duration [s]; default 40/bandwidth of the slowest axis (0.5 s to 30 s).
    """
    plt = _pyplot()
    analyses = [loop_analysis(params, a, *gains.axis(a), dt, delay_steps, gains.d_filter_hz[i])
                for i, a in enumerate(AXES)]
    if t_final is None:
        bws = [a.bandwidth for a in analyses if a.bandwidth and math.isfinite(a.bandwidth) and a.bandwidth > 0]
        t_final = min(max(40.0 / min(bws), 0.5), 30.0) if bws else 5.0
    fig, axs = plt.subplots(1, 3, figsize=(13, 3.8), sharey=False)
    for ax, an in zip(axs, analyses):
        t = np.arange(0.0, t_final + 0.5 * max(dt, 1e-9), dt) if dt else np.linspace(0, t_final, 1000)
        for sys, style, label in ((an.reference_to_angle, "-", "reference step (rate ref 0)"),
                                  (an.complementary, "--", "T = L/(1+L)")):
            r = control.step_response(sys, T=t)
            y = np.squeeze(r.outputs)
            if not an.stable:
                y = np.clip(y, -5, 5)
            ax.plot(r.time, y, style, drawstyle="steps-post" if dt else "default", label=label)
        ax.axhline(1.0, color="0.6", lw=0.8)
        state = "stable" if an.stable else "UNSTABLE"
        ax.set_title(f"{an.axis}: kp={an.kp:.3g}, kd={an.kd:.3g} ({state})\n"
                     f"PM {an.phase_margin:.1f}°, GM {an.gain_margin_db:.1f} dB, bw {an.bandwidth:.3g} rad/s",
                     fontsize=9)
        ax.set_xlabel("time [s]")
        ax.grid(True, alpha=0.3)
    axs[0].set_ylabel("angle / reference [-]")
    axs[0].legend(fontsize=8)
    fig.suptitle(f"PD closed-loop step responses (dt = {dt:g} s, ZOH{'' if not delay_steps else f', delay {delay_steps}'})",
                 fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def plot_bode(params: ModelParams, axis, kp: float, kd: float, path, dt: float = 0.01, delay_steps: int = 0,
              d_filter_hz: float | None = None) -> Path:
    """Bode plot of the loop ``L`` with its gain and phase margins marked; saved atomically.

    The sampled loop (the environment's, with the derivative filter ``d_filter_hz`` when given) is
    drawn with its margins; the continuous loop ``s (kp + kd s) P(s)`` is overlaid dashed to show what
    the zero-order hold and any delay cost in phase.
    """
    plt = _pyplot()
    an = loop_analysis(params, axis, kp, kd, dt, delay_steps, d_filter_hz)
    w_hi = math.pi / dt if dt else 1e3
    omega = np.geomspace(1e-2, w_hi * (0.999 if dt else 1.0), 800)
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    for sys, style, label in ((an.loop, "-", f"L (sampled, dt={dt:g} s)" if dt else "L"),
                              (an.loop_continuous, "--", "L without sampling")):
        if sys is an.loop_continuous and not dt:
            continue
        resp = control.frequency_response(sys, omega)
        mag = np.squeeze(resp.magnitude)
        ph = np.degrees(np.unwrap(np.squeeze(resp.phase)))
        ph -= 360.0 * np.round(ph[0] / 360.0 + 0.25)  # start near -90 deg (integrator)
        ax_m.semilogx(omega, 20 * np.log10(mag), style, label=label)
        ax_p.semilogx(omega, ph, style)
    ax_m.axhline(0.0, color="k", lw=0.7)
    ax_p.axhline(-180.0, color="k", lw=0.7)
    if math.isfinite(an.gain_crossover):
        ax_m.axvline(an.gain_crossover, color="C2", ls=":", lw=1)
        ax_p.axvline(an.gain_crossover, color="C2", ls=":", lw=1)
        ax_p.annotate("", xy=(an.gain_crossover, -180.0 + an.phase_margin), xytext=(an.gain_crossover, -180.0),
                      arrowprops=dict(arrowstyle="<->", color="C2"))
        ax_p.text(an.gain_crossover * 1.1, -180.0 + 0.5 * an.phase_margin, f"PM {an.phase_margin:.1f}°", color="C2")
    if math.isfinite(an.phase_crossover) and math.isfinite(an.gain_margin):
        ax_m.axvline(an.phase_crossover, color="C3", ls=":", lw=1)
        ax_p.axvline(an.phase_crossover, color="C3", ls=":", lw=1)
        ax_m.annotate("", xy=(an.phase_crossover, 0.0), xytext=(an.phase_crossover, -an.gain_margin_db),
                      arrowprops=dict(arrowstyle="<->", color="C3"))
        ax_m.text(an.phase_crossover / 1.1, -0.5 * an.gain_margin_db, f"GM {an.gain_margin_db:.1f} dB ", color="C3",
                  ha="right", va="center")
    if dt:
        for ax in (ax_m, ax_p):
            ax.axvline(math.pi / dt, color="0.5", lw=0.8)
        # placed in axes height (not data), so the final limits cannot push it out of the frame
        ax_m.text(math.pi / dt, 0.97, "Nyquist ", transform=ax_m.get_xaxis_transform(), ha="right", va="top",
                  fontsize=8, color="0.4")
    ax_m.set_ylabel("|L| [dB]")
    ax_p.set_ylabel("phase L [deg]")
    ax_p.set_xlabel("frequency [rad/s]")
    ax_m.legend(fontsize=8, loc="lower left")
    for ax in (ax_m, ax_p):
        ax.grid(True, which="both", alpha=0.3)
    cut = "" if an.d_filter_hz is None else f", D filter {an.d_filter_hz:.3g} Hz"
    ax_m.set_title(f"{an.axis} loop: kp={an.kp:.3g} stick/rad, kd={an.kd:.3g} stick/(rad/s){cut}\n"
                   f"crossover {an.gain_crossover:.3g} rad/s, closed-loop bw {an.bandwidth:.3g} rad/s, "
                   f"{'stable' if an.stable else 'UNSTABLE'}", fontsize=9)
    # Fixed margins, not tight_layout: its extra draw of the log axes' ticks was half the figure's time
    # (0.4 of 0.8 s); these leave room for the two-line title and tick labels down to -1000.
    fig.subplots_adjust(left=0.1, right=0.975, top=0.915, bottom=0.08, hspace=0.09)
    return save_figure(fig, path, dpi=110)

