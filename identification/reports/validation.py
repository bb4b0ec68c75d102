"""The validation's figures and tables: Figs. 9-18 and Tables 1-2 of the paper, drawn from a :class:`ValidationResult`.

:func:`plot_rate_fit` draws measured against forward-simulated body rates
(Figs. 9-14, residual Fig. 11) with close-ups where the rate varies most
(:func:`pick_windows`); :func:`plot_attitude_fit` the detrended attitude angles
(Figs. 15-18); :func:`validation_markdown` the error tables in the paper's
layout. The statistics themselves are computed in :mod:`identification.validation.forward_simulation`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from heli_core.files import save_figure
from heli_core.terms import AXES

from ..attitude import detrended_angles
from .figures import DPI, MEASURED_STYLE, model_styles, pyplot
from .tables import markdown_table

if TYPE_CHECKING:
    from ..validation.result import ValidationResult

WINDOW_LENGTH = 10.0
"""Length of the automatic close-up windows of :func:`plot_rate_fit` [s] (Fig. 10)."""

RATE_FIT_TITLE = "Body rates: measured vs forward-simulated models (cf. paper Figs. 9-14)"
"""The title of :func:`plot_rate_fit`'s figure unless told otherwise."""


# ---------------------------------------------------------------------- tables
def validation_markdown(result: ValidationResult) -> str:
    """The rate table (Tables 1-2 layout, models side by side) and the attitude table."""
    labels = result.labels
    header = ["Attitude"]
    for lab in labels:
        header += [f"{lab}: MAE (deg/s)", f"{lab}: 90th pct (deg/s)", f"{lab}: rel. to max (%)"]
    if result.between is not None:
        header.append("MAE between models (deg/s)")
    rows = []
    for axis in AXES:
        row = [f"{axis.capitalize()} rate"]
        for lab in labels:
            s = result.rate_stats[lab][axis]
            row += [f"{s['mae_deg_s']:.4f}", f"{s['p90_deg_s']:.4f}", f"{s['rel_max_pct']:.2f}"]
        if result.between is not None:
            row.append(f"{result.between[axis]:.4f}")
        rows.append(row)
    rate_table = markdown_table(header, rows)

    header = ["Attitude"]
    for lab in labels:
        header += [f"{lab}: MAE (deg)", f"{lab}: std (deg)"]
    rows = []
    for axis in AXES:
        row = [f"{axis.capitalize()} angle"]
        for lab in labels:
            s = result.attitude_stats[lab][axis]
            row += [f"{s['mae_deg']:.4f}", f"{s['std_deg']:.4f}"]
        rows.append(row)
    att_table = markdown_table(header, rows)
    return (
        "**Body-rate error of the forward-simulated models** (Tables 1-2)\n\n"
        f"{rate_table}\n\n"
        f"**Attitude error after removing a piecewise-linear trend over {result.period:g} s pieces** "
        "(eqs. 25-29, Section 3.2)\n\n"
        f"{att_table}\n"
    )


