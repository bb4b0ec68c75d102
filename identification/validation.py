"""Validate identified models against a flight: the paper's error tables and figures.

Section 3.2 of the paper judges a model by forward-simulating it with the
measured sticks and comparing the simulated body rates with the measured ones
(Figs. 9-14, Tables 1-2: mean absolute error, 90th percentile of the absolute
error, and the error relative to the largest measured rate), then by comparing
the attitude angles of eqs. (25)-(29) after subtracting the best piecewise-linear
function over 10 s pieces from both (Figs. 15-18). Section 3.4 repeats the
comparison with the identified disturbance fed to the model.

:func:`validate_models` runs that comparison for any number of models at once
and returns a :class:`ValidationResult` holding the histories, the statistics,
a JSON-ready dictionary and Markdown tables in the paper's layout;
:func:`plot_rate_fit` and :func:`plot_attitude_fit` draw the figures.

All statistics are reported in degrees (deg/s for rates), as in the paper;
every array going in is in radians (rad/s for rates).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from heli_core.errors import MissingDependency
from heli_core.files import jsonable, save_figure
from heli_core.params import ModelParams
from heli_core.physics import QUAT, initial_state, simulate
from heli_core.quaternion import euler_from_quaternion
from heli_core.terms import AXES, STICK_ROW

from .attitude import detrend_piecewise
from .errors import SimulationDivergedError
from .flight import Flight

DETREND_PERIOD = 10.0
"""Length of the linear pieces removed from the angles before comparison [s] (Section 3.2)."""

WINDOW_LENGTH = 10.0
"""Length of the automatic close-up windows of :func:`plot_rate_fit` [s] (Fig. 10)."""

PERCENTILE_METHOD = "hazen"
"""``numpy.percentile`` method matching Matlab's ``prctile`` (sample k sits at (k - 0.5)/n)."""

_DPI = 110


# ---------------------------------------------------------------------- checks
def _as_histories(name: str, values, n: int | None = None) -> np.ndarray:
    """``values`` as a float array of shape (3, n), or a ValueError naming it."""
    a = np.asarray(values, dtype=float)
    if a.ndim != 2 or a.shape[0] != 3 or (n is not None and a.shape[1] != n):
        want = f"(3, {n})" if n is not None else "(3, n)"
        raise ValueError(f"{name} must have shape {want} (roll, pitch, yaw by sample), got {a.shape}")
    if a.shape[1] == 0:
        raise ValueError(f"{name} holds no samples")
    if not np.all(np.isfinite(a)):
        bad = ~np.isfinite(a)
        row, col = np.unravel_index(int(np.argmax(bad)), a.shape)
        raise ValueError(
            f"{name} has {int(bad.sum())} non-finite values, first on the {AXES[row]} axis at sample {col}"
        )
    return a


def _pair(name_a: str, a, name_b: str, b) -> tuple[np.ndarray, np.ndarray]:
    a = _as_histories(name_a, a)
    b = _as_histories(name_b, b, a.shape[1])
    return a, b


