"""Gain sweeps → error distributions: the paper's Section 4 proposal.

    "use the disturbance profile identified from experiments to simulate the
    response of a proportional-derivative controller for a number of gains. The
    distribution of the error ... could then be predicted and compared with
    flight tests."

:func:`sweep_gains` flies every PD gain pair of a Kp × Kd grid against windows
of the model's disturbance library (the identified ``u_d`` of eqs. 41-47) and
reports the error distribution each pair gives, two ways:

* **time domain** — the gusts replayed through the physics core in closed loop
  (:mod:`controllers.replay`, the one batched closed loop the flight tests fly
  too), all gain pairs × windows stepped as one numpy batch; percentiles, RMS,
  control effort, saturation and a histogram per pair
  (:func:`controllers.metrics.error_metrics_inplace`);
* **frequency domain** — the Welch spectrum of ``u_d`` through the linearised
  closed loop (:mod:`controllers.closed_loop`), Gaussian percentiles.

Where the two disagree (saturation, non-Gaussian gusts, model non-linearity)
the result flags it. :mod:`controllers.flight_test` checks the prediction
against flights of the truth model in fresh wind.

Beside the errors stand each pair's gain and phase margins
(:mod:`controllers.sweep_margins`), so the report can name the best pair and
the best *robust* one (6 dB, 45°). A grid whose best pair lies on an edge grows
past it until the best pair is interior or a limit holds
(:mod:`controllers.sweep_extend`): the grid a user types need not contain the
optimum.

The replay
----------
(:mod:`controllers.replay`; windows from :mod:`controllers.sweep_inputs`, statistics by
:mod:`controllers.sweep_replay`.) The state starts level at rest, servos settled on the trim. At every control
period ``dt`` the PD law (:func:`controllers.pd.law.pd_command`) computes
a stick offset per axis from the true attitude and rates (reference 0:
attitude hold), clipped to [-1, 1]; the applied stick is ``clip(trim + offset,
-1, 1)`` with the trim for the recorded collective, exactly as the
environments apply an action. The gust torque ``k·u_d`` of the window's sample
and the recorded collective are held over the period. All three axes fly:
the swept axis with the pair under test, the other two with nominal PD gains
(:func:`controllers.closed_loop.nominal_gains`, 4 rad/s, ζ = 0.7) so the
aircraft stays near hover in its own gusts. Errors are recorded on the swept
axis at the start of each period (the state the controller acts on), so the
first sample of every window is the level start.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from heli_core.config import configured
from heli_core.deprecation import module_getattr
from heli_core.terms import AXES

from .closed_loop import (
    GAUSS_ABS_FACTOR,
    closed_loop_poles,
    d_cutoffs,
    disturbance_spectrum,
    hover_plant,
    nominal_gains,
    predict_std,
    sensor_noise_std,
)
from .errors import SweepError
from .metrics import histogram_edges
from .sweep_extend import EXTENSION_VALUES, MAX_EXTENSIONS, PairBlock, extend_grid
from .sweep_inputs import check_gains, check_pairs, prepare
from .sweep_interval import BLOCK_SECONDS, LEVEL, interval_summary
from .sweep_margins import loop_margins
from .sweep_replay import TD_COLUMNS, check_chunk_pairs, replay, replay_on
from .sweep_result import SweepResult

__all__ = ["SweepConfig", "sweep_config", "sweep_gains", "sweep_pairs"]

_DEG = 180.0 / math.pi


# ------------------------------------------------------------------- config
@dataclass(frozen=True)
class SweepConfig:
    """Settings of a gain sweep: the keyword arguments of :func:`sweep_gains` and :func:`sweep_pairs`.

    ``sweep_gains(model, kp, kd, config)`` runs a sweep from one; keyword settings replace its fields
    (``sweep_gains(model, kp, kd, windows=10)``). The fields are checked when the sweep runs
    (:class:`SweepError`).

    Attributes
    ----------
    axis : {"roll", "pitch", "yaw"}
        Axis swept; the other two are held by ``nominal`` gains.
    duration : float or None
        Length of each replayed window [s]; None replays each selected trace whole
        (from its start, for the length of the shortest), or each explicit window
        from its offset to the end of its trace (for the length of the shortest).
    dt : float or None
        Control period [s], a whole number of the traces' sample periods; None (default): the environment's
        for the model (:func:`heli_core.control_period.default_dt`: 0.01 s, or 0.02 s for a 50 Hz log's model).
    seed : int
        Seeds the window offsets (``numpy.random.Generator``); same seed, same result.
    traces : sequence of int, or of (trace, offset), optional
        Library traces to draw windows from (default all), or explicit windows.
    windows : int, optional
        Number of (trace, offset) windows, spread round robin over ``traces`` with
        distinct offsets per trace, drawn at random; windows of one trace may
        overlap when the trace is shorter than their total length. Default: windows that
        tile every trace end to end (:func:`~controllers.sweep_inputs.tile_windows`), the
        whole library flown once: every p90 then carries the smallest sampling error the
        library allows, its 90 % interval in the table (:mod:`controllers.sweep_interval`).
    progress : bool
        tqdm bar on stderr (when it is a terminal).
    nominal : array (3, 2), optional
        (kp, kd) per axis for the held axes; default :func:`~controllers.closed_loop.nominal_gains`.
    agree_tol : float
        Relative difference of the p90s above which time and frequency domain are flagged.
    keep_samples : bool
        Keep every pair's signed error samples in ``result.samples``.
    hist_max_deg, hist_bins : float, int
        Histogram: top edge [deg] and number of bins (the first bin is [0, 0.01°), the
        others geometric up to ``hist_max_deg``).
    max_batch : int
        Pair × window states stepped at once (memory: ~12 bytes × steps each).
    backend : None, {"local", "ray"} or heli_core.backends.Backend
        Where the time-domain replay runs. None (default): in this process, as one
        batch. Otherwise the stable pairs are split into chunks (``chunk_pairs``) run as
        tasks of the backend (``"local"``: every core of this machine; ``"ray"``:
        ``RAY_ADDRESS`` or a Ray instance started here, closed after the sweep). The
        result is the same, bit for bit, on every backend and worker count.
    chunk_pairs : int, optional
        Pairs per task with a backend (default :data:`TASK_STATES` // windows).
    extend : bool
        Grow the grid while its best pair lies on an edge (default True). The grid gains
        :data:`~controllers.sweep_extend.EXTENSION_VALUES` values past that edge per round, its last
        ratio continued (:func:`~controllers.sweep_extend.continuation`); ``settings["extension"]``
        and the ``extension_round`` column record what was added and why the growth stopped.
    max_extensions : int
        Rounds of growth at most (default :data:`MAX_EXTENSIONS`), >= 0.
    sensors : bool
        The autopilot reads the state through the model's identified sensors (``model.json["sensors"]``:
        white noise and vibration lines, :func:`~controllers.sweep_inputs.sensor_inputs`) in the replay, and
        their variance is added in the frequency domain (:func:`~controllers.closed_loop.sensor_noise_std`);
        False: the true state (default True; a model without sensors reads the true state either way).
    d_filter_hz : None, float or 3 floats
        Cutoff of the derivative filter every pair (and the held axes) flies with [Hz], as
        :class:`controllers.pd.PDController` runs it; None: no filter (default). The replay, the poles, the
        margins and the frequency-domain prediction all include it (:func:`~controllers.closed_loop.hover_plant`).
    """

    axis: object = "roll"
    duration: float | None = 60.0
    dt: float | None = None
    seed: int = 0
    traces: object = None
    windows: int | None = None
    progress: bool = True
    nominal: object = None
    agree_tol: float = 0.2
    keep_samples: bool = False
    hist_max_deg: float = 30.0
    hist_bins: int = 120
    max_batch: int = 4096
    backend: object = None
    chunk_pairs: int | None = None
    extend: bool = True
    max_extensions: int = MAX_EXTENSIONS
    sensors: bool = True
    d_filter_hz: object = None


# -------------------------------------------------------------------- sweep
def sweep_gains(model, kp_values, kd_values, config: SweepConfig | None = None, **settings) -> SweepResult:
    """Predict the error distribution of every PD gain pair of a Kp × Kd grid (paper Section 4).

    Each pair's gain and phase margins come beside its errors (:meth:`SweepResult.best_robust`
    picks among the pairs that keep 6 dB and 45°). When the best pair lies on an edge of the
    grid, the grid grows past that edge and the new pairs are swept on the same windows, until
    the best pair is interior, the pair beyond is unstable, or ``max_extensions`` rounds ran
    (:mod:`controllers.sweep_extend`; ``extend=False`` sweeps the grid as given).

    Parameters
    ----------
    model : str, Path, EnvModel or None
        Model directory written by ``heli identify`` (``model.json`` + ``disturbances/``),
        a loaded :class:`heli_env.env_model.EnvModel`, or None for the shipped model.
    kp_values : sequence of float, shape (n_kp,)
        Proportional gains [stick/rad], >= 0.
    kd_values : sequence of float, shape (n_kd,)
        Derivative gains [stick/(rad/s)], >= 0.
    config : SweepConfig, optional
        The sweep's settings (default ``SweepConfig()``), described there.
    **settings
        :class:`SweepConfig` fields replacing the config's (``axis="pitch", windows=10, ...``).

    Returns
    -------
    SweepResult

    Raises
    ------
    SweepError
        Bad gains, axis, dt or duration, windows that do not fit, a missing or corrupt model directory,
        or nominal gains that do not stabilise the held axes.
    identification.errors.MissingDependency
        ``backend="ray"`` without the ``cluster`` extra.
    identification.errors.TaskFailed
        A backend's worker died more often than its retries allow.
    """
    cfg = sweep_config(config, settings)
    kp_values = check_gains(kp_values, "kp_values")
    kd_values = check_gains(kd_values, "kd_values")
    return _sweep(model, kp_values, kd_values, "grid", cfg)


def sweep_pairs(model, pairs, config: SweepConfig | None = None, **settings) -> SweepResult:
    """:func:`sweep_gains` on a list of ``(kp, kd)`` pairs instead of a grid (same arguments).

    The table rows follow ``pairs``; ``kp_values``/``kd_values`` hold each pair's
    gains and :meth:`SweepResult.grid` is not available. A list has no edges to grow:
    ``extend`` and ``max_extensions`` are accepted (so one :class:`SweepConfig` runs
    either function) and the extension is recorded as ``"disabled"``.
    """
    cfg = sweep_config(config, settings)
    _, kp, kd = check_pairs(pairs)
    return _sweep(model, kp, kd, "pairs", cfg)


def sweep_config(config: SweepConfig | None, settings: dict) -> SweepConfig:
    """``config`` (default ``SweepConfig()``) with ``settings`` replacing its fields
    (:func:`heli_core.config.configured`).

    Raises
    ------
    TypeError
        ``config`` is not a SweepConfig, or a setting that is not one of its fields (the message lists them).
    """
    return configured(SweepConfig, config, settings, "sweep")


def _make_backend(backend):
    """:func:`heli_core.backends.make_backend`, an unknown name reported as a :class:`SweepError`.

    Making a backend starts nothing (no processes, no Ray instance) until its first ``map``;
    ``"ray"`` without the ``cluster`` extra raises :class:`~heli_core.errors.MissingDependency`.
    Looked up through :mod:`heli_core.backends` (its re-export), where the tests replace it.
    """
    from heli_core.errors import BackendError
    from heli_core.backends import make_backend

    try:
        return make_backend(backend)
    except BackendError as e:
        raise SweepError(str(e)) from e


def _check_settings(cfg: SweepConfig, be) -> np.ndarray:
    """Check the sweep's own settings (before any work); the histogram edges."""
    if be is not None:
        check_chunk_pairs(cfg.chunk_pairs)
    if not isinstance(cfg.extend, (bool, np.bool_)):
        raise SweepError(f"extend must be True or False, got {cfg.extend!r}")
    m = cfg.max_extensions
    if not (isinstance(m, (int, np.integer)) and not isinstance(m, bool) and m >= 0):
        raise SweepError(f"max_extensions must be a whole number >= 0, got {m!r}")
    agree_tol = cfg.agree_tol
    if not (isinstance(agree_tol, (int, float)) and agree_tol > 0 and math.isfinite(agree_tol)):
        raise SweepError(f"agree_tol must be a positive fraction, got {agree_tol!r}")
    try:
        return histogram_edges(float(cfg.hist_max_deg), int(cfg.hist_bins))
    except ValueError as e:
        raise SweepError(str(e)) from e


