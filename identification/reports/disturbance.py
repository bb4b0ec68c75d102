"""The identified disturbance in a report: its Markdown section and Figs. 19-21 of the paper.

:func:`profile_markdown` writes the section of ``report.md`` on a
:class:`~identification.disturbance.profile.DisturbanceProfile` (the disturbance table
of Section 3.3 and the simulation table of Section 3.4); :func:`save_figures`
draws the profile (Fig. 19), the distributions of stick and disturbance
(Figs. 20-21) and the rates simulated with the disturbance (Section 3.4).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy import stats

from heli_core.files import save_figure
from heli_core.terms import AXES, INPUT_FOR_AXIS

from ..disturbance.profile import MODEL_LABELS, compare_with_truth, interval90
from ..disturbance.smoothing import SMOOTHING_WINDOW
from ..errors import DisturbanceError
from .figures import DPI, pyplot
from .tables import markdown_table
from .validation import plot_rate_fit

if TYPE_CHECKING:
    from ..disturbance.profile import DisturbanceProfile


# ------------------------------------------------------------------- markdown
def profile_markdown(profile: DisturbanceProfile, title: str = "Wind disturbance (Sections 2.5.3, 3.3)") -> str:
    """Report section under the heading ``### title``: the disturbance table (Section 3.3) and the
    simulation table (Section 3.4)."""
    rows = []
    for a in profile.axes:
        i = AXES.index(a)
        s = profile.statistics[a]
        rows.append([
            a.capitalize(), f"{profile.kd[i]:.4f}", str(s["passes"]), str(s["auto_passes"]), f"{s['ud_std']:.4f}",
            "[{:.4f}, {:.4f}]".format(*s["ud_interval90"]),
            "[{:.4f}, {:.4f}]".format(*s["stick_interval90"]),
            f"{s['ks_statistic']:.3f}", f"{s['ks_pvalue']:.3g}",
        ])
    table = markdown_table(["Axis", "kd (rad/s²)", "passes", "passes by the paper's rule", "std u_d",
                            "90 % interval u_d", "90 % interval recorded stick", "KS statistic", "KS p-value"], rows)
    mode = "chosen by matching fitted normals (Section 3.3)" if profile.smoothing == "auto" else "fixed"
    text = [
        f"### {title}\n",
        f"Piecewise-constant disturbance torque over Δt = {profile.interval:g} s "
        f"({profile.samples_per_interval} samples, {profile.n_intervals} intervals), eq. (46); "
        f"equivalent input u_d = (ū_d − kd)/k, eqs. (42), (47). Smoothing: {SMOOTHING_WINDOW}-point moving "
        f"average, passes {mode}. Source: {profile.source.get('name')} "
        f"(SHA-256 {str(profile.source.get('sha256'))[:12]}…).\n",
        table + "\n",
        "The paper's rule matches the fitted normal of u_d to that of the stick (minus its mean); the KS test "
        "compares the two samples (a small p-value says they differ).\n",
    ]
    if profile.trace_source in ("smoother", "posterior draw"):
        text += _smoother_section(profile)
    if profile.simulation_diverged:
        text += [f"**Simulating the model with the identified disturbance: diverged.** "
                 f"{profile.simulation_diverged}.\n"]
    if profile.simulation is not None:
        text += _simulation_section(profile)
    return "\n".join(text)


def _smoother_section(profile: DisturbanceProfile) -> list[str]:
    """Paragraphs on the stored trace when it is the smoother's wind rather than eq. (46)'s profile."""
    rows = [[a.capitalize(), f"{profile.kd[AXES.index(a)]:.4f}", f"{profile.statistics[a]['smoother_ud_std']:.4f}",
             "[{:.4f}, {:.4f}]".format(*profile.statistics[a]["smoother_ud_interval90"]),
             f"{profile.statistics[a]['ud_std']:.4f}",
             f"{profile.statistics[a]['smoother_vs_eq46_correlation']:.3f}"] for a in profile.axes]
    header = ["Axis", "kd (rad/s²)", "std u_d (smoother)", "90 % interval u_d (smoother)",
              "std u_d (eq. 46, smoothed)", "correlation smoother vs eq. 46"]
    if profile.trace_source == "posterior draw":
        for row, a in zip(rows, profile.axes):
            row += [f"{profile.statistics[a]['draw_ud_std']:.4f}",
                    "[{:.4f}, {:.4f}]".format(*profile.statistics[a]["draw_ud_interval90"])]
        return [
            "**Stored trace: a draw from the smoother's posterior.** The library stores (and the environment "
            "and the sweeps replay) one draw of the wind torque given the flight, by the simulation smoother "
            "of Durbin & Koopman (2002) on the maximum-likelihood model's Rauch-Tung-Striebel smoother "
            f"(seed {profile.trace_draw['seed']}, from the flight's SHA-256), over the control gain: it "
            "follows the flight's gusts where the gyro saw them and has the identified wind's full power "
            "where it could not. The smoother's conditional mean, the best estimate of the wind that blew, "
            "is smoother than any wind (its std below); it is kept for the figures and the comparison with "
            "a known wind. kd is the model's offset plus the flight's mean wind. The eq. (46) profile above "
            "is kept for the paper's comparison.\n",
            markdown_table(header + ["std u_d (stored draw)", "90 % interval u_d (stored draw)"], rows) + "\n",
        ]
    return [
        "**Stored trace: the smoother's wind.** The library stores (and the environment replays) the wind "
        "torque that the Rauch-Tung-Striebel smoother of the maximum-likelihood model estimated at every "
        "sample, over the control gain; kd is the model's offset plus the flight's mean wind. The eq. (46) "
        "profile above is kept for the paper's comparison.\n",
        markdown_table(header, rows) + "\n",
    ]


def _simulation_section(profile: DisturbanceProfile) -> list[str]:
    """The simulation table of Section 3.4: rate and angle errors without and with the disturbance."""
    rows = []
    for a in profile.axes:
        r0 = profile.simulation.rate_stats[MODEL_LABELS[0]][a]
        r1 = profile.simulation.rate_stats[MODEL_LABELS[1]][a]
        a0 = profile.simulation.attitude_stats[MODEL_LABELS[0]][a]
        a1 = profile.simulation.attitude_stats[MODEL_LABELS[1]][a]
        rows.append([a.capitalize(), f"{r0['mae_deg_s']:.4f}", f"{r1['mae_deg_s']:.4f}",
                     f"{r1['p90_deg_s']:.4f}", f"{a0['mae_deg']:.4f}", f"{a1['mae_deg']:.4f}",
                     f"{a1['std_deg']:.4f}"])
    return [
        "**Simulating the model with the identified disturbance** (Section 3.4; paper: roll-rate MAE "
        "0.095 deg/s, roll-angle MAE 0.28°)\n",
        markdown_table(["Axis", "rate MAE without (deg/s)", "rate MAE with (deg/s)", "90th pct with (deg/s)",
                        "angle MAE without (deg)", "angle MAE with (deg)", "angle error std with (deg)"],
                       rows) + "\n",
    ]


# --------------------------------------------------------------------- figures
def plot_profile(profile: DisturbanceProfile, path, true_ud=None):
    """The identified disturbance profile u_d against time, the analog of Fig. 19.

    Per axis: u_d before smoothing (light) and after (the stored profile), with
    the true wind of a synthetic flight when ``true_ud`` (3, n) is given.
    """
    plt = pyplot()
    fig, axs = plt.subplots(len(profile.axes), 1, figsize=(13, 2.9 * len(profile.axes) + 0.6), sharex=True,
                            squeeze=False)
    t_int = profile.interval_starts
    truth = compare_with_truth(profile, true_ud) if true_ud is not None else None
    for ax, a in zip(axs[:, 0], profile.axes):
        i = AXES.index(a)
        ax.step(t_int, profile.ud_raw[i], where="post", color="0.7", lw=0.6, label="eq. (46), unsmoothed")
        if profile.trace_mean is None:
            ax.step(profile.time, profile.trace[i], where="post", color="C0", lw=1.0,
                    label=f"smoothed, {profile.passes[i]} passes")
        else:  # the stored draw, and the smoother's mean it was drawn about
            ax.plot(profile.time, profile.trace[i], color="C2", lw=0.6, alpha=0.7,
                    label="posterior draw (stored trace)")
            ax.plot(profile.time, profile.trace_mean[i], color="C0", lw=1.0, label="smoother mean")
        if true_ud is not None:
            tr = np.asarray(true_ud)[i]
            c = truth[a]
            ax.plot(profile.time, tr - tr.mean(), color="C3", lw=0.9, ls="--",
                    label=f"true wind (corr {c['correlation']:.3f}, RMS err {c['rms_error']:.4f})")
        ax.axhline(0.0, color="0.4", lw=0.5)
        name = {"roll": "lateral cyclic", "pitch": "longitudinal cyclic", "yaw": "pedal"}[a]
        ax.set_ylabel(f"u_d {a}\n[{name}, stick units]")
        ax.set_title(f"{a.capitalize()}: identified disturbance, kd = {profile.kd[i]:.4f} rad/s²", loc="left",
                     fontsize=10)
        ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=8, ncol=3, frameon=False,
                  borderaxespad=0.1)
        ax.grid(alpha=0.3)
    axs[-1, 0].set_xlabel("time [s]")
    axs[0, 0].set_xlim(profile.time[0], profile.time[-1])
    fig.suptitle(f"Identified wind disturbance u_d, Δt = {profile.interval:g} s (cf. paper Fig. 19)", fontsize=12)
    fig.tight_layout()
    return save_figure(fig, path, dpi=DPI)


def plot_distributions(profile: DisturbanceProfile, path):
    """Histograms of the pilot's stick and of u_d with fitted normals and 90 % intervals, Figs. 20-21."""
    plt = pyplot()
    fig, axs = plt.subplots(len(profile.axes), 2, figsize=(12, 3.0 * len(profile.axes) + 0.6), squeeze=False)
    for row, a in zip(axs, profile.axes):
        i = AXES.index(a)
        s = profile.statistics[a]
        stick = profile.sticks[i] - profile.sticks[i].mean()
        _draw_histogram(row[0], stick, f"{a.capitalize()}: pilot {INPUT_FOR_AXIS[i]} stick − mean", "C1")
        _draw_histogram(row[1], profile.ud[i], f"{a.capitalize()}: disturbance u_d", "C0", stick=stick)
        row[1].text(0.02, 0.95, f"{s['passes']} passes\nKS D = {s['ks_statistic']:.3f}\np = {s['ks_pvalue']:.2g}",
                    transform=row[1].transAxes, va="top", fontsize=8,
                    bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "0.7"})
    fig.suptitle("Pilot stick vs identified disturbance: histograms and fitted normals (cf. paper Figs. 20-21)",
                 fontsize=12)
    fig.tight_layout()
    return save_figure(fig, path, dpi=DPI)