# ---------------------------------------------------------------- statistics
def rate_error_stats(measured, modelled) -> dict[str, dict[str, float]]:
    """Error statistics of modelled body rates, Table 1 / Table 2.

    Parameters
    ----------
    measured : array_like, shape (3, n)
        Measured (usually low-pass filtered) p, q, r [rad/s].
    modelled : array_like, shape (3, n)
        Simulated p, q, r at the same samples [rad/s].

    Returns
    -------
    dict
        Per axis name (``"roll"``, ``"pitch"``, ``"yaw"``) a dict with

        ``mae_deg_s``
            Mean absolute error [deg/s].
        ``p90_deg_s``
            90th percentile of the absolute error [deg/s], interpolated as
            Matlab's ``prctile`` (:data:`PERCENTILE_METHOD`).
        ``rel_max_pct``
            Mean absolute error relative to the largest absolute measured rate
            [%] (Table 1, "error relative to maximum"); NaN when the measured
            rate is identically zero.

    Raises
    ------
    ValueError
        Shapes other than (3, n) with equal n, or non-finite values.
    """
    measured, modelled = _pair("measured", measured, "modelled", modelled)
    err = np.degrees(np.abs(modelled - measured))
    mae = err.mean(axis=1)
    p90 = np.percentile(err, 90.0, axis=1, method=PERCENTILE_METHOD)
    peak = np.degrees(np.abs(measured).max(axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(peak > 0.0, 100.0 * mae / np.where(peak > 0.0, peak, 1.0), np.nan)
    return {
        axis: {"mae_deg_s": float(mae[i]), "p90_deg_s": float(p90[i]), "rel_max_pct": float(rel[i])}
        for i, axis in enumerate(AXES)
    }


def between_models_mae(a, b) -> dict[str, float]:
    """Mean absolute difference between two modelled rate histories, Table 2.

    Parameters
    ----------
    a, b : array_like, shape (3, n)
        Simulated p, q, r of two models at the same samples [rad/s].

    Returns
    -------
    dict of str to float
        Per axis name, the mean absolute difference [deg/s] (Table 2, "mean
        absolute error between models").
    """
    a, b = _pair("a", a, "b", b)
    mae = np.degrees(np.abs(a - b)).mean(axis=1)
    return {axis: float(mae[i]) for i, axis in enumerate(AXES)}


def detrended_angles(time, angles, period: float = DETREND_PERIOD) -> np.ndarray:
    """Unwrapped angles minus their best piecewise-linear fit over ``period`` s pieces [deg].

    Section 3.2: "to remove drift in integration, the best least squares
    piecewise linear function over 10 s periods is subtracted from the data and
    the model" (:func:`identification.attitude.detrend_piecewise`).

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times [s].
    angles : array_like, shape (3, n)
        Roll, pitch, yaw [rad], wrapped or not.
    period : float
        Length of the linear pieces [s].

    Returns
    -------
    ndarray, shape (3, n)
        Detrended angles [deg].
    """
    angles = np.unwrap(np.asarray(angles, dtype=float), axis=-1)
    return np.degrees(detrend_piecewise(time, angles, period))


def attitude_error_stats(time, measured_att, modelled_att, period: float = DETREND_PERIOD) -> dict[str, dict]:
    """Error statistics of modelled attitude after the 10 s detrend, Section 3.2.

    Both angle histories are unwrapped and detrended with
    :func:`identification.attitude.detrend_piecewise`; the error is their
    difference (Fig. 15).

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times [s].
    measured_att : array_like, shape (3, n)
        Measured roll, pitch, yaw [rad].
    modelled_att : array_like, shape (3, n)
        Modelled roll, pitch, yaw from eqs. (25)-(29) [rad].
    period : float
        Length of the linear pieces of the detrend [s].

    Returns
    -------
    dict
        Per axis name a dict with ``mae_deg`` (mean absolute error [deg]) and
        ``std_deg`` (standard deviation of the error [deg]).

    Raises
    ------
    ValueError
        Shapes that do not match ``time``, non-finite values, or a
        non-positive ``period``.
    """
    time = np.asarray(time, dtype=float)
    if time.ndim != 1 or time.size < 2:
        raise ValueError(f"time must be 1-D with at least 2 samples, got shape {time.shape}")
    if not period > 0.0:
        raise ValueError(f"period must be a positive number of seconds, got {period!r}")
    measured_att = _as_histories("measured_att", measured_att, time.size)
    modelled_att = _as_histories("modelled_att", modelled_att, time.size)
    err = detrended_angles(time, modelled_att, period) - detrended_angles(time, measured_att, period)
    mae = np.abs(err).mean(axis=1)
    std = err.std(axis=1)
    return {axis: {"mae_deg": float(mae[i]), "std_deg": float(std[i])} for i, axis in enumerate(AXES)}


# ---------------------------------------------------------------- the result
def _md_cell(text: str) -> str:
    return str(text).replace("|", "\\|")


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(_md_cell(h) for h in header) + " |",
             "|" + "|".join(["---"] + ["---:"] * (len(header) - 1)) + "|"]
    lines += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


@dataclass(eq=False)
class ValidationResult:
    """Simulated histories and error statistics of one or more models on one flight.

    Built by :func:`validate_models`.

    Attributes
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    measured_rates : ndarray, shape (3, n)
        The measured p, q, r the models are compared with [rad/s].
    simulated : dict of str to ndarray, shape (3, n)
        Model label -> simulated p, q, r [rad/s].
    simulated_attitude : dict of str to ndarray, shape (3, n)
        Model label -> roll, pitch, yaw from the simulated quaternion,
        eqs. (25)-(29) [rad] (wrapped, not detrended).
    rate_stats : dict
        Model label -> :func:`rate_error_stats` (Tables 1-2).
    attitude_stats : dict
        Model label -> :func:`attitude_error_stats` (Section 3.2).
    between : dict of str to float or None
        :func:`between_models_mae` of the two models when exactly two were
        compared (Table 2), else None.
    measured_attitude : ndarray, shape (3, n), optional
        Measured roll, pitch, yaw [rad]; needed by :func:`plot_attitude_fit`.
    period : float
        Length of the pieces of the attitude detrend [s].
    """

    time: np.ndarray
    measured_rates: np.ndarray
    simulated: dict
    simulated_attitude: dict
    rate_stats: dict
    attitude_stats: dict
    between: dict | None = None
    measured_attitude: np.ndarray | None = None
    period: float = DETREND_PERIOD

    @property
    def labels(self) -> list[str]:
        """Model labels in the order they were given."""
        return list(self.simulated)

    def to_dict(self) -> dict:
        """Statistics as plain JSON-ready values (non-finite numbers become None).

        The histories are left out; the dictionary holds ``models``,
        ``n_samples``, ``duration_s``, ``detrend_period_s``, ``rate_stats``,
        ``attitude_stats`` and ``between``.
        """
        return jsonable({
            "models": self.labels,
            "n_samples": int(np.size(self.time)),
            "duration_s": float(self.time[-1] - self.time[0]),
            "detrend_period_s": float(self.period),
            "rate_stats": self.rate_stats,
            "attitude_stats": self.attitude_stats,
            "between": self.between,
        })

    def markdown(self) -> str:
        """The rate table (Tables 1-2 layout, models side by side) and the attitude table."""
        labels = self.labels
        header = ["Attitude"]
        for lab in labels:
            header += [f"{lab}: MAE (deg/s)", f"{lab}: 90th pct (deg/s)", f"{lab}: rel. to max (%)"]
        if self.between is not None:
            header.append("MAE between models (deg/s)")
        rows = []
        for axis in AXES:
            row = [f"{axis.capitalize()} rate"]
            for lab in labels:
                s = self.rate_stats[lab][axis]
                row += [f"{s['mae_deg_s']:.4f}", f"{s['p90_deg_s']:.4f}", f"{s['rel_max_pct']:.2f}"]
            if self.between is not None:
                row.append(f"{self.between[axis]:.4f}")
            rows.append(row)
        rate_table = _md_table(header, rows)

        header = ["Attitude"]
        for lab in labels:
            header += [f"{lab}: MAE (deg)", f"{lab}: std (deg)"]
        rows = []
        for axis in AXES:
            row = [f"{axis.capitalize()} angle"]
            for lab in labels:
                s = self.attitude_stats[lab][axis]
                row += [f"{s['mae_deg']:.4f}", f"{s['std_deg']:.4f}"]
            rows.append(row)
        att_table = _md_table(header, rows)
        return (
            "**Body-rate error of the forward-simulated models** (Tables 1-2)\n\n"
            f"{rate_table}\n\n"
            f"**Attitude error after removing a piecewise-linear trend over {self.period:g} s pieces** "
            "(eqs. 25-29, Section 3.2)\n\n"
            f"{att_table}\n"
        )


# ---------------------------------------------------------------- validation
DIVERGED_RATE = 100.0
"""A simulated body rate beyond this [rad/s] (about 16 revolutions per second) has diverged."""


def _check_bounded(label: str, params: ModelParams, time, rates) -> None:
    """Raise :class:`SimulationDivergedError` when a simulated rate history leaves ``DIVERGED_RATE``."""
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(rates) <= DIVERGED_RATE)  # NaN counts as diverged
    if not bad.any():
        return
    row, col = np.unravel_index(int(np.argmax(bad)), bad.shape)
    damping = {a: params.get(k) for a, k in zip(AXES, ("k3", "k7", "k11"))}
    unstable = [a for a, v in damping.items() if not v > 0.0]
    why = (f"its damping is not positive on {', '.join(unstable)} "
           f"({', '.join(f'{k}={params.get(k):.3g}' for a, k in zip(AXES, ('k3', 'k7', 'k11')) if a in unstable)})"
           if unstable else "its added terms feed the rates back faster than the damping removes them")
    raise SimulationDivergedError(
        f"model {label!r} diverges when simulated from the flight's sticks: the {AXES[row]} rate leaves "
        f"±{DIVERGED_RATE:g} rad/s at t={float(time[col]):.2f} s; {why}. Likely causes: an unmodelled servo "
        "delay (identify with --delay auto), a log whose input column lags the response, or a log of an aircraft "
        "flown by a rate controller (its recorded command is not an open-loop input)")