def _plant_and_nominal(rp, nominal, d_filter_hz=None):
    """The hover plant at the library's mean collective (with the derivative filters' states), and the held
    axes' gains, checked to stabilise."""
    plant = hover_plant(rp.env_model.params, rp.dt, float(np.mean(rp.env_model.collective)), d_filter_hz)
    nominal = nominal_gains(plant) if nominal is None else np.asarray(nominal, dtype=float).reshape(3, 2)
    ax = rp.axis
    _, nominal_ok = closed_loop_poles(plant, ax, [nominal[ax][0]], [nominal[ax][1]], nominal)
    if not nominal_ok[0]:
        raise SweepError(f"the nominal gains {nominal.tolist()} do not stabilise the model; pass nominal=")
    return plant, nominal


@dataclass(eq=False)
class _Run:
    """What every batch of pairs of one sweep shares (windows, plant, spectrum, backend), and what they took."""

    rp: object
    plant: object
    nominal: np.ndarray
    freq: np.ndarray
    psd: np.ndarray
    hist_edges: np.ndarray
    be: object
    cfg: SweepConfig
    seconds: dict
    tasks: int = 0
    where: str = "in-process"
    bar: object = None

    def progress(self):
        """The one bar over the whole sweep (every round of a growing grid adds its tasks to it), or False."""
        if not self.cfg.progress:
            return False
        if self.bar is None:
            import sys

            from tqdm import tqdm

            self.bar = tqdm(total=0, desc=f"sweep {AXES[self.rp.axis]}", unit="task" if self.be else "step",
                            unit_scale=self.be is None, leave=False, file=sys.stderr, disable=not sys.stderr.isatty())
        return self.bar

    def close(self):
        if self.bar is not None:
            self.bar.close()

    @property
    def sensors(self):
        """The sensors the autopilot reads through (None: the true state)."""
        inputs = self.rp.inputs
        return None if inputs.att_noise is None else self.rp.env_model.sensors

    def evaluate(self, kp: np.ndarray, kd: np.ndarray) -> PairBlock:
        """Poles, margins, the frequency-domain prediction and the replay of the pairs ``(kp[g], kd[g])``."""
        ax, G, dt = self.rp.axis, kp.size, self.rp.dt
        t0 = time.perf_counter()
        max_pole, stable = closed_loop_poles(self.plant, ax, kp, kd, self.nominal)
        gm, pm = loop_margins(self.plant, ax, kp, kd, self.nominal)
        sigma = predict_std(self.plant, ax, kp, kd, self.nominal, self.freq, self.psd)
        if self.sensors is not None:  # the noise the autopilot reads, added in variance to the gusts' errors
            sigma = np.hypot(sigma, sensor_noise_std(self.plant, ax, kp, kd, self.nominal, self.sensors))
        self.seconds["frequency_domain"] += time.perf_counter() - t0
        with np.errstate(divide="ignore", invalid="ignore"):
            settle = np.where(stable, -4.0 * dt / np.log(np.minimum(max_pole, 1.0)), np.inf)
        table = {"kp": kp, "kd": kd, "max_pole": max_pole, "settle_s": settle, "gain_margin_db": gm,
                 "phase_margin_deg": pm}
        table.update({c: np.full(G, np.nan) for c in TD_COLUMNS})
        block = PairBlock(table, np.zeros((G, self.hist_edges.size - 1), dtype=np.int64), np.zeros(G, dtype=np.int64))
        status = np.where(stable, "stable", "unstable").astype(object)
        t0 = time.perf_counter()
        self._time_domain(kp, kd, stable, block, status)
        self.seconds["time_domain"] += time.perf_counter() - t0
        _predicted(table, sigma, self.cfg.agree_tol)
        table["status"] = status
        table["extension_round"] = np.zeros(G, dtype=np.int64)
        return block

    def _time_domain(self, kp, kd, stable, block: PairBlock, status) -> None:
        """Replay the stable pairs (here or on the backend), filling ``block`` and ``status`` in place."""
        idx = np.flatnonzero(stable)
        if not idx.size:
            return
        cfg, rp = self.cfg, self.rp
        if self.be is None:
            st, h, o, div, smp = replay(rp, kp[idx], kd[idx], self.nominal, cfg.keep_samples, self.progress(),
                                        cfg.max_batch, self.hist_edges, self.plant.d_poles)
            self.tasks += 1
        else:
            st, h, o, div, smp, n_tasks = replay_on(self.be, rp, kp[idx], kd[idx], self.nominal, self.hist_edges, cfg,
                                                    self.progress(), self.plant.d_poles)
            self.tasks += n_tasks
            self.where = self.be.describe()
        for c in TD_COLUMNS:
            block.table[c][idx] = st[c]
        block.hist[idx], block.overflow[idx] = h, o
        status[idx[div]] = "diverged"
        block.samples = {int(idx[j]): v for j, v in smp.items()}

    def beyond_fault(self, kp: float, kd: float) -> str | None:
        """What keeps the grid from growing towards ``(kp, kd)``: instability, no margin; None if nothing."""
        _, stable = closed_loop_poles(self.plant, self.rp.axis, [kp], [kd], self.nominal)
        if not stable[0]:
            return "unstable"
        gm, pm = loop_margins(self.plant, self.rp.axis, [kp], [kd], self.nominal)
        if gm[0] <= 0.0 or pm[0] <= 0.0:
            return f"without margin (gain margin {gm[0]:.2f} dB, phase margin {pm[0]:.1f}°)"
        return None

    def settings(self, layout: str, total_seconds: float) -> dict:
        """The result's ``settings``: what was swept, on which windows and gains, how long each part took."""
        rp, env_model, cfg = self.rp, self.rp.env_model, self.cfg
        df = self.freq[1] - self.freq[0]
        return {
            "model": str(env_model.path), "library_version": env_model.library_version,
            "trace_ids": list(env_model.trace_ids), "axis": AXES[rp.axis], "layout": layout, "dt": rp.dt,
            "duration": rp.steps * rp.dt, "steps": rp.steps, "seed": int(cfg.seed), "n_windows": len(rp.windows),
            "nominal_gains": self.nominal.tolist(), "agree_tol": float(cfg.agree_tol),
            "linearised_at_collective": self.plant.collective,
            "ud_std": np.sqrt(np.sum(self.psd, axis=1) * df).tolist(),
            "seconds": {"total": total_seconds, **self.seconds}, "backend": self.where, "tasks": self.tasks,
            "sensors": env_model.sensors.to_dict() if rp.inputs.att_noise is not None else None,
            "p90_interval": p90_interval_settings(rp),
            "d_filter_hz": d_cutoffs(self.cfg.d_filter_hz),
        }


