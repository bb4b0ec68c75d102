"""Check a sweep's predicted error distributions against flight tests of the truth model in fresh wind.

The paper's Section 4 proposal ends with "... could then be predicted and
compared with flight tests". Here the flight test is the project's synthetic
aircraft (:mod:`identification.bench.synthetic`): the truth model integrated by the
physics core's RK4 with sub-steps (as the flight generator flies it), a
digital PD autopilot at the control period holding its stick over each period
(zero-order hold), and **fresh wind** — not the library traces that made the
prediction, but new gusts of their statistics. By default (``gusts="spectrum"``)
each flight's gust is a phase-randomised surrogate of a library trace
(:func:`heli_env.surrogates.phase_randomised`: every Fourier amplitude of its
u_d kept, new phases), so it has the library's whole spectrum — slow and
broadband parts alike. ``gusts="corner"`` draws coloured noise instead
(:func:`identification.bench.synthetic.coloured_noise`, the generator's wind model:
white noise through a 2nd-order Butterworth low-pass) at the level and the one
fitted corner of the library's spectrum; a library of slow plus broadband gusts
has more slow power than that low-pass, and a loose loop, whose error is the
slow gust itself, then flies half the predicted error (KS 0.16–0.40 at
Kp ≤ 4 on the shipped model, `scripts/bench.py --only sweep`'s grid). The autopilot sees the generator's sensor model (gyro noise, rotor
vibration, attitude noise; :class:`identification.bench.flight_config.FlightConfig`)
and adds the trim of the *identified* model for the flown collective (what a
real autopilot would know); the errors compared are those of the true state
(the aircraft's, as a motion-capture reference would give them).

The truth is, by choice:

* ``"model"`` — the model's own identified parameters: a clean check of the
  method (the wind library and the two predictions), free of model error;
* ``"paper"`` — :data:`identification.bench.flight_config.PAPER_PARAMS`, the truth the
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

from heli_core.config import check, configured, is_flag, is_real, whole_number
from heli_core.deprecation import module_getattr
from heli_core.params import ModelParams
from heli_core.physics import trim_sticks
from heli_core.terms import AXES
from identification.bench.flight_config import PAPER_PARAMS, FlightConfig
from identification.bench.synthetic import coloured_noise, sensor_errors

from .closed_loop import axis_index, d_cutoffs, d_poles_of, disturbance_spectrum, replay_segments
from .errors import SweepError
from .flight_test_result import FlightTestResult
from .metrics import QUANTILES
from .replay import Autopilot, LoopInputs, fly, rk4_step
from .sweep_inputs import check_pairs, load_model

_DEG = 180.0 / math.pi
GUSTS = ("spectrum", "corner")
"""Fresh gusts of the flight tests (:attr:`FlightTestConfig.gusts`)."""
TRUTHS = ("model", "paper")
"""The truths named by a word (:attr:`FlightTestConfig.truth`); a ModelParams is the third kind."""


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
    (:attr:`heli_env.env_model.EnvModel.replay_ud`; each trace's mean removed,
    eq. 42) at the control period; ``corner_hz`` the fitted Butterworth corner of its
    Welch spectrum (:func:`fit_corner`).
    """
    var = np.zeros(3)
    n = 0
    for seg in replay_segments(env_model, dt):
        var += seg.var(axis=1) * seg.shape[1]
        n += seg.shape[1]
    freq, psd = disturbance_spectrum(env_model, dt)
    return {"std": np.sqrt(var / n).tolist(), "corner_hz": [fit_corner(freq, p) for p in psd],
            "collective_mean": float(np.mean(env_model.collective)),
            "collective_std": float(np.std(env_model.collective))}


def _truth(truth, env_model) -> tuple[str, ModelParams]:
    """(name, parameters) of the aircraft flown (:attr:`FlightTestConfig.truth`)."""
    if isinstance(truth, ModelParams):
        return "given", truth
    return truth, env_model.params if truth == "model" else PAPER_PARAMS


