"""Check a sweep's predicted error distributions against flight tests of the truth model in fresh wind.

The paper's Section 4 proposal ends with "... could then be predicted and
compared with flight tests". Here the flight test is the project's synthetic
aircraft (:mod:`identification.synthetic`): the truth model integrated by the
physics core's RK4 with sub-steps (as the flight generator flies it), a
digital PD autopilot at the control period holding its stick over each period
(zero-order hold), and **fresh wind**: coloured noise
(:func:`identification.synthetic.coloured_noise`, the generator's wind model:
white noise through a 2nd-order Butterworth low-pass) at the level and
bandwidth *measured on the library* — not the library traces that made the
prediction. The autopilot sees the generator's sensor model (gyro noise, rotor
vibration, attitude noise; :class:`identification.synthetic.FlightConfig`)
and adds the trim of the *identified* model for the flown collective (what a
real autopilot would know); the errors compared are those of the true state
(the aircraft's, as a motion-capture reference would give them).

The truth is, by choice:

* ``"model"`` — the model's own identified parameters: a clean check of the
  method (the wind library and the two predictions), free of model error;
* ``"paper"`` — :data:`identification.synthetic.PAPER_PARAMS`, the truth the
  shipped model's synthetic flights were flown with: adds the identification
  error (e.g. k12, kd3 of the yaw axis);
* a :class:`heli_core.params.ModelParams`.

The collective wanders as the generator's does (0.05 Hz low-pass) around the
library's recorded mean with its standard deviation.

Two-sample Kolmogorov-Smirnov statistics (``scipy.stats.ks_2samp``) compare
measured |error| samples with the time-domain prediction's; one-sample KS
(``scipy.stats.kstest`` against a half-normal) with the frequency-domain
prediction. Samples are autocorrelated, so KS p-values would be far too
optimistic and are not reported; the statistic (largest CDF gap) is the
measure. Issue target: KS <= 0.1 at stable swept gains.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from heli_core.files import jsonable, write_text
from heli_core.params import ModelParams
from heli_core.physics import trim_sticks
from heli_core.terms import AXES
from identification.synthetic import PAPER_PARAMS, FlightConfig, coloured_noise

from .closed_loop import axis_index, disturbance_spectrum
from .errors import SweepError
from .metrics import QUANTILES
from .replay import LoopInputs, fly, rk4_step
from .sweep_inputs import check_pairs, load_model

_DEG = 180.0 / math.pi
KS_TARGET = 0.1


def fit_corner(freq: np.ndarray, psd: np.ndarray, floor: float = 1e-3) -> float:
    """Corner frequency [Hz] of a 2nd-order Butterworth power spectrum ``S0/(1 + (f/fc)^4)`` fitted to ``psd``.

    Least squares on ``log S`` over the bins (DC excluded) where ``psd`` is at least
    ``floor`` times its low-frequency level, i.e. the band that carries the gusts.
    """
    from scipy.optimize import least_squares

    f, s = freq[1:], psd[1:]
    level = np.median(s[: max(3, s.size // 100)])
    band = (s >= floor * level) & (s > 0)
    f, s = f[band], s[band]
    if f.size < 3:
        raise SweepError("the disturbance spectrum is too short or too flat to fit a bandwidth")

    def resid(v):
        return v[0] - np.log1p((f / math.exp(v[1])) ** 4) - np.log(s)

    sol = least_squares(resid, [math.log(level), math.log(f[min(f.size - 1, f.size // 4)])])
    return float(math.exp(sol.x[1]))


def wind_statistics(env_model, dt: float) -> dict:
    """Level and bandwidth of the library's gusts per axis, and its collective's mean and spread.

    ``std`` is the standard deviation of the replayed u_d
    (:attr:`heli_env.model_dir.EnvModel.replay_ud`; each trace's mean removed,
    eq. 42) at the control period; ``corner_hz`` the fitted Butterworth corner of its
    Welch spectrum (:func:`fit_corner`).
    """
    ratio = int(round(dt * env_model.sample_rate))
    var = np.zeros(3)
    n = 0
    for s, m in zip(env_model.starts, env_model.lengths):
        seg = env_model.replay_ud[:, s:s + m:ratio]
        var += seg.var(axis=1) * seg.shape[1]
        n += seg.shape[1]
    freq, psd = disturbance_spectrum(env_model, dt)
    return {"std": np.sqrt(var / n).tolist(), "corner_hz": [fit_corner(freq, p) for p in psd],
            "collective_mean": float(np.mean(env_model.collective)),
            "collective_std": float(np.std(env_model.collective))}


def _truth(truth, env_model) -> tuple[str, ModelParams]:
    if isinstance(truth, ModelParams):
        return "given", truth
    if truth == "model":
        return "model", env_model.params
    if truth == "paper":
        return "paper", PAPER_PARAMS
    raise SweepError(f"truth must be 'model', 'paper' or a ModelParams, got {truth!r}")


@dataclass(eq=False)
class FlightTestResult:
    """Measured against predicted error distributions, per gain pair.

    Attributes
    ----------
    axis : str
    table : dict of str -> ndarray (n_pairs,)
        ``kp``, ``kd``, ``status`` ("flown" or "unstable"), ``ks_att``/``ks_rate`` (two-sample KS
        against the time-domain prediction), ``ks_att_gauss``/``ks_rate_gauss`` (against the
        frequency-domain half-normal), measured ``att_p{50,90,99}_deg``, ``rate_p{...}_dps``,
        predicted ``pred_td_*`` and ``pred_fd_*``, ``saturation``.
    settings : dict
        Truth, wind statistics, flights, duration, seed, sensors.
    samples : dict of int -> (att_err_deg, rate_err_deg_s)
        Measured signed errors per flown pair, all flights concatenated.
    """

    axis: str
    table: dict
    settings: dict
    samples: dict

    @property
    def flown(self) -> np.ndarray:
        return self.table["status"] == "flown"

    @property
    def max_ks(self) -> float:
        """Largest KS statistic (|attitude error|, time-domain prediction) over the flown pairs."""
        v = np.asarray(self.table["ks_att"], dtype=float)[self.flown]
        return float(v.max()) if v.size else float("nan")

    @property
    def target_met(self) -> bool:
        return bool(self.max_ks <= KS_TARGET)

    def rows(self) -> list:
        keys = list(self.table)
        out = []
        for i in range(self.table["kp"].size):
            row = {}
            for k in keys:
                v = self.table[k][i]
                row[k] = v.item() if hasattr(v, "item") else v
            out.append(row)
        return out

    def to_markdown(self) -> str:
        """The report section (:func:`controllers.sweep_report.flight_test_markdown`)."""
        from .sweep_report import flight_test_markdown

        return flight_test_markdown(self)

    def to_json(self, path):
        import json

        doc = {"schema": "heli-env/flight-test", "schema_version": 1, "axis": self.axis,
               "settings": self.settings, "ks_target": KS_TARGET, "target_met": self.target_met,
               "rows": self.rows()}
        return write_text(path, json.dumps(jsonable(doc), indent=1, allow_nan=False) + "\n")


def _prediction_rows(prediction, axis: str, dt: float, kp, kd) -> list:
    """Row of ``prediction`` for each pair ``(kp[g], kd[g])``, checked to be a sweep of ``axis`` at ``dt``.

    :meth:`~controllers.sweep.SweepResult.index` finds the *nearest* row, so without these checks a
    sweep of another axis, control period or gains would be compared with the flights without a word.
    :class:`SweepError` unless the axis and dt are the flight test's and every pair is a row.
    """
    if prediction.axis != axis:
        raise SweepError(f"prediction must be a sweep of the flight test's axis ({axis}), got a sweep of "
                         f"{prediction.axis}")
    pred_dt = float(prediction.settings["dt"])
    if not math.isclose(pred_dt, dt, rel_tol=1e-9, abs_tol=0.0):
        raise SweepError(f"prediction must be run at the flight test's dt = {dt:g} s, got dt = {pred_dt:g} s")
    table_kp, table_kd = np.asarray(prediction.table["kp"], float), np.asarray(prediction.table["kd"], float)
    rows = []
    for k, d in zip(kp, kd):
        i = prediction.index(k, d)
        if not np.allclose((table_kp[i], table_kd[i]), (k, d), rtol=1e-9, atol=1e-12):
            raise SweepError(f"prediction has no row for the pair (kp, kd) = ({k:g}, {d:g}) (its nearest is "
                             f"({table_kp[i]:g}, {table_kd[i]:g})); sweep the flight test's pairs")
        rows.append(i)
    return rows


def validate_against_flights(model, pairs, axis="roll", n_flights: int = 10, duration: float = 60.0, seed: int = 0,
                             truth="model", dt: float = 0.01, sensors: bool = True, substeps: int | None = None,
                             prediction=None, progress: bool = True, max_batch: int = 4096) -> FlightTestResult:
    """Fly the truth model under the PD autopilot in fresh wind; compare with the predicted distributions.

    Parameters
    ----------
    model : str, Path, EnvModel or None
        The model directory whose library makes the prediction (None: the shipped model).
    pairs : sequence of (kp, kd)
        Gain pairs [stick/rad, stick/(rad/s)] on ``axis``.
    axis : {"roll", "pitch", "yaw"}
    n_flights : int
        Flights per pair (the same fresh winds for every pair).
    duration : float
        Length of each flight [s].
    seed : int
        Seeds the fresh wind, the collective and the sensor noise.
    truth : "model", "paper" or ModelParams
        Parameters of the aircraft flown (see the module docstring).
    dt : float
        Autopilot period [s].
    sensors : bool
        The autopilot sees the flight generator's noisy sensors (default) or the true state.
    substeps : int, optional
        RK4 sub-steps per period (default the flight generator's, 4).
    prediction : SweepResult, optional
        A :func:`controllers.sweep.sweep_pairs` result for ``pairs`` on ``axis`` at ``dt`` with
        ``keep_samples=True`` (its nominal gains hold the other axes);
        default: the whole library replayed (each trace from its start, full length).
    progress : bool

    Returns
    -------
    FlightTestResult

    Raises
    ------
    SweepError
        Bad pairs, flights or duration, a missing or corrupt model directory, or a ``prediction``
        of another axis, another dt, without samples or without one of ``pairs``.
    """
    env_model = load_model(model)
    ax = axis_index(axis)
    arr, kp_all, kd_all = check_pairs(pairs)
    if int(n_flights) != n_flights or n_flights < 1:
        raise SweepError(f"n_flights must be a whole number >= 1, got {n_flights!r}")
    if not (duration > 0 and math.isfinite(duration)):
        raise SweepError(f"duration must be a positive number of seconds, got {duration!r}")
    cfg = FlightConfig()
    substeps = cfg.substeps if substeps is None else int(substeps)
    truth_name, params = _truth(truth, env_model)
    if prediction is None:
        from .sweep import sweep_pairs

        prediction = sweep_pairs(env_model, arr, axis=AXES[ax], duration=None, dt=dt, keep_samples=True,
                                 progress=progress)
    elif not prediction.samples:
        raise SweepError("prediction must be run with keep_samples=True")
    pred_idx = _prediction_rows(prediction, AXES[ax], dt, kp_all, kd_all)
    nominal = np.asarray(prediction.settings["nominal_gains"])
    pred_rows = [prediction.row(i) for i in pred_idx]
    flyable = np.array([r["status"] == "stable" for r in pred_rows])

    wind = wind_statistics(env_model, dt)
    n = int(round(duration / dt))
    inputs = _fresh_wind(np.random.default_rng(seed), wind, params, env_model.params, n, int(n_flights), dt,
                         sensors, cfg)
    idx = np.flatnonzero(flyable)
    att, rate, sat = _fly(params, env_model.params, inputs, ax, kp_all[idx], kd_all[idx], nominal, dt, substeps,
                          max_batch, progress)
    table, samples = _compare(kp_all, kd_all, flyable, idx, att, rate, sat, n, prediction, pred_idx, pred_rows)
    pset = prediction.settings
    settings = {"truth": truth_name, "truth_parameters": params.values(), "n_flights": int(n_flights),
                "duration": n * dt, "dt": dt, "seed": int(seed), "sensors": bool(sensors), "substeps": substeps,
                "wind": wind, "nominal_gains": nominal.tolist(), "model": str(env_model.path),
                "prediction": f"{pset['n_windows']} windows of {pset['duration']:g} s"}
    return FlightTestResult(AXES[ax], table, settings, samples)


def _fresh_wind(rng, wind: dict, params, model_params, n: int, F: int, dt: float, sensors: bool,
                cfg: FlightConfig) -> LoopInputs:
    """What ``F`` flights of ``n`` periods hold over each period: fresh gusts, a wandering collective, sensors.

    Per flight, in this order from ``rng``: the gust of each axis (coloured noise at the library's
    level and bandwidth), the collective (0.05 Hz low-pass around the library's mean), and with
    ``sensors`` the flight generator's gyro (noise + rotor vibration) and attitude noise. The torque
    is the truth's ``k·u_d``; the trim the autopilot adds is the identified model's (``model_params``).
    """
    fs = 1.0 / dt
    gust = np.empty((3, n, F))
    col = np.empty((n, F))
    gyro = np.zeros((3, n, F))
    attn = np.zeros((3, n, F))
    t = np.arange(n) * dt
    for f in range(F):
        for i in range(3):
            gust[i, :, f] = coloured_noise(rng, n, fs, wind["corner_hz"][i], wind["std"][i])
        col[:, f] = np.clip(wind["collective_mean"] + coloured_noise(rng, n, fs, 0.05, wind["collective_std"]),
                            -1.0, 1.0)
        if sensors:  # the flight generator's sensor model
            phase = rng.uniform(0, 2 * np.pi, size=(3, 2))
            vib = sum(cfg.vibration / (j + 1) * np.sin(2 * np.pi * (j + 1) * cfg.rotor_hz * t[None, :]
                                                          + phase[:, j:j + 1]) for j in range(2))
            gyro[:, :, f] = cfg.gyro_noise * rng.standard_normal((3, n)) + vib
            attn[:, :, f] = cfg.attitude_noise * rng.standard_normal((3, n))
    torque = params.control_gains[:, None, None] * gust
    trim = np.array(trim_sticks(model_params, col))  # the autopilot's trim: the identified model's
    return LoopInputs(trim, col, torque, att_noise=attn, rate_noise=gyro)


def _fly(params, model_params, inputs: LoopInputs, ax, kp, kd, nominal, dt, substeps, max_batch, progress):
    """The truth (``params``, RK4 with ``substeps``) under the autopilot (signs of ``model_params``).

    Returns the swept axis' attitude and rate errors (P, n, F) of the true state and the clipped periods (P, F).
    """
    P, n, F = kp.size, inputs.steps, inputs.windows
    att = np.zeros((P, n, F), dtype=np.float32)
    rate = np.zeros((P, n, F), dtype=np.float32)
    sat = np.zeros((P, F))
    signs = np.sign(model_params.control_gains)
    for sl, rec in fly(rk4_step(params, dt, substeps), inputs, ax, kp, kd, nominal, signs, max_batch, progress,
                       "flight tests"):
        att[sl], rate[sl], sat[sl] = rec.att, rec.rate, rec.sat
    return att, rate, sat


def _compare(kp_all, kd_all, flyable, idx, att, rate, sat, n, prediction, pred_idx, pred_rows):
    """The table of measured against predicted distributions per pair, and the measured samples."""
    from scipy import stats as sps

    G = kp_all.size
    cols = ["ks_att", "ks_att_gauss", "ks_rate", "ks_rate_gauss", "saturation"]
    for q in QUANTILES:
        cols += [f"att_p{q}_deg", f"pred_td_att_p{q}_deg", f"pred_fd_att_p{q}_deg",
                 f"rate_p{q}_dps", f"pred_td_rate_p{q}_dps", f"pred_fd_rate_p{q}_dps"]
    cols += ["att_p90_err_td", "att_p90_err_fd", "pred_settle_s"]
    table = {"kp": kp_all, "kd": kd_all, "status": np.where(flyable, "flown", "unstable").astype(object)}
    table.update({c: np.full(G, np.nan) for c in cols})
    samples = {}
    for j, gi in enumerate(idx):
        row, pi = pred_rows[gi], pred_idx[gi]
        ma, mr = np.abs(att[j].ravel()) * _DEG, np.abs(rate[j].ravel()) * _DEG
        pa, pr = np.abs(prediction.samples[pi][0]), np.abs(prediction.samples[pi][1])
        if not (np.all(np.isfinite(ma)) and np.max(ma) < 60.0):
            table["status"][gi] = "diverged"
            continue
        samples[int(gi)] = (att[j].T.ravel() * _DEG, rate[j].T.ravel() * _DEG)
        table["ks_att"][gi] = sps.ks_2samp(ma, pa).statistic
        table["ks_rate"][gi] = sps.ks_2samp(mr, pr).statistic
        table["ks_att_gauss"][gi] = sps.kstest(ma, "halfnorm", args=(0.0, row["pred_att_rms_deg"])).statistic
        table["ks_rate_gauss"][gi] = sps.kstest(mr, "halfnorm", args=(0.0, row["pred_rate_rms_dps"])).statistic
        table["saturation"][gi] = sat[j].mean() / n
        pm_a, pm_r = np.percentile(ma, QUANTILES), np.percentile(mr, QUANTILES)
        for q, va, vr in zip(QUANTILES, pm_a, pm_r):
            table[f"att_p{q}_deg"][gi] = va
            table[f"rate_p{q}_dps"][gi] = vr
            table[f"pred_td_att_p{q}_deg"][gi] = row[f"att_p{q}_deg"]
            table[f"pred_td_rate_p{q}_dps"][gi] = row[f"rate_p{q}_dps"]
            table[f"pred_fd_att_p{q}_deg"][gi] = row[f"pred_att_p{q}_deg"]
            table[f"pred_fd_rate_p{q}_dps"][gi] = row[f"pred_rate_p{q}_dps"]
        table["pred_settle_s"][gi] = row["settle_s"]
        table["att_p90_err_td"][gi] = row["att_p90_deg"] / pm_a[1] - 1.0
        table["att_p90_err_fd"][gi] = row["pred_att_p90_deg"] / pm_a[1] - 1.0
    return table, samples
