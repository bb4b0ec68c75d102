"""Reports of a gain sweep (:mod:`controllers.sweep_result`) and of its flight tests
(:mod:`controllers.flight_test_result`): the Markdown report, the heat map and the histograms (figures written atomically).

Presentation only: the CSV and JSON files are the result's own (:meth:`~controllers.sweep_result.SweepResult.to_csv`,
:meth:`~controllers.sweep_result.SweepResult.to_json`).
"""

from __future__ import annotations

import math

import numpy as np

from heli_core.deprecation import module_getattr
from heli_core.files import save_figure

from .closed_loop import GAUSS_ABS_FACTOR


def _fmt(v, spec=".3f"):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    if isinstance(v, float) and math.isinf(v):
        return "∞" if v > 0 else "−∞"
    return format(v, spec)


def _margins(row) -> str:
    gm, pm = row["gain_margin_db"], row["phase_margin_deg"]
    return f"{_fmt(gm, '.1f')} dB / {_fmt(pm, '.0f')}°"


def _note(row, duration):
    notes = [f"added by extension {row['extension_round']}"] if row["extension_round"] else []
    if row["status"] != "stable":
        return "; ".join([row["status"]] + notes)
    if row["disagree"]:
        why = []
        if row["saturation"] > 0.005:
            why.append(f"saturated {100 * row['saturation']:.1f} % of the time")
        if row["settle_s"] > 0.25 * duration:
            why.append(f"lightly damped: settles in {row['settle_s']:.0f} s, windows are {duration:g} s")
        notes.append("disagree: " + ("; ".join(why) or "non-Gaussian gusts or non-linear model"))
    return "; ".join(notes)