def _draw_histogram(ax, x, title: str, color: str, stick=None) -> None:
    """Histogram of ``x`` with its fitted normal and 90 % interval; with ``stick``, the stick's normal too."""
    ax.hist(x, bins=60, density=True, color=color, alpha=0.45, label="histogram")
    mu, sd = stats.norm.fit(x)
    lo_x, hi_x = np.percentile(x, [0.1, 99.9])
    xs = np.linspace(lo_x, hi_x, 300)
    ax.plot(xs, stats.norm.pdf(xs, mu, sd), color=color, lw=1.6, label=f"fitted normal (σ = {sd:.4f})")
    if stick is not None:
        mu_s, sd_s = stats.norm.fit(stick)
        ax.plot(xs, stats.norm.pdf(xs, mu_s, sd_s), color="C1", lw=1.0, ls=":",
                label=f"stick's fitted normal (σ = {sd_s:.4f})")
    lo, hi = interval90(x)
    for v in (lo, hi):
        ax.axvline(v, color="k", ls="--", lw=0.8)
    ax.plot([], [], color="k", ls="--", lw=0.8, label=f"90 %: [{lo:.4f}, {hi:.4f}]")
    ax.set_ylim(top=ax.get_ylim()[1] * 1.35)  # room for the legend
    ax.set_title(title, loc="left", fontsize=10)
    ax.set_xlabel("stick units")
    ax.set_ylabel("density")
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(alpha=0.3)


def plot_simulation(profile: DisturbanceProfile, path):
    """Measured vs simulated rates without and with the identified disturbance (Section 3.4)."""
    if profile.simulation is None:
        raise DisturbanceError("the profile holds no simulation; identify it with simulate=True")
    return plot_rate_fit(profile.simulation, path, title="Body rates simulated without and with the identified "
                         "wind disturbance (Section 3.4)")


def figure_names(profile: DisturbanceProfile) -> tuple:
    """The figures :func:`save_figures` draws of ``profile``, each written as ``<prefix>_<name>.png``."""
    return ("profile", "distributions") + (("simulation",) if profile.simulation is not None else ())


def save_figures(profile: DisturbanceProfile, directory, true_ud=None, prefix: str = "disturbance") -> dict[str, Path]:
    """Write the profile, distribution and (when simulated) rate figures as PNG into ``directory``:
    ``<prefix>_<name>.png`` for each of :func:`figure_names`."""
    directory = Path(directory)
    draw = {"profile": lambda path: plot_profile(profile, path, true_ud), "distributions":
            lambda path: plot_distributions(profile, path), "simulation": lambda path: plot_simulation(profile, path)}
    return {name: draw[name](directory / f"{prefix}_{name}.png") for name in figure_names(profile)}