def p90_interval_settings(rp) -> dict:
    """How the p90s' intervals were made (``settings["p90_interval"]``; the half-widths are added at the end)."""
    n_blocks = None if rp.blocks is None else int(np.max(rp.blocks[0])) + 1
    return {"level": LEVEL, "method": f"Woodruff's, over blocks of {BLOCK_SECONDS:g} s of library time",
            "block_s": BLOCK_SECONDS, "n_blocks": n_blocks,
            "library_s_flown": None if n_blocks is None else _library_seconds(rp)}


def _library_seconds(rp) -> float:
    """Seconds of library time the windows cover (each stretch counted once)."""
    wins = np.asarray(rp.windows, dtype=np.int64).reshape(-1, 2)
    samples = wins[:, 1:] + rp.ratio * np.arange(rp.steps, dtype=np.int64)[None, :]
    keys = wins[:, :1] * (int(samples.max()) + 1) + samples
    return float(np.unique(keys).size * rp.dt)


def _predicted(table: dict, sigma: np.ndarray, agree_tol: float) -> None:
    """The frequency-domain columns from the predicted σ, and where the two domains disagree, in place."""
    s_att, s_rate, s_stick = (sigma[:, 0] * _DEG, sigma[:, 1] * _DEG, sigma[:, 2])
    table["pred_att_rms_deg"], table["pred_rate_rms_dps"], table["pred_stick_rms"] = s_att, s_rate, s_stick
    for q, f in GAUSS_ABS_FACTOR.items():
        table[f"pred_att_p{q}_deg"] = f * s_att
        table[f"pred_rate_p{q}_dps"] = f * s_rate
    with np.errstate(invalid="ignore", divide="ignore"):
        table["att_p90_rel_diff"] = table["att_p90_deg"] / table["pred_att_p90_deg"] - 1.0
        table["rate_p90_rel_diff"] = table["rate_p90_dps"] / table["pred_rate_p90_dps"] - 1.0
    table["disagree"] = (np.abs(np.nan_to_num(table["att_p90_rel_diff"])) > agree_tol) | (
        np.abs(np.nan_to_num(table["rate_p90_rel_diff"])) > agree_tol)


