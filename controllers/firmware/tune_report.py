"""The report of a firmware tune: the comparison, its figures and a flight-test card, as Markdown.

Reads a :class:`~controllers.firmware.tune.TuneResult` (and, where the log records one, what the log actually
flew: :class:`~controllers.firmware.flown.FlownErrors`); draws nothing it is not asked to and fits nothing.
"""

from __future__ import annotations

import math

import numpy as np

from heli_core.terms import AXES

LABELS = ("current", "default", "proposed")


def _fmt(v, digits=3) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "inf" if isinstance(v, float) and math.isinf(v) else "–"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


def _p(stats: dict, q: int) -> str:
    if stats.get("diverged", True):
        return "diverged"
    lo, hi = stats.get(f"p{q}_deg_interval", [None, None])
    inter = f" ({_fmt(lo)}–{_fmt(hi)})" if lo is not None and hi is not None else ""
    return f"{stats[f'p{q}_deg']:.3g}{inter}"


def _margins(stats: dict) -> str:
    if not stats.get("stable"):
        return "unstable"
    dm = stats.get("delay_margin_s")
    delay = "" if dm is None else f" / {_fmt(dm * 1000 if math.isfinite(dm) else dm)} ms"
    return f"{_fmt(stats.get('gain_margin_db'))} dB / {_fmt(stats.get('phase_margin_deg'))}°{delay}"


def comparison_table(result) -> list:
    """Markdown lines: per axis the three sets' p50/p90/p99 (90 % intervals), margins, frequency-domain p90."""
    lines = ["| axis | set | p50 [deg] | p90 [deg] (90 % interval) | p99 [deg] | margins GM / PM / delay | "
             "frequency-domain p90 [deg] |", "|---|---|---|---|---|---|---|"]
    for axis in AXES:
        row = result.axes[axis]
        for label in LABELS:
            s = row[label]
            lines.append(f"| {axis} | {label} | {_p(s, 50).split(' ')[0]} | {_p(s, 90)} | {_p(s, 99).split(' ')[0]} "
                         f"| {_margins(s)} | {_fmt(s.get('fd_p90_deg'))} |")
    return lines


def gains_table(result) -> list:
    """Markdown lines: every gain of every axis, current / default / proposed (changed ones in bold)."""
    lines = ["| parameter | current | default | proposed |", "|---|---|---|---|"]
    seen = set()
    for axis in AXES:
        row = result.axes[axis]
        for name, value in row["proposed"]["gains"].items():
            if name in seen:
                continue
            seen.add(name)
            cur, dflt = row["current"]["gains"][name], row["default"]["gains"][name]
            prop = f"**{value:.4g}**" if not math.isclose(value, cur, rel_tol=1e-9, abs_tol=1e-12) else f"{value:.4g}"
            lines.append(f"| {name} | {cur:.4g} | {dflt:.4g} | {prop} |")
    return lines


def _robust_margins(result) -> str:
    """The margins a robust set keeps, as the report words them ("6 dB, 45° and 25 ms of delay margin")."""
    ms = 1000.0 * result.settings.get("min_delay_margin_s", 0.025)
    return f"6 dB, 45° and {ms:g} ms of delay margin" if ms > 0 else "6 dB and 45° (no delay margin: --delay-margin 0)"


def verdict_lines(result) -> list:
    """One sentence per axis: change against current and defaults, and whether the defaults are near best."""
    out = []
    for axis in AXES:
        row = result.axes[axis]
        cur, dflt, prop = (row[k] for k in LABELS)
        if row["kept_current"]:
            out.append(f"- **{axis}**: no swept set kept {_robust_margins(result)}; the current gains are kept.")
            continue
        p_prop = prop.get("p90_deg")
        parts = []
        for name, other in (("current", cur), ("the defaults", dflt)):
            if other.get("diverged", True):
                parts.append(f"{name} diverged in these gusts")
            else:
                parts.append(f"{(p_prop / other['p90_deg'] - 1) * 100:+.0f} % against {name}")
        near = " The defaults are already near best (within 10 %)." if row["defaults_near_best"] else ""
        out.append(f"- **{axis}**: p90 {p_prop:.3g} deg, {', '.join(parts)}; margins {_margins(prop)}.{near}")
    return out


