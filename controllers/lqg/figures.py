"""Figures of an LQG design: each axis' loop at the plant input, and the recovery from an attitude error.

Presentation only, like :mod:`controllers.pd.figures`: the loop is
:func:`controllers.lqg.design.plant_input_loop` (the one whose margins the design keeps) and the recovery
is :func:`controllers.lqg.design.recovery_response` (the design model's closed loop without noise).
matplotlib is imported when a figure is drawn.
"""

from __future__ import annotations

import math
from pathlib import Path

import control
import numpy as np

from heli_core.files import save_figure

from .design import AxisDesign, LQGDesign, plant_input_loop, recovery_response

RECOVERY_DEG = 2.0
"""The attitude error the recovery figure starts from [deg]: on the shipped model the first sticks are 0.1-0.9,
inside the ±1 the env clips at, so the figure shows the linear loop the margins describe (from 5° roll and pitch
asked 1.4-2.2)."""


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_loop_bode(axis: AxisDesign, path) -> Path:
    """Bode plot of one axis' loop at the plant input, ``L(z) = -C_lqg(z) P(z)``, with the margins the design
    kept (gain crossover and phase margin, the -180° crossings and gain margin); saved atomically."""
    plt = _pyplot()
    model = axis.model
    loop = plant_input_loop(model, axis.K, axis.M)
    omega = np.geomspace(1e-2, math.pi / model.dt * 0.999, 800)
    resp = control.frequency_response(loop, omega)
    mag_db = 20.0 * np.log10(np.maximum(np.squeeze(resp.magnitude), 1e-300))
    phase = np.degrees(np.unwrap(np.squeeze(resp.phase)))
    phase -= 360.0 * np.round((phase[0] + 180.0) / 360.0)  # the low-frequency phase within ±180° of -180°
    fig, (ax_m, ax_p) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    ax_m.semilogx(omega, mag_db, label=f"L at the plant input (sampled, dt={model.dt:g} s)")
    ax_p.semilogx(omega, phase)
    ax_m.axhline(0.0, color="k", lw=0.7)
    for level in -180.0 + 360.0 * np.arange(-3, 2):
        if phase.min() <= level <= phase.max():
            ax_p.axhline(level, color="k", lw=0.7)
    wc = axis.crossover_rad_s
    if math.isfinite(wc):
        for ax in (ax_m, ax_p):
            ax.axvline(wc, color="C2", ls=":", lw=1)
        ax_p.text(wc * 1.1, float(np.interp(wc, omega, phase)), f" PM {axis.phase_margin_deg:.1f}°", color="C2",
                  va="bottom")
    ax_m.text(0.02, 0.05, f"GM {axis.gain_margin_db:.1f} dB (the smallest at a -180° crossing)",
              transform=ax_m.transAxes, color="C3")
    for ax in (ax_m, ax_p):
        ax.axvline(math.pi / model.dt, color="0.5", lw=0.8)
        ax.grid(True, which="both", alpha=0.3)
    ax_m.set_ylabel("|L| [dB]")
    ax_p.set_ylabel("phase [deg]")
    ax_p.set_xlabel("frequency [rad/s]")
    ax_m.legend(fontsize=8, loc="upper right")
    ax_m.set_title(f"{model.axis}: LQG loop at the plant input ({model.n} states, recovery q {axis.recovery:.3g}); "
                   f"crossover {wc:.3g} rad/s", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def plot_recovery(design: LQGDesign, path, seconds: float | None = None) -> Path:
    """The three axes' noise-free recovery from a :data:`RECOVERY_DEG` attitude error, the filter starting from
    its prior as at an episode's start (top: the angle; bottom: the stick, unclipped); saved atomically.
    ``seconds`` defaults to 40 / the lowest crossover (0.5 s to 20 s): the regulator's slowest mode (it removes
    the gust states' offset) is well below the crossover."""
    plt = _pyplot()
    if seconds is None:
        wcs = [a.crossover_rad_s for a in design.axes if math.isfinite(a.crossover_rad_s) and a.crossover_rad_s > 0]
        seconds = min(max(40.0 / min(wcs), 0.5), 20.0) if wcs else 5.0
    fig, (ax_a, ax_u) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for j, axis in enumerate(design.axes):
        t, angle, stick = recovery_response(axis.model, axis.K, axis.M, math.radians(RECOVERY_DEG), seconds)
        ax_a.plot(t, np.degrees(angle), color=f"C{j}", drawstyle="steps-post", label=axis.model.axis)
        ax_u.plot(t, stick, color=f"C{j}", drawstyle="steps-post")
    ax_a.axhline(0.0, color="0.6", lw=0.8)
    ax_u.axhline(0.0, color="0.6", lw=0.8)
    for lim in (-1.0, 1.0):
        ax_u.axhline(lim, color="C3", ls="--", lw=0.8)
    ax_a.set_ylabel("attitude [deg]")
    ax_u.set_ylabel("stick offset (clipped at ±1 in flight)")
    ax_u.set_xlabel("time [s]")
    ax_a.legend(fontsize=8)
    for ax in (ax_a, ax_u):
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"LQG recovery from a {RECOVERY_DEG:g}° attitude error (no gusts or noise; the filter starts from "
                 f"its prior, dt = {design.dt:g} s)", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