def flight_validation_markdown(checks, figures: bool = True) -> list[str]:
    """The lines of ``report.md``'s section on flights the model was not fitted on
    (:class:`~identification.validation.other_flights.FlightValidation` each): one table row per flight and axis,
    a sentence per diverged simulation, and with ``figures`` a link to each flight's ``validation_N.png``."""
    from ..likelihood.ahead_score import format_r2

    rows, notes = [], []
    for c in checks:
        name = f"{c.name} †" if c.computed_on else c.name
        for axis in c.axes:
            ahead = "—" if c.ahead_r2 is None else format_r2(c.ahead_r2.get(axis))
            fit = "diverged" if c.diverged else f"{c.fit_pct[axis]:.1f}"
            cost = c.cost.get(axis) if c.cost else None
            rows.append([name, axis, fit, "diverged" if c.diverged else format_r2(c.r2[axis]), ahead,
                         "—" if cost is None or not np.isfinite(cost) else f"{cost:.1f}"])
        if c.diverged:
            notes.append(f"- {name}: {c.diverged}")
        if c.computed_on:  # carried over by heli refresh: another model's numbers, said so
            sha = str(c.computed_on.get("model_sha256") or "")
            notes.append(f"- {name}: computed on an earlier model (model.json SHA-256 `{sha[:12]}…`), not on this "
                         f"one: {c.computed_on.get('reason', 'not computed again')}")
    first = checks[0]
    lines = [
        f"The {first.model} model simulated from each flight's sticks alone, from its measured first state and "
        "with the model's offsets, against the measured rates as the fit takes a flight (vibration lines removed, "
        "or the integral method's prefilter), as MATLAB's `compare` does: fit = 100 (1 − ‖y − ŷ‖ / "
        "‖y − ȳ‖) %, R² = 1 − ‖y − ŷ‖² / ‖y − ȳ‖². Wind the sticks cannot explain lowers both on a correct "
        "model; the prediction 0.5 s ahead from the model's Kalman-filtered state (wind state included) does not"
        + (" (— : the integral method has no wind state)" if first.ahead_r2 is None else "")
        + ". J is CIFER's frequency-response cost of the model over the flight's band where the coherence of "
        "stick and rate is 0.6 or more (as in the section below; — : no coherent band).",
        "",
        markdown_table(["Flight", "Axis", "Fit (%)", "R²", "R² 0.5 s ahead", "J"], rows),
        "",
    ]
    if notes:
        lines += notes + [""]
    if figures:
        lines += [f"![{c.name}: measured vs simulated body rates](validation_{i + 1}.png)"
                  for i, c in enumerate(checks) if c.validation is not None] + [""]
    return lines