def flown_lines(result, flown) -> list:
    """The log's own attitude error beside the predicted one for the current gains (issue 32.4)."""
    if flown is None:
        return []
    lines = ["## What the log flew", ""]
    if not flown.available:
        return lines + [f"Not available: {flown.reason}.", ""]
    lines += [f"Attitude error against the desired attitude in the log ({flown.reason}; {flown.seconds:.0f} s kept), "
              "beside the prediction for the gains it flew (current):", "",
              "| axis | flown p50 | flown p90 | flown p99 | predicted p90 (current) |", "|---|---|---|---|---|"]
    for axis in AXES:
        f, c = flown.axes[axis], result.axes[axis]["current"]
        lines.append(f"| {axis} | {f['p50_deg']:.3g} | {f['p90_deg']:.3g} | {f['p99_deg']:.3g} | {_p(c, 90)} |")
    return lines + ["", "The flown errors include the pilot's small corrections and any model error; the "
                    "prediction flies the identified gusts only.", ""]


def flight_card(result, files: dict) -> list:
    """The flight-test card: what to fly first, what to watch, how to revert."""
    fw = result.firmware
    load = ("Mission Planner: Config → Full Parameter List → Load from file, then Write Params; MAVProxy: "
            f"`param load {files['proposed']}`" if fw == "ardupilot"
            else f"Rotorflight Configurator: CLI tab, select the PID profile you fly (`profile 0`), paste "
                 f"{files['proposed']} (it ends with `save`)")
    revert = (f"load `{files['current']}` the same way" if fw == "ardupilot"
              else f"paste `{files['current']}` in the CLI the same way")
    raps = []
    for axis in AXES:
        cur, prop = (result.axes[axis][k].get("step") for k in ("current", "proposed"))
        if prop and not prop.get("diverged") and prop.get("rise_90_s") is not None:
            was = "" if not cur or cur.get("diverged") or cur.get("overshoot_pct") is None else \
                f" (current gains: {cur['overshoot_pct']:.0f} %)"
            raps.append(f"{axis} reaches 90 % of a {prop['step_deg']:g}° command in {prop['rise_90_s']:.2f} s and "
                        f"overshoots {prop['overshoot_pct']:.0f} %{was}")
    worst = max(AXES, key=lambda a: (result.axes[a]["proposed"].get("p90_deg") or 0.0))
    pm = min((result.axes[a]["proposed"].get("phase_margin_deg") or math.inf) for a in AXES)
    lines = ["## Flight-test card", "",
             "**Before**: keep the current gains — "
             f"`{files['current']}` holds exactly what the log flew.", "",
             f"**Load**: {load}.", "",
             "**Fly first**: a hover of 30–60 s in calm air, in the mode the log was flown in "
             f"({'Stabilize or AltHold' if fw == 'ardupilot' else 'angle mode'}), at the head speed of the log; "
             "then small stick raps of 5–10° on each axis, one axis at a time, returning to hover between them.",
             "",
             "**Watch**: a fast wobble or a buzz on any axis (the proposed loops keep at least "
             f"{pm:.0f}° of phase margin in the model; a real rotor with more lag than identified has less) — land "
             "and revert at once. In gusts like the log's the attitude should stay within the proposed p90 "
             f"(the largest: {worst}, {result.axes[worst]['proposed'].get('p90_deg', float('nan')):.2g} deg) nine "
             "tenths of the time. In the model " + ("; ".join(raps) if raps else "no step response was computed")
             + ": a rap that overshoots clearly more, or rings, says the aircraft has more lag than the model.", "",
             f"**Revert**: {revert}; nothing else was changed.", ""]
    return lines


def notes_lines(result, extra=()) -> list:
    notes = list(extra) + list(result.notes)
    if not notes:
        return []
    return ["## Notes", ""] + [f"- {n}" for n in notes] + [""]