@dataclass(frozen=True)
class FlightTestConfig:
    """Settings of the flight tests of :func:`validate_against_flights` (all but the model, pairs and prediction).

    ``validate_against_flights(model, pairs, config)`` flies them; keyword settings replace its fields
    (``validate_against_flights(model, pairs, config, seed=3)``).

    Attributes
    ----------
    axis : {"roll", "pitch", "yaw"} or int
        Axis the pairs fly on; the prediction's nominal gains hold the other two.
    n_flights : int
        Flights per pair (the same fresh winds for every pair), >= 1.
    duration : float
        Length of each flight [s], > 0.
    seed : int
        Seeds the fresh wind, the collective and the sensor noise, >= 0.
    truth : "model", "paper" or ModelParams
        Parameters of the aircraft flown (see the module docstring).
    dt : float
        Autopilot period [s], > 0.
    sensors : bool
        The autopilot sees the flight generator's noisy sensors (default) or the true state.
    gusts : {"spectrum", "corner"}
        Fresh gusts as phase-randomised surrogates of the library's traces (default: its whole
        spectrum) or as coloured noise at its level and one fitted corner (the module docstring).
    substeps : int, optional
        RK4 sub-steps per period, >= 1 (default the flight generator's, 4).
    progress : bool
        tqdm bars on stderr (when it is a terminal).
    max_batch : int
        Pair × flight states stepped at once, >= 1 (memory, never a number).
    d_filter_hz : None, float or 3 floats
        The derivative filter the autopilot flies with [Hz] (:class:`controllers.sweep.SweepConfig`'s); a
        given prediction must have been swept with the same.

    Raises
    ------
    SweepError
        (a ValueError) A field out of range; the message names it, what was expected and what came.
    """

    axis: object = "roll"
    n_flights: int = 10
    duration: float = 60.0
    seed: int = 0
    truth: object = "model"
    dt: float = 0.01
    sensors: bool = True
    gusts: str = "spectrum"
    substeps: int | None = None
    progress: bool = True
    max_batch: int = 4096
    d_filter_hz: object = None

    def __post_init__(self):
        axis_index(self.axis)
        for name, minimum in (("n_flights", 1), ("seed", 0), ("max_batch", 1)):
            object.__setattr__(self, name, whole_number(getattr(self, name), name, minimum, SweepError))
        if self.substeps is not None:
            object.__setattr__(self, "substeps", whole_number(self.substeps, "substeps", 1, SweepError))
        check(is_real(self.duration) and self.duration > 0, "duration", "a positive number of seconds",
              self.duration, SweepError)
        check(is_real(self.dt) and self.dt > 0, "dt", "a positive control period in seconds", self.dt, SweepError)
        check(isinstance(self.truth, ModelParams) or (isinstance(self.truth, str) and self.truth in TRUTHS),
              "truth", "'model', 'paper' or a ModelParams", self.truth, SweepError)
        for name in ("sensors", "progress"):
            check(is_flag(getattr(self, name)), name, "True or False", getattr(self, name), SweepError)
        check(self.gusts in GUSTS, "gusts", f"one of {GUSTS}", self.gusts, SweepError)

    @property
    def steps(self) -> int:
        """Autopilot periods per flight."""
        return int(round(self.duration / self.dt))