def validate_models(flight: Flight, models: dict[str, ModelParams], rates=None, disturbance=None) -> ValidationResult:
    """Forward-simulate models with the flight's sticks and compare them with the flight.

    Each model is simulated with :func:`identification.model.simulate` (eqs. 18,
    21, 31 and the quaternion kinematics 25-26) from the measured initial rates
    and attitude, the servo states settled on the first sticks. Its rates are
    compared with the measured rates (Tables 1-2) and its attitude (eqs. 27-29)
    with the measured attitude after the 10 s detrend (Figs. 15-18).

    Parameters
    ----------
    flight : Flight
        The validation flight; its ``attitude`` is the measured attitude.
    models : dict of str to ModelParams
        Label -> model, e.g. ``{"decoupled": p1, "coupled": p2}``.
    rates : array_like, shape (3, n), optional
        Measured p, q, r to compare against [rad/s], e.g. low-pass filtered as in
        Fig. 8(b); default ``flight.rates``. The simulations start from its
        first sample.
    disturbance : array_like, shape (3, n), or dict of str to such arrays, optional
        Wind torque per inertia on roll, pitch, yaw [rad/s^2] (eq. 42,
        Section 3.4), applied to every model, or per model label (a label
        missing from the dict is simulated without disturbance).

    Returns
    -------
    ValidationResult

    Raises
    ------
    ValueError
        No models, arrays whose shapes do not match the flight, or non-finite
        values.
    SimulationDivergedError
        A model whose simulated rates leave ±:data:`DIVERGED_RATE` (the message names
        the model, axis, time and likely cause).
    TypeError
        A model that is not a :class:`~identification.model.ModelParams`.
    """
    if not models:
        raise ValueError("models must name at least one ModelParams to validate, got none")
    for label, params in models.items():
        if not isinstance(params, ModelParams):
            raise TypeError(f"model {label!r} must be a ModelParams, got {type(params).__name__}")
    n = flight.n
    measured = flight.rates if rates is None else _as_histories("rates", rates, n)
    if isinstance(disturbance, Mapping):
        unknown = set(disturbance) - set(models)
        if unknown:
            raise ValueError(f"disturbance given for unknown model(s) {sorted(unknown)}; models: {list(models)}")
        dist = {lab: _as_histories(f"disturbance[{lab!r}]", d, n) for lab, d in disturbance.items()}
    elif disturbance is not None:
        shared = _as_histories("disturbance", disturbance, n)
        dist = {lab: shared for lab in models}
    else:
        dist = {}

    x0 = initial_state(rates=measured[:, 0], euler=flight.attitude[:, 0], sticks=flight.sticks[list(STICK_ROW), 0])
    simulated, sim_att, rate_stats, att_stats = {}, {}, {}, {}
    for label, params in models.items():
        state = simulate(params, flight.time, flight.sticks, disturbance=dist.get(label), x0=x0)
        _check_bounded(label, params, flight.time, state[:3])
        simulated[label] = state[:3]
        sim_att[label] = euler_from_quaternion(state[QUAT])
        rate_stats[label] = rate_error_stats(measured, simulated[label])
        att_stats[label] = attitude_error_stats(flight.time, flight.attitude, sim_att[label], DETREND_PERIOD)
    between = None
    if len(models) == 2:
        a, b = simulated.values()
        between = between_models_mae(a, b)
    return ValidationResult(
        time=flight.time,
        measured_rates=measured,
        simulated=simulated,
        simulated_attitude=sim_att,
        rate_stats=rate_stats,
        attitude_stats=att_stats,
        between=between,
        measured_attitude=flight.attitude,
        period=DETREND_PERIOD,
    )


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