def markdown(result, max_rows: int = 400) -> str:
    """The sweep report: settings, summary, the side-by-side time/frequency table."""
    s = result.settings
    st = result.table["status"]
    n_unst = int(np.sum(st == "unstable"))
    n_div = int(np.sum(st == "diverged"))
    n_dis = int(np.sum(result.table["disagree"]))
    tol = s["agree_tol"]
    lines = [
        f"# Gain sweep — {result.axis}",
        "",
        f"Model `{s['model']}` (library v{s['library_version']}), PD attitude hold on **{result.axis}**, "
        f"{result.n_pairs} gain pairs × {s['n_windows']} gust windows of {s['duration']:g} s at dt = {s['dt']:g} s "
        f"(seed {s['seed']}). The other axes are held by nominal PD gains "
        + ", ".join(f"{a}: Kp {g[0]:.3g}, Kd {g[1]:.3g}" for a, g in zip(("roll", "pitch", "yaw"), s["nominal_gains"])
                    if a != result.axis)
        + " (pole placement at 4 rad/s, damping ratio 0.7, `controllers.closed_loop.nominal_gains`: a gentle "
        "hold that keeps the swept axis' errors its own; these are not the gains `heli design` picks for "
        "those axes)." + _filter_sentence(s.get("d_filter_hz")),
        "",
        "Two independent predictions of the error distribution (paper Section 4): **time domain** — the "
        "library's gusts replayed through the physics core in closed loop (stick clipping included); **frequency "
        "domain** — the Welch spectrum of u_d through the linearised closed loop, Gaussian percentiles of |e| "
        f"(p50 = {GAUSS_ABS_FACTOR[50]:.3f}σ, p90 = {GAUSS_ABS_FACTOR[90]:.3f}σ, p99 = {GAUSS_ABS_FACTOR[99]:.3f}σ). "
        f"Flagged where the p90s differ by more than {100 * tol:.0f} %.",
        "",
        "## Summary",
        "",
        f"- stable pairs: {int(np.sum(st == 'stable'))}; unstable (closed-loop poles, not simulated): {n_unst}; "
        f"diverged in replay: {n_div}",
        f"- time and frequency domain disagree (p90 > {100 * tol:.0f} %): {n_dis}",
    ] + _interval_lines(s)
    lines += _grid_lines(result) + _best_lines(result)
    sec = s.get("seconds", {})
    if sec:
        lines.append(f"- run time: {sec.get('total', float('nan')):.2f} s (time domain "
                     f"{sec.get('time_domain', float('nan')):.2f} s, frequency domain "
                     f"{sec.get('frequency_domain', float('nan')):.2f} s)")
    lines += [
        "",
        "## Per gain pair",
        "",
        "|attitude error| [deg] and |rate error| [deg/s]: time domain / frequency domain, the time domain's "
        "p90 with its 90 % interval in brackets (its sampling error); margins of the "
        "sampled loop broken at the swept stick: gain [dB] / phase [deg].",
        "",
        "| Kp | Kd | p50 att | p90 att | p99 att | Δp90 att | p90 rate | Δp90 rate | RMS stick | sat. % | margins "
        "| note |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    rows = result.rows()
    for row in rows[:max_rows]:
        if row["status"] == "unstable":
            note = _note(row, s["duration"]).replace("unstable", f"unstable (max pole {row['max_pole']:.4f})", 1)
            lines.append(f"| {row['kp']:.4g} | {row['kd']:.4g} | — | — | — | — | — | — | — | — | {_margins(row)} "
                         f"| {note} |")
            continue
        note = _note(row, s["duration"])
        note = f"**{note}**" if row["disagree"] else note
        lines.append(
            f"| {row['kp']:.4g} | {row['kd']:.4g} "
            f"| {_fmt(row['att_p50_deg'])} / {_fmt(row['pred_att_p50_deg'])} "
            f"| {_fmt(row['att_p90_deg'])} {_interval(row, 'att_p90', 'deg')} / {_fmt(row['pred_att_p90_deg'])} "
            f"| {_fmt(row['att_p99_deg'])} / {_fmt(row['pred_att_p99_deg'])} "
            f"| {_fmt(100 * row['att_p90_rel_diff'], '+.1f')} % "
            f"| {_fmt(row['rate_p90_dps'])} {_interval(row, 'rate_p90', 'dps')} / {_fmt(row['pred_rate_p90_dps'])} "
            f"| {_fmt(100 * row['rate_p90_rel_diff'], '+.1f')} % "
            f"| {_fmt(row['stick_rms'])} / {_fmt(row['pred_stick_rms'])} "
            f"| {_fmt(100 * row['saturation'], '.1f')} | {_margins(row)} | {note} |")
    if len(rows) > max_rows:
        lines.append(f"\n({len(rows) - max_rows} more rows in sweep.csv)")
    return "\n".join(lines) + "\n"


def _interval(row, name: str, unit: str, spec: str = ".3f") -> str:
    """``[lo, hi]``: the 90 % interval of a p90 (empty where there is none)."""
    lo, hi = row.get(f"{name}_lo_{unit}"), row.get(f"{name}_hi_{unit}")
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return ""
    return f"[{format(lo, spec)}, {format(hi, spec)}]"


def interval_sentence(settings: dict) -> str:
    """The p90s' sampling error in one sentence (``settings["p90_interval"]``), or an empty string."""
    iv = settings.get("p90_interval") or {}
    if iv.get("median_half_width") is None:
        return ""
    return (f"sampling error of the p90s (90 % interval, {iv['method']}; {iv['n_blocks']} blocks, "
            f"{iv['library_s_flown']:g} s of library flown in {settings['n_windows']} windows): half-width "
            f"±{100 * iv['median_half_width']:.1f} % of the p90 (median over the stable pairs), "
            f"±{100 * iv['max_half_width']:.1f} % at most")


def _interval_lines(settings: dict) -> list:
    """The summary's line on the p90s' sampling error."""
    sentence = interval_sentence(settings)
    return [f"- {sentence}. It covers which stretches of wind the library holds, not the model's error."] \
        if sentence else []


def _span(values) -> str:
    return f"{values[0]:.4g} … {values[-1]:.4g}" if len(values) > 1 else f"{values[0]:.4g}"


def _grid_lines(result) -> list:
    """The summary's line on the grid: asked for, grown, and why the growth stopped."""
    ext = result.settings.get("extension")
    if not result.is_grid or ext is None:
        return []
    kp0, kd0 = ext["kp_asked"], ext["kd_asked"]
    line = f"- grid: {len(kp0)} × {len(kd0)} pairs asked for (Kp {_span(kp0)}, Kd {_span(kd0)})"
    rounds = ext["rounds"]
    if rounds:
        added = sum(r["pairs_added"] for r in rounds)
        line += (f"; its best pair lay on an edge, so it grew {len(rounds)} time{'s' * (len(rounds) != 1)} "
                 f"({ext['values_per_round']} gains past the edge each time, the grid's last ratio continued) to "
                 f"{result.kp_values.size} × {result.kd_values.size} (Kp {_span(result.kp_values)}, "
                 f"Kd {_span(result.kd_values)}; {added} pairs added)")
    stop = {"interior": "the best pair is interior", "unstable beyond": "the stability boundary is reached",
            "bound": "no edge left to grow", "limit": f"limit of {ext['max_extensions']} extensions reached",
            "no stable pair": "no stable pair", "disabled": "extension off"}[ext["stop"]]
    return [line + f". Stopped: **{stop}** — {ext['stop_detail']}."]


def pair_summary(row, deg: str = "°", emphasis: str = "") -> str:
    """One pair in a line: gains (between ``emphasis``), p90s in both domains, stick, margins (units ``deg``)."""
    ci = _interval(row, "att_p90", "deg", ".3g")
    return (f"{emphasis}Kp = {row['kp']:.4g}, Kd = {row['kd']:.4g}{emphasis}: p90 {row['att_p90_deg']:.3g}{deg} "
            f"{'(90 % interval ' + ci + ', ' if ci else '('}frequency domain {row['pred_att_p90_deg']:.3g}{deg}), p90 |rate error| {row['rate_p90_dps']:.3g}"
            f"{deg}/s, RMS stick {row['stick_rms']:.3f}, gain margin {_fmt(row['gain_margin_db'], '.1f')} dB, "
            f"phase margin {_fmt(row['phase_margin_deg'], '.1f')}{deg}")


def _best_lines(result) -> list:
    """The summary's lines on the best pair (and the grid's own best before it grew) and the best robust pair."""
    from .sweep_margins import ROBUST_GAIN_MARGIN_DB, ROBUST_PHASE_MARGIN_DEG

    best, rob = result.best(), result.best_robust()
    if best is None:
        return ["- no stable pair"]
    lines = [f"- best pair by p90 |attitude error|: {pair_summary(best, emphasis='**')}"]
    rounds = (result.settings.get("extension") or {}).get("rounds")
    if rounds:
        b = rounds[0]["best_before"]
        lines[0] += f" (the grid asked for had Kp = {b['kp']:.4g}, Kd = {b['kd']:.4g}: p90 {b['att_p90_deg']:.3g}°)"
    need = f"gain margin ≥ {ROBUST_GAIN_MARGIN_DB:g} dB and phase margin ≥ {ROBUST_PHASE_MARGIN_DEG:g}°"
    if rob is None:
        lines.append(f"- best robust pair ({need}): none — no stable pair keeps both margins")
    elif (rob["kp"], rob["kd"]) == (best["kp"], best["kd"]):
        lines.append(f"- best robust pair ({need}): the best pair itself")
    else:
        lines.append(f"- best robust pair ({need}): {pair_summary(rob, emphasis='**')}")
    return lines


def _asked_block(result):
    """(Kp rows, Kd columns) slices of the grid asked for inside an extended grid; None if it did not grow."""
    ext = result.settings.get("extension") or {}
    if not ext.get("rounds"):
        return None
    rows = np.searchsorted(result.kp_values, ext["kp_asked"][0])
    cols = np.searchsorted(result.kd_values, ext["kd_asked"][0])
    return slice(rows, rows + len(ext["kp_asked"])), slice(cols, cols + len(ext["kd_asked"]))


def _gain_ticks(set_ticks, values, most: int = 10) -> None:
    """Ticks on the cells of about ``most`` gains, labelled with their values."""
    idx = np.arange(0, values.size, max(1, -(-values.size // most)))
    set_ticks(idx, [f"{v:.3g}" for v in values[idx]])


def plot_heatmap(result, path):
    """p90 |attitude error| over Kp × Kd: time domain and frequency domain side by side."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Patch, Rectangle

    if not result.is_grid:
        raise ValueError("a heat map needs a Kp × Kd grid sweep")
    kp, kd = result.kp_values, result.kd_values
    td = result.grid("att_p90_deg").astype(float)
    fd = result.grid("pred_att_p90_deg").astype(float)
    unstable = result.grid("status") == "unstable"
    fd = np.where(unstable, np.nan, fd)
    finite = np.concatenate([td[np.isfinite(td)], fd[np.isfinite(fd)]])
    norm = None
    if finite.size and finite.min() > 0 and finite.max() > finite.min():
        norm = LogNorm(vmin=finite.min(), vmax=finite.max())
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True, constrained_layout=True)
    # one cell per pair, whatever the spacing (an extended grid continues geometrically), gains on the ticks
    xe, ye = np.arange(kd.size + 1) - 0.5, np.arange(kp.size + 1) - 0.5
    best, robust, asked = result.best(), result.best_robust(), _asked_block(result)
    if robust is not None and best is not None and (robust["kp"], robust["kd"]) == (best["kp"], best["kd"]):
        robust = best
    cell = {id(r): divmod(result.index(r["kp"], r["kd"]), kd.size)[::-1] for r in (best, robust) if r}
    for ax, data, title in ((axes[0], td, "time domain (replayed gusts)"),
                            (axes[1], fd, "frequency domain (Welch × |H|², Gaussian)")):
        mesh = ax.pcolormesh(xe, ye, np.ma.masked_invalid(data), cmap="viridis", norm=norm, shading="flat")
        for i, j in zip(*np.nonzero(unstable)):  # hatched cells: not simulated
            ax.add_patch(Rectangle((xe[j], ye[i]), xe[j + 1] - xe[j], ye[i + 1] - ye[i], facecolor="0.85",
                                   hatch="xx", edgecolor="0.45", linewidth=0.0))
        if kp.size > 1 and kd.size > 1:
            rho = result.grid("max_pole").astype(float)
            if np.nanmin(rho) < 1.0 < np.nanmax(rho):
                ax.contour(np.arange(kd.size), np.arange(kp.size), rho, levels=[1.0], colors="red",
                           linewidths=1.5)
        if asked is not None:  # the grid asked for, inside the grown one
            ax.add_patch(Rectangle((xe[asked[1].start], ye[asked[0].start]),
                                   xe[asked[1].stop] - xe[asked[1].start], ye[asked[0].stop] - ye[asked[0].start],
                                   fill=False, edgecolor="white", linestyle="--", linewidth=1.2))
        if robust and robust is not best:
            ax.plot(*cell[id(robust)], marker="D", color="white", markersize=8, markeredgecolor="black")
        if best:
            ax.plot(*cell[id(best)], marker="*", color="white", markersize=14, markeredgecolor="black")
        ax.set_title(title)
        ax.set_xlabel("Kd [stick/(rad/s)]")
        _gain_ticks(ax.set_xticks, kd)
    _gain_ticks(axes[0].set_yticks, kp)
    axes[0].set_ylabel("Kp [stick/rad]")
    cb = fig.colorbar(mesh, ax=axes, shrink=0.9)
    cb.set_label(f"p90 |{result.axis} attitude error| [deg]")
    handles = [Patch(facecolor="0.8", hatch="xx", edgecolor="0.4", label="unstable (closed-loop poles)"),
               plt.Line2D([], [], color="red", label="stability boundary |z| = 1"),
               plt.Line2D([], [], marker="*", color="white", markeredgecolor="black", linestyle="",
                          markersize=12, label="best p90 (time domain)")]
    if robust is not None and robust is not best:
        handles.append(plt.Line2D([], [], marker="D", color="white", markeredgecolor="black", linestyle="",
                                  markersize=7, label="best p90 with 6 dB and 45° of margin"))
    if asked is not None:
        handles.append(Patch(fill=False, edgecolor="0.3", linestyle="--", label="grid asked for (then extended)"))
    fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 3), fontsize=8)
    fig.suptitle(f"PD gain sweep on {result.axis}: p90 |attitude error|")
    return save_figure(fig, path, dpi=110)


def default_pairs(result, n: int = 4) -> list:
    """The best pair and ``n - 1`` others spread over the stable pairs' p90 ranking."""
    stable = np.flatnonzero(result.stable & np.isfinite(np.asarray(result.table["att_p90_deg"], dtype=float)))
    if stable.size == 0:
        return []
    order = stable[np.argsort(np.asarray(result.table["att_p90_deg"], dtype=float)[stable])]
    picks = np.unique(np.round(np.linspace(0, order.size - 1, min(n, order.size))).astype(int))
    return [(float(result.table["kp"][i]), float(result.table["kd"][i])) for i in order[picks]]


def _fresh_gusts(kind: str, wind: dict) -> str:
    """The flight tests' fresh gusts in words (:attr:`controllers.flight_test.FlightTestConfig.gusts`)."""
    level = f"u_d std {', '.join(f'{v:.4f}' for v in wind['std'])}"
    if kind == "spectrum":
        return (f"fresh gusts with the library's spectrum (phase-randomised surrogates of its traces; {level}, "
                "roll/pitch/yaw)")
    return (f"fresh coloured wind at the library's level ({level}) and bandwidth "
            f"(corner {', '.join(f'{v:.3f}' for v in wind['corner_hz'])} Hz, roll/pitch/yaw)")


def plot_histograms(result, path, pairs=None):
    """Overlaid |attitude error| histograms (density per decade, log axis) with the half-normal predictions."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    pairs = default_pairs(result) if pairs is None else list(pairs)
    edges = result.hist_edges[1:]  # geometric part; the [0, edges[1]) bin is left off the log axis
    dlog = np.diff(np.log10(edges))
    fine = np.geomspace(edges[0], edges[-1], 400)
    fig, ax = plt.subplots(figsize=(8, 4.8), constrained_layout=True)
    lo, hi = np.inf, 0.0
    for n, (kp, kd) in enumerate(pairs):
        i = result.index(kp, kd)
        row = result.row(i)
        colour = f"C{n % 10}"
        if row["status"] != "stable":
            ax.plot([], [], color=colour, label=f"Kp {row['kp']:.3g}, Kd {row['kd']:.3g}: {row['status']}")
            continue
        counts = result.hist_counts[i]
        total = counts.sum() + result.hist_overflow[i]
        dens = counts[1:] / (total * dlog)
        ax.stairs(dens, edges, color=colour, linewidth=1.6,
                  label=f"Kp {row['kp']:.3g}, Kd {row['kd']:.3g}: p90 {row['att_p90_deg']:.2f}° "
                  f"(pred. {row['pred_att_p90_deg']:.2f}°)")
        sigma = row["pred_att_rms_deg"]
        if sigma and math.isfinite(sigma) and sigma > 0:  # half-normal density per decade: pdf(e)·e·ln 10
            pdf = np.sqrt(2 / np.pi) / sigma * np.exp(-0.5 * (fine / sigma) ** 2) * fine * np.log(10)
            ax.plot(fine, pdf, color=colour, linestyle="--", linewidth=1.0)
        lo, hi = min(lo, row["att_p50_deg"] / 30), max(hi, row["att_p99_deg"] * 3)
    ax.set_xscale("log")
    if math.isfinite(lo) and hi > 0:
        ax.set_xlim(max(lo, edges[0]), min(hi, edges[-1]))
    ax.set_xlabel(f"|{result.axis} attitude error| [deg]")
    ax.set_ylabel("density per decade")
    ax.set_title("Error distributions: replayed gusts (solid), frequency-domain half-normal (dashed)")
    if pairs:
        ax.legend(fontsize=8, loc="upper left")
    return save_figure(fig, path, dpi=110)


def flight_test_markdown(result) -> str:
    """The flight tests' report section: settings, target, one row per pair, and for every pair that misses
    the target the likely reason (a :class:`controllers.flight_test_result.FlightTestResult`)."""
    from .flight_test_result import KS_TARGET

    s = result.settings
    w = s["wind"]
    lines = [
        f"## Prediction checked against flight tests ({result.axis})",
        "",
        f"{s['n_flights']} flights of {s['duration']:g} s per gain pair of the truth model "
        f"(**{s['truth']}** parameters), RK4 with {s['substeps']} sub-steps, PD autopilot at dt = {s['dt']:g} s"
        f"{' on noisy sensors' if s['sensors'] else ''}, in {_fresh_gusts(s.get('gusts', 'corner'), w)}, "
        f"seed {s['seed']}. "
        f"Predictions: the library replayed through the identified model ({s['prediction']}).",
        "",
        "KS = largest gap between the measured and predicted CDFs of |error| (two-sample against the "
        "time-domain samples; one-sample against the frequency-domain half-normal). "
        f"Target: KS ≤ {KS_TARGET} (attitude, time domain) at stable gains — "
        f"**{'met' if result.target_met else 'NOT met'}** (largest {result.max_ks:.3f}).",
        "",
        "| Kp | Kd | KS att | KS att (Gauss) | KS rate | KS rate (Gauss) | p50 att meas / td / fd | "
        "p90 att meas / td / fd | p99 att meas / td / fd | p90 rate meas / td / fd |",
        "|---:|---:|---:|---:|---:|---:|---|---|---|---|",
    ]
    for r in result.rows():
        if r["status"] != "flown":
            lines.append(f"| {r['kp']:.4g} | {r['kd']:.4g} | {r['status']} | | | | | | | |")
            continue
        cell = lambda a, b, c: f"{a:.3f} / {b:.3f} / {c:.3f}"  # noqa: E731
        lines.append(
            f"| {r['kp']:.4g} | {r['kd']:.4g} | {r['ks_att']:.3f} | {r['ks_att_gauss']:.3f} | "
            f"{r['ks_rate']:.3f} | {r['ks_rate_gauss']:.3f} | "
            f"{cell(r['att_p50_deg'], r['pred_td_att_p50_deg'], r['pred_fd_att_p50_deg'])} | "
            f"{cell(r['att_p90_deg'], r['pred_td_att_p90_deg'], r['pred_fd_att_p90_deg'])} | "
            f"{cell(r['att_p99_deg'], r['pred_td_att_p99_deg'], r['pred_fd_att_p99_deg'])} | "
            f"{cell(r['rate_p90_dps'], r['pred_td_rate_p90_dps'], r['pred_fd_rate_p90_dps'])} |")
    missed = [r for r in result.rows() if r["status"] == "flown" and r["ks_att"] > KS_TARGET]
    if missed:
        lines += ["", "Pairs that miss the target, and why:", ""]
        lines += [f"- Kp {r['kp']:.4g}, Kd {r['kd']:.4g} (KS {r['ks_att']:.3f}): {miss_reason(r, s)}" for r in missed]
    return "\n".join(lines) + "\n"


SLOW_LOOP_FRACTION = 0.1
"""A loop that settles in more than this share of a prediction window is read as slow."""


def miss_reason(row: dict, settings: dict) -> str:
    """The likely reason a flown pair's measured errors differ from the prediction."""
    window = float(settings["duration"])
    settle = row.get("pred_settle_s", float("nan"))
    p90_err = row["att_p90_err_td"]
    if math.isfinite(settle) and settle > SLOW_LOOP_FRACTION * window:
        return (f"a slow loop (it settles in {settle:.1f} s): its error follows the slowest gusts, which the "
                f"prediction's windows ({settings['prediction']}) sample poorly; sweep more or longer windows "
                "(--windows, --duration)")
    if row["saturation"] > 0.01:
        return (f"the stick saturates {100 * row['saturation']:.1f} % of the time, where the replay and the "
                "flights part ways")
    return (f"the prediction's p90 is {100 * p90_err:+.0f} % off the flights': the identified model, its sensors "
            "or the library's gusts differ from the truth's at these gains")


def _filter_sentence(cutoffs) -> str:
    """The report's sentence on a sweep's derivative filter (cutoffs per axis from its settings); "" without one."""
    if not cutoffs or all(c is None for c in cutoffs):
        return ""
    cut = ", ".join(f"{a} {'none' if c is None else f'{c:.3g} Hz'}" for a, c in zip(("roll", "pitch", "yaw"), cutoffs))
    return (f" The D term is low-passed as `heli design`'s controller does it (cutoff {cut}); both predictions and "
            "the margins include the filter.")


__getattr__ = module_getattr(__name__)