def _prediction_rows(prediction, axis: str, dt: float, kp, kd) -> list:
    """Row of ``prediction`` for each pair ``(kp[g], kd[g])``, checked to be a sweep of ``axis`` at ``dt``.

    :meth:`~controllers.sweep_result.SweepResult.index` finds the *nearest* row, so without these checks a
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


def validate_against_flights(model, pairs, config: FlightTestConfig | None = None, *, prediction=None,
                             **settings) -> FlightTestResult:
    """Fly the truth model under the PD autopilot in fresh wind; compare with the predicted distributions.

    Parameters
    ----------
    model : str, Path, EnvModel or None
        The model directory whose library makes the prediction (None: the shipped model).
    pairs : sequence of (kp, kd)
        Gain pairs [stick/rad, stick/(rad/s)] on the config's ``axis``.
    config : FlightTestConfig, optional
        The flight tests' settings (default ``FlightTestConfig()``), described there.
    prediction : SweepResult, optional
        A :func:`controllers.sweep.sweep_pairs` result for ``pairs`` on ``axis`` at ``dt`` with
        ``keep_samples=True`` (its nominal gains hold the other axes);
        default: the whole library replayed (each trace from its start, full length).
    **settings
        :class:`FlightTestConfig` fields replacing the config's (``axis="pitch", n_flights=5, ...``).

    Returns
    -------
    FlightTestResult

    Raises
    ------
    SweepError
        Bad pairs or settings, a missing or corrupt model directory, or a ``prediction``
        of another axis, another dt, without samples or without one of ``pairs``.
    TypeError
        ``config`` is not a FlightTestConfig, or a keyword is not one of its fields.
    """
    cfg = configured(FlightTestConfig, config, settings, "flight test")
    env_model = load_model(model)
    arr, kp_all, kd_all = check_pairs(pairs)
    truth_name, params = _truth(cfg.truth, env_model)
    predicted = _Prediction.of(prediction, env_model, arr, cfg)
    wind = wind_statistics(env_model, cfg.dt)
    inputs = _fresh_wind(cfg, wind, params, env_model)
    idx = np.flatnonzero(predicted.flyable)
    autopilot = Autopilot(axis_index(cfg.axis), kp_all[idx], kd_all[idx], predicted.nominal,
                          np.sign(env_model.params.control_gains), d_poles_of(cfg.d_filter_hz, cfg.dt))
    substeps = FlightConfig().substeps if cfg.substeps is None else cfg.substeps
    flights = _fly(rk4_step(params, cfg.dt, substeps), inputs, autopilot, idx, cfg)
    table, samples = _compare(kp_all, kd_all, predicted, flights)
    pset = predicted.result.settings
    settings = {"truth": truth_name, "truth_parameters": params.values(), "n_flights": cfg.n_flights,
                "duration": cfg.steps * cfg.dt, "dt": cfg.dt, "seed": cfg.seed, "sensors": bool(cfg.sensors),
                "gusts": cfg.gusts, "substeps": substeps, "wind": wind, "nominal_gains": predicted.nominal.tolist(),
                "d_filter_hz": d_cutoffs(cfg.d_filter_hz),
                "model": str(env_model.path), "prediction": f"{pset['n_windows']} windows of {pset['duration']:g} s"}
    return FlightTestResult(AXES[autopilot.axis], table, settings, samples)


@dataclass(frozen=True, eq=False)
class _Prediction:
    """The sweep the flights are held against: its result, and per pair its row's index and the row."""

    result: object
    index: list
    rows: list

    @classmethod
    def of(cls, prediction, env_model, pairs, cfg: FlightTestConfig) -> _Prediction:
        """``prediction``'s rows of ``pairs`` (checked, :func:`_prediction_rows`), or a replay of the whole
        library computed here when ``prediction`` is None."""
        axis = AXES[axis_index(cfg.axis)]
        if prediction is None:
            from .sweep import sweep_pairs

            prediction = sweep_pairs(env_model, pairs, axis=axis, duration=None, dt=cfg.dt, keep_samples=True,
                                     progress=cfg.progress, d_filter_hz=cfg.d_filter_hz)
        elif not prediction.samples:
            raise SweepError("prediction must be run with keep_samples=True")
        elif prediction.settings.get("d_filter_hz") != d_cutoffs(cfg.d_filter_hz):
            raise SweepError(f"prediction must be swept with the flight test's derivative filter "
                             f"({d_cutoffs(cfg.d_filter_hz)} Hz), got {prediction.settings.get('d_filter_hz')}")
        index = _prediction_rows(prediction, axis, cfg.dt, pairs[:, 0], pairs[:, 1])
        return cls(prediction, index, [prediction.row(i) for i in index])

    @property
    def flyable(self) -> np.ndarray:
        """Pairs the prediction found stable (the others are not flown)."""
        return np.array([r["status"] == "stable" for r in self.rows])

    @property
    def nominal(self) -> np.ndarray:
        """(kp, kd) per axis of the held axes, shape (3, 2)."""
        return np.asarray(self.result.settings["nominal_gains"])


@dataclass(frozen=True, eq=False)
class _Flights:
    """What the flown pairs did on the swept axis: errors of the true state and the clipped periods."""

    pairs: np.ndarray  # (P,) index of each flown pair among all the pairs
    att: np.ndarray  # (P, n, F) attitude error [rad]
    rate: np.ndarray  # (P, n, F) rate error [rad/s]
    sat: np.ndarray  # (P, F) periods where the stick was clipped

    @property
    def steps(self) -> int:
        return int(self.att.shape[1])