def _pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - matplotlib is a core dependency
        raise MissingDependency("matplotlib is needed to plot; install it with: pip install matplotlib") from e
    return plt


_MEASURED_STYLE = {"color": "black", "lw": 0.9, "label": "measured"}


def _model_styles(labels):
    """Colour and dash per model, so that overlapping models stay visible."""
    dashes = ("-", "--", ":", "-.")
    return {lab: {"color": f"C{i}", "ls": dashes[i % len(dashes)]} for i, lab in enumerate(labels)}


RATE_FIT_TITLE = "Body rates: measured vs forward-simulated models (cf. paper Figs. 9-14)"
"""The title of :func:`plot_rate_fit`'s figure unless told otherwise."""


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
    plt = _pyplot()
    t = result.time
    labels = result.labels
    styles = _model_styles(labels)
    meas = np.degrees(result.measured_rates)
    sims = {lab: np.degrees(v) for lab, v in result.simulated.items()}
    if windows is not None:
        windows = [(float(a), float(b)) for a, b in windows]
        if len(windows) != 2 or any(not b > a for a, b in windows):
            raise ValueError(f"windows must be two (t_start, t_end) pairs with t_end > t_start, got {windows}")

    fig = plt.figure(figsize=(15, 13))
    outer = fig.add_gridspec(3, 1, hspace=0.3)
    for i, axis in enumerate(AXES):
        row = outer[i].subgridspec(1, 2, width_ratios=[2.3, 1], wspace=0.14)
        left = row[0].subgridspec(2, 1, hspace=0.08)
        right = row[1].subgridspec(2, 1, hspace=0.45)
        ax_full = fig.add_subplot(left[0])
        ax_res = fig.add_subplot(left[1], sharex=ax_full)
        ax_r = [fig.add_subplot(right[0]), fig.add_subplot(right[1])]
        wins = windows if windows is not None else pick_windows(t, meas[i])

        ax_full.plot(t, meas[i], **_MEASURED_STYLE)
        for lab in labels:
            mae = result.rate_stats[lab][axis]["mae_deg_s"]
            ax_full.plot(t, sims[lab][i], **styles[lab], lw=0.9, label=f"{lab} (MAE {mae:.2f} deg/s)")
            ax_res.plot(t, meas[i] - sims[lab][i], **styles[lab], lw=0.8, label=lab)
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
            ax.plot(t[m], meas[i, m], **_MEASURED_STYLE)
            for lab in labels:
                ax.plot(t[m], sims[lab][i, m], **styles[lab], lw=1.0, label=lab)
            ax.set_xlim(a, b)
            ax.set_title(f"Close-up R{k + 1} ({a:.1f}-{b:.1f} s)", fontsize=9, loc="left")
            ax.set_ylabel(f"{axis} rate [deg/s]", fontsize=8)
            ax.grid(alpha=0.3)
        ax_r[1].set_xlabel("time [s]")
        for ax in (ax_full, ax_res):
            ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=13)
    fig.subplots_adjust(left=0.06, right=0.985, top=0.93, bottom=0.05)
    return save_figure(fig, path, dpi=_DPI)