def _grown(run: _Run, kp_values, kd_values, layout, cfg: SweepConfig):
    """Sweep the grid (or the pairs) and grow a grid while its best pair lies on an edge.

    Returns ``(kp_values, kd_values, block, extension record)``.
    """
    record = {"enabled": bool(cfg.extend) and layout == "grid", "max_extensions": int(cfg.max_extensions),
              "values_per_round": EXTENSION_VALUES, "kp_asked": kp_values.tolist(), "kd_asked": kd_values.tolist()}
    if layout != "grid":
        block = run.evaluate(kp_values, kd_values)
        return kp_values, kd_values, block, {**record, "rounds": [], "stop": "disabled",
                                             "stop_detail": "a list of pairs has no edges to grow"}
    KP, KD = np.meshgrid(kp_values, kd_values, indexing="ij")
    block = run.evaluate(KP.ravel(), KD.ravel())
    kp_values, kd_values, block, grown = extend_grid(kp_values, kd_values, block, run.evaluate, run.beyond_fault,
                                                     cfg.max_extensions if cfg.extend else 0)
    if not cfg.extend and grown["stop"] == "limit":
        grown.update(stop="disabled", stop_detail=grown["stop_detail"] + " (extension off)")
    return kp_values, kd_values, block, {**record, **grown}