def to_markdown(result, files: dict, flown=None, figures=(), context=()) -> str:
    """The whole report (module docstring). ``context``: lines about the model and the log, shown first."""
    s = result.scale
    sets = result.settings
    title = {"ardupilot": "ArduPilot TradHeli", "rotorflight": "Rotorflight (pid_mode 3)"}[result.firmware]
    lines = [f"# Firmware tune: {title}", ""] + list(context) + [
        f"Loop rate {result.loop_rate_hz:g} Hz (the physics sub-stepped {sets['substeps']}x per "
        f"{result.control_dt:g} s); command scale roll {s.scale[0]:.4g}, pitch {s.scale[1]:.4g}, yaw {s.scale[2]:.4g} "
        f"model stick per firmware unit ({s.source}: {s.detail}).", "",
        f"Predicted in the identified gusts: {sets['windows']['count']} windows of {sets['windows']['window_s']:g} s "
        f"({sets['windows']['library_s']:.0f} s of the library's wind), "
        f"{'through the model sensors' if sets['sensors'] else 'with exact sensors'}; "
        f"{sets['candidates_flown']} robust candidate set(s) flown beside the current and default gains.", "",
        "## Attitude error", ""] + comparison_table(result) + ["",
        "p50/p90/p99 of |attitude error| in the time domain (the firmware loop at its own rate in the replayed "
        "gusts) with the 90 % interval of the p90 over blocks of library time; margins of the loop broken at the "
        "axis' stick at the loop's tick (inf: never crosses; the delay margin is the extra servo delay the loop "
        "survives, PM/ω at the gain crossover); the frequency-domain p90 is the Gaussian one of the linearised "
        f"loop. The proposal keeps {_robust_margins(result)}.", ""] + verdict_lines(result) + ["", "## Gains", ""] + gains_table(result) + [""]
    lines += flown_lines(result, flown)
    lines += flight_card(result, files)
    lines += notes_lines(result)
    if figures:
        lines += ["## Figures", ""] + [f"![{p.stem}]({p.name})" for p in figures] + [""]
    return "\n".join(lines)


def plot_comparison(result, path):
    """Bar chart of the three sets' p90 per axis with their 90 % intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from heli_core.files import save_figure

    fig, ax = plt.subplots(figsize=(7, 3.6))
    width = 0.26
    for k, label in enumerate(LABELS):
        vals, lo, hi = [], [], []
        for axis in AXES:
            s = result.axes[axis][label]
            v = np.nan if s.get("diverged", True) else s["p90_deg"]
            inter = s.get("p90_deg_interval") or [None, None]
            vals.append(v)
            lo.append(v - inter[0] if inter[0] is not None and np.isfinite(v) else 0.0)
            hi.append(inter[1] - v if inter[1] is not None and np.isfinite(v) else 0.0)
        ax.bar(np.arange(3) + (k - 1) * width, vals, width, yerr=[lo, hi], capsize=3, label=label)
    ax.set_xticks(range(3), AXES)
    ax.set_ylabel("p90 |attitude error| [deg]")
    ax.set_title(f"{result.firmware}: predicted in the identified gusts")
    ax.legend()
    return save_figure(fig, path)


def plot_sweeps(result, path):
    """Frequency-domain p90 over each axis' swept grid; robust sets outlined, current and proposed marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from heli_core.files import save_figure

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for i, ax in enumerate(axes):
        sw = result.sweeps[i]
        a, b = np.unique(sw.a), np.unique(sw.b)
        grid = sw.grid("fd_p90_deg")
        mesh = ax.pcolormesh(b, a, grid, shading="nearest", cmap="viridis")
        fig.colorbar(mesh, ax=ax, label="p90 [deg]")
        robust = sw.robust.reshape(a.size, b.size)
        ax.contour(b, a, robust.astype(float), levels=[0.5], colors="white", linewidths=1.0)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(sw.names[1])
        ax.set_ylabel(sw.names[0])
        row = result.axes[AXES[i]]
        for label, marker in (("current", "o"), ("proposed", "*")):
            g = row[label]["gains"]
            if sw.names[0] in g and sw.names[1] in g:
                ax.plot(g[sw.names[1]], g[sw.names[0]], marker, color="red" if label == "proposed" else "white",
                        markersize=10 if label == "proposed" else 7, label=label)
        ax.set_title(AXES[i])
        ax.legend(loc="lower left", fontsize=7)
    fig.suptitle(f"frequency-domain p90; inside the white line: {_robust_margins(result)}", fontsize=10)
    fig.subplots_adjust(top=0.86, bottom=0.16, wspace=0.5)  # not tight_layout: its bounding boxes took 2 s of a tune
    return save_figure(fig, path)


def plot_steps(result, path):
    """The 10° step responses of the current and proposed sets per axis (the flight-test card's raps)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from heli_core.files import save_figure

    fig, axes = plt.subplots(1, 3, figsize=(12, 3.4))
    for ax, axis in zip(axes, AXES):
        for label, style in (("current", "--"), ("proposed", "-")):
            st = result.axes[axis][label].get("step")
            if st and not st.get("diverged"):
                ax.plot(st["time_s"], st["angle_deg"], style, label=label)
        ax.set_title(axis)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("attitude [deg]")
        ax.legend(fontsize=7)
    return save_figure(fig, path)