def plot_attitude_fit(result: ValidationResult, path):
    """Detrended measured vs modelled attitude angles, the analog of Figs. 15-18.

    Left, per axis: measured and modelled angles after removing the best
    piecewise-linear function over ``result.period`` s pieces (Figs. 16-18);
    right: the residual measured - modelled (Fig. 15). Angles in degrees; the
    legend gives each model's mean absolute error.

    Parameters
    ----------
    result : ValidationResult
        Must carry ``measured_attitude`` (as built by :func:`validate_models`).
    path : str or Path
        Destination PNG, written atomically.

    Returns
    -------
    Path
        ``path``.
    """
    if result.measured_attitude is None:
        raise ValueError("result has no measured_attitude; build it with validate_models")
    plt = _pyplot()
    t = result.time
    labels = result.labels
    styles = _model_styles(labels)
    meas = detrended_angles(t, result.measured_attitude, result.period)
    sims = {lab: detrended_angles(t, v, result.period) for lab, v in result.simulated_attitude.items()}
    names = ("roll angle φ", "pitch angle θ", "yaw angle ψ")

    fig, axes = plt.subplots(3, 2, figsize=(15, 10), sharex=True, gridspec_kw={"width_ratios": [2.3, 1]})
    for i, axis in enumerate(AXES):
        ax, ax_res = axes[i]
        ax.plot(t, meas[i], **_MEASURED_STYLE)
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
    return save_figure(fig, path, dpi=_DPI)