def _fresh_wind(cfg: FlightTestConfig, wind: dict, params, env_model) -> LoopInputs:
    """What ``cfg.n_flights`` flights of ``cfg.steps`` periods hold over each period: fresh gusts, a wandering
    collective, sensors.

    Per flight, in this order from ``numpy.random.default_rng(cfg.seed)``: the gust of the three axes
    (``cfg.gusts``: surrogates of the library's traces, :func:`_surrogate_gust`, or coloured noise at its
    level and corner per axis), the collective (0.05 Hz low-pass around the library's mean), and with
    ``cfg.sensors`` the flight generator's gyro (noise + rotor vibration) and attitude noise
    (:class:`~identification.bench.flight_config.FlightConfig`). The torque is the truth's ``k·u_d``; the trim the
    autopilot adds is the identified model's (``env_model.params``).
    """
    rng, sensor = np.random.default_rng(cfg.seed), FlightConfig()
    n, F, dt = cfg.steps, cfg.n_flights, cfg.dt
    fs = 1.0 / dt
    gust = np.empty((3, n, F))
    col = np.empty((n, F))
    gyro = np.zeros((3, n, F))
    attn = np.zeros((3, n, F))
    t = np.arange(n) * dt
    traces = None
    if cfg.gusts == "spectrum":  # each trace's mean removed (eq. 42: the trim absorbs it)
        traces = [seg - seg.mean(axis=1, keepdims=True) for seg in replay_segments(env_model, dt)]
    for f in range(F):
        if traces is not None:
            gust[:, :, f] = _surrogate_gust(rng, traces, n)
        else:
            for i in range(3):
                gust[i, :, f] = coloured_noise(rng, n, fs, wind["corner_hz"][i], wind["std"][i])
        col[:, f] = np.clip(wind["collective_mean"] + coloured_noise(rng, n, fs, 0.05, wind["collective_std"]),
                            -1.0, 1.0)
        if cfg.sensors:  # the flight generator's sensor model
            terms, attn[:, :, f] = sensor_errors(rng, sensor, t)
            gyro[:, :, f] = sum(terms[1:], terms[0])
    torque = params.control_gains[:, None, None] * gust
    trim = np.array(trim_sticks(env_model.params, col))  # the autopilot's trim: the identified model's
    return LoopInputs(trim, col, torque, att_noise=attn, rate_noise=gyro)


def _surrogate_gust(rng: np.random.Generator, traces: list, n: int) -> np.ndarray:
    """``n`` periods of a new gust with the library's spectra: phase-randomised surrogates of traces drawn in
    proportion to their length, joined until long enough, from a random start."""
    from heli_env.surrogates import phase_randomised

    lengths = np.array([tr.shape[1] for tr in traces], dtype=float)
    pieces, have = [], 0
    while have < n + 1:
        piece = phase_randomised(traces[int(rng.choice(len(traces), p=lengths / lengths.sum()))], rng)
        pieces.append(piece)
        have += piece.shape[1]
    joined = np.concatenate(pieces, axis=1)
    start = int(rng.integers(0, joined.shape[1] - n + 1))
    return joined[:, start:start + n]


def _fly(step, inputs: LoopInputs, autopilot: Autopilot, pairs: np.ndarray, cfg: FlightTestConfig) -> _Flights:
    """The truth (``step``: its RK4 with sub-steps) under ``autopilot`` flying ``pairs`` (their indices among
    all the pairs); the swept axis' errors of the true state and the clipped periods."""
    P, n, F = autopilot.pairs, inputs.steps, inputs.windows
    att = np.zeros((P, n, F), dtype=np.float32)
    rate = np.zeros((P, n, F), dtype=np.float32)
    sat = np.zeros((P, F))
    for sl, rec in fly(step, inputs, autopilot, cfg.max_batch, cfg.progress, "flight tests"):
        att[sl], rate[sl], sat[sl] = rec.att, rec.rate, rec.sat
    return _Flights(pairs, att, rate, sat)


def _compare(kp_all, kd_all, predicted: _Prediction, flights: _Flights):
    """The table of measured against predicted distributions per pair, and the measured samples."""
    from scipy import stats as sps

    G = kp_all.size
    cols = ["ks_att", "ks_att_gauss", "ks_rate", "ks_rate_gauss", "saturation"]
    for q in QUANTILES:
        cols += [f"att_p{q}_deg", f"pred_td_att_p{q}_deg", f"pred_fd_att_p{q}_deg",
                 f"rate_p{q}_dps", f"pred_td_rate_p{q}_dps", f"pred_fd_rate_p{q}_dps"]
    cols += ["att_p90_err_td", "att_p90_err_fd", "pred_settle_s"]
    table = {"kp": kp_all, "kd": kd_all, "status": np.where(predicted.flyable, "flown", "unstable").astype(object)}
    table.update({c: np.full(G, np.nan) for c in cols})
    samples = {}
    att, rate, sat, n = flights.att, flights.rate, flights.sat, flights.steps
    for j, gi in enumerate(flights.pairs):
        row, pi = predicted.rows[gi], predicted.index[gi]
        ma, mr = np.abs(att[j].ravel()) * _DEG, np.abs(rate[j].ravel()) * _DEG
        pa, pr = np.abs(predicted.result.samples[pi][0]), np.abs(predicted.result.samples[pi][1])
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


__getattr__ = module_getattr(__name__)