def _sweep(model, kp_values, kd_values, layout, cfg: SweepConfig) -> SweepResult:
    t_start = time.perf_counter()
    be = None if cfg.backend is None else _make_backend(cfg.backend)  # check before any work
    run = None
    try:
        hist_edges = _check_settings(cfg, be)
        rp = prepare(model, cfg.axis, cfg.duration, cfg.dt, cfg.seed, cfg.traces, cfg.windows, cfg.sensors)
        plant, nominal = _plant_and_nominal(rp, cfg.nominal, cfg.d_filter_hz)
        t0 = time.perf_counter()
        freq, psd = disturbance_spectrum(rp.env_model, rp.dt)
        run = _Run(rp, plant, nominal, freq, psd, hist_edges, be, cfg,
                   {"time_domain": 0.0, "frequency_domain": time.perf_counter() - t0})
        kp_values, kd_values, block, extension = _grown(run, kp_values, kd_values, layout, cfg)
        settings = run.settings(layout, time.perf_counter() - t_start)
        settings["extension"] = extension
        settings["p90_interval"].update(interval_summary(block.table, block.table["status"] == "stable"))
        return SweepResult(AXES[rp.axis], np.asarray(kp_values), np.asarray(kd_values), block.table, hist_edges,
                           block.hist, block.overflow, rp.windows, freq, psd, settings, block.samples)
    finally:
        if run is not None:
            run.close()
        if be is not cfg.backend:  # made here from a name: release it
            be.close()


__getattr__ = module_getattr(__name__)