# ---------------------------------------------------------------------- plots
def pick_windows(time, values, length: float = WINDOW_LENGTH, count: int = 2) -> list[tuple[float, float]]:
    """Non-overlapping windows of ``length`` s where ``values`` varies most.

    The windows maximise the summed variance of ``values`` inside them: the
    variance of every window start comes at once from cumulative sums, and a
    dynamic programme over the starts (one vectorised pass per window) places
    ``count`` windows without overlap. When the flight is shorter than ``count``
    windows, the windows shrink to ``n // count`` samples.

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times [s], uniformly spaced.
    values : array_like, shape (n,)
        Signal to rank the windows by.
    length : float
        Window length [s].
    count : int
        Number of windows.

    Returns
    -------
    list of (float, float)
        ``(t_start, t_end)`` [s] of each window (first and last sample), in time order.
    """
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    n = time.size
    if count < 1 or n < 2 * count:
        raise ValueError(f"need at least {2 * count} samples for {count} windows, got {n}")
    dt = float(np.median(np.diff(time)))
    w = max(2, min(int(round(length / dt)) + 1, n // count))
    c1 = np.concatenate([[0.0], np.cumsum(values - values.mean())])
    c2 = np.concatenate([[0.0], np.cumsum((values - values.mean()) ** 2)])
    s1 = c1[w:] - c1[:-w]
    var = (c2[w:] - c2[:-w]) / w - (s1 / w) ** 2  # variance of the window starting at each sample
    m = var.size
    # best[s]: best total of k windows, the last starting at s; prev[k][s]: start of window k-1
    best = var.copy()
    prev = []
    for _ in range(count - 1):
        arg = np.arange(m)
        arg = np.maximum.accumulate(np.where(best >= np.maximum.accumulate(best), arg, 0))
        run = np.maximum.accumulate(best)  # run[j] = max(best[:j + 1]), reached at arg[j]
        j = np.arange(m) - w
        ok = j >= 0
        best = np.where(ok, var + run[np.clip(j, 0, None)], -np.inf)
        prev.append(np.where(ok, arg[np.clip(j, 0, None)], -1))
    starts = [int(np.argmax(best))]
    for back in reversed(prev):
        starts.append(int(back[starts[-1]]))
    return [(float(time[s]), float(time[s + w - 1])) for s in sorted(starts)]


def plot_rate_fit(result: ValidationResult, path, windows=None, title: str = RATE_FIT_TITLE):
    """Measured vs modelled body rates, the analog of Figs. 9-14 (residual: Fig. 11).

    For each axis: the whole flight (Figs. 9, 12, 13a) with the close-up
    windows shaded, two close-ups R1 and R2 (Figs. 10, 13b, 14) and the
    residual measured - modelled over the whole flight (Fig. 11). Rates are in
    deg/s; the legend gives each model's mean absolute error.

    Parameters
    ----------
    result : ValidationResult
    path : str or Path
        Destination PNG, written atomically.
    windows : sequence of two (float, float), optional
        Close-up windows ``(t_start, t_end)`` [s] used on every axis. Default:
        per axis, the two 10 s windows where the measured rate varies most
        (:func:`pick_windows`).
    title : str
        The figure's title (default :data:`RATE_FIT_TITLE`).

    Returns
    -------
    Path
        ``path``.
    """
    plt = pyplot()
    meas = np.degrees(result.measured_rates)
    sims = {lab: np.degrees(v) for lab, v in result.simulated.items()}
    if windows is not None:
        windows = [(float(a), float(b)) for a, b in windows]
        if len(windows) != 2 or any(not b > a for a, b in windows):
            raise ValueError(f"windows must be two (t_start, t_end) pairs with t_end > t_start, got {windows}")

    fig = plt.figure(figsize=(15, 13))
    outer = fig.add_gridspec(3, 1, hspace=0.3)
    for i, axis in enumerate(AXES):
        wins = windows if windows is not None else pick_windows(result.time, meas[i])
        _draw_rate_axis(fig, outer[i], result, i, meas[i], {lab: v[i] for lab, v in sims.items()}, wins)
    fig.suptitle(title, fontsize=13)
    fig.subplots_adjust(left=0.06, right=0.985, top=0.93, bottom=0.05)
    return save_figure(fig, path, dpi=DPI)


def _draw_rate_axis(fig, cell, result: ValidationResult, i: int, meas, sims, wins) -> None:
    """One axis' row of :func:`plot_rate_fit` in grid cell ``cell``: the whole flight with the windows
    shaded, the residual below it, and the two close-ups beside them (rates ``meas``, ``sims`` in deg/s)."""
    t = result.time
    axis = AXES[i]
    labels = result.labels
    styles = model_styles(labels)
    row = cell.subgridspec(1, 2, width_ratios=[2.3, 1], wspace=0.14)
    left = row[0].subgridspec(2, 1, hspace=0.08)
    right = row[1].subgridspec(2, 1, hspace=0.45)
    ax_full = fig.add_subplot(left[0])
    ax_res = fig.add_subplot(left[1], sharex=ax_full)
    ax_r = [fig.add_subplot(right[0]), fig.add_subplot(right[1])]

    ax_full.plot(t, meas, **MEASURED_STYLE)
    for lab in labels:
        mae = result.rate_stats[lab][axis]["mae_deg_s"]
        ax_full.plot(t, sims[lab], **styles[lab], lw=0.9, label=f"{lab} (MAE {mae:.2f} deg/s)")
        ax_res.plot(t, meas - sims[lab], **styles[lab], lw=0.8, label=lab)
    for k, (a, b) in enumerate(wins):
        ax_full.axvspan(a, b, color="0.88", zorder=0)
        ax_full.text(0.5 * (a + b), 0.97, f"R{k + 1}", transform=ax_full.get_xaxis_transform(),
                     ha="center", va="top", fontsize=9, fontweight="bold")
    ax_full.set_title(f"{axis.capitalize()} rate: measured vs simulated", loc="left", fontsize=11)
    ax_full.set_ylabel(f"{axis} rate [deg/s]")
    ax_full.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=8, ncol=1 + len(labels),
                   frameon=False, borderaxespad=0.1)
    ax_full.tick_params(labelbottom=False)
    ax_res.axhline(0.0, color="0.5", lw=0.6)
    ax_res.set_ylabel("measured − model\n[deg/s]")
    ax_res.set_xlabel("time [s]")
    ax_full.set_xlim(t[0], t[-1])

    for k, (ax, (a, b)) in enumerate(zip(ax_r, wins)):
        m = (t >= a) & (t <= b)
        ax.plot(t[m], meas[m], **MEASURED_STYLE)
        for lab in labels:
            ax.plot(t[m], sims[lab][m], **styles[lab], lw=1.0, label=lab)
        ax.set_xlim(a, b)
        ax.set_title(f"Close-up R{k + 1} ({a:.1f}-{b:.1f} s)", fontsize=9, loc="left")
        ax.set_ylabel(f"{axis} rate [deg/s]", fontsize=8)
        ax.grid(alpha=0.3)
    ax_r[1].set_xlabel("time [s]")
    for ax in (ax_full, ax_res):
        ax.grid(alpha=0.3)


def plot_attitude_fit(result: ValidationResult, path):
    """Detrended measured vs modelled attitude angles, the analog of Figs. 15-18.

    Left, per axis: measured and modelled angles after removing the best
    piecewise-linear function over ``result.period`` s pieces (Figs. 16-18);
    right: the residual measured - modelled (Fig. 15). Angles in degrees; the
    legend gives each model's mean absolute error.

    Parameters
    ----------
    result : ValidationResult
        Must carry ``measured_attitude`` (as built by
        :func:`~identification.validation.forward_simulation.validate_models`).
    path : str or Path
        Destination PNG, written atomically.

    Returns
    -------
    Path
        ``path``.
    """
    if result.measured_attitude is None:
        raise ValueError("result has no measured_attitude; build it with validate_models")
    plt = pyplot()
    t = result.time
    labels = result.labels
    styles = model_styles(labels)
    meas = detrended_angles(t, result.measured_attitude, result.period)
    sims = {lab: detrended_angles(t, v, result.period) for lab, v in result.simulated_attitude.items()}
    names = ("roll angle φ", "pitch angle θ", "yaw angle ψ")

    fig, axes = plt.subplots(3, 2, figsize=(15, 10), sharex=True, gridspec_kw={"width_ratios": [2.3, 1]})
    for i, axis in enumerate(AXES):
        ax, ax_res = axes[i]
        ax.plot(t, meas[i], **MEASURED_STYLE)
        for lab in labels:
            s = result.attitude_stats[lab][axis]
            ax.plot(t, sims[lab][i], **styles[lab], lw=0.9,
                    label=f"{lab} (MAE {s['mae_deg']:.2f}°, std {s['std_deg']:.2f}°)")
            ax_res.plot(t, meas[i] - sims[lab][i], **styles[lab], lw=0.8, label=lab)
        ax.set_title(names[i].capitalize(), loc="left", fontsize=11)  # short: the legend shares its line
        ax.set_ylabel(f"detrended {axis} [deg]")
        ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=8, ncol=1 + len(labels),
                  frameon=False, borderaxespad=0.1)
        ax_res.axhline(0.0, color="0.5", lw=0.6)
        ax_res.set_title(f"Residual, {axis}", loc="left", fontsize=11)
        ax_res.set_ylabel("measured − model [deg]")
        for a in (ax, ax_res):
            a.grid(alpha=0.3)
    for a in axes[-1]:
        a.set_xlabel("time [s]")
    axes[0, 0].set_xlim(t[0], t[-1])
    fig.suptitle(
        f"Attitude: measured vs the models' quaternion-derived angles, after removing a piecewise-linear trend "
        f"over {result.period:g} s pieces (cf. paper Figs. 15-18)", fontsize=13,
    )
    fig.tight_layout()
    return save_figure(fig, path, dpi=DPI)
