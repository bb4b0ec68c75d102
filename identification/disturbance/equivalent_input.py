"""Wind-disturbance identification with the intrinsic parameters fixed (Sections 2.5.3, 3.3, 3.4).

Once the intrinsic parameters are known (:class:`~identification.integral.method.IntegralIdentifier`),
the wind is the torque that the model is missing. Eq. (41) writes the roll
model with a piecewise-constant disturbance torque ``ū_d`` (eq. 43) in place of
the constant offset; integrating it over one interval ``[t_{i-1}, t_i]`` of
length Δt (eq. 45) gives eq. (46), solved for the interval's torque::

    ū_{d,i} = [ p(t_i) - p(t_{i-1}) - ∫ (every model term but the offset) dt ] / Δt     (46)
    ū_{d,i} = k2 * u_{d,i} + kd1,     mean(u_d) = 0                                      (42), (47)

so ``kd1 = mean(ū_d)`` and ``u_d = (ū_d - kd1) / k2`` is the *equivalent
cyclic input*: the stick deflection that would have produced the wind torque.
Pitch and yaw are the same with ``k6`` and ``k10`` (and, for yaw, the
collective term ``-k12*col`` among the model terms). The integrals are
trapezium-rule sums of the features of :mod:`heli_core.terms` on the
prefiltered flight (Section 3.1), with the Padé-delayed command (eq. 31,
:func:`~heli_core.servo.pade_filter`) when the model has a servo
delay; everything is vectorised over samples, intervals and axes. Samples after
the last whole interval keep the last interval's value.

Smoothing (Section 3.3, :mod:`identification.disturbance.smoothing`). The
interval-level profile is smoothed by repeated 10-point moving averages. With
``smoothing="auto"`` the number of passes is the one whose fitted normal
distribution of ``u_d`` is closest to that of the pilot's stick on that axis:
the paper's assumption is that the pilot's stick mirrors the gusts. The
two-sample Kolmogorov-Smirnov test (:func:`scipy.stats.ks_2samp`) and the 90 %
intervals of both are reported. Note that a *small* KS p-value (the paper's
0.00097) rejects the hypothesis that the two samples come from one
distribution; it is reported as it comes, without the paper's reading.

Simulation with the disturbance (Section 3.4). The model is simulated by
:func:`heli_core.physics.simulate` from the measured initial state with the
disturbance torque ``k*u_d`` and the offsets ``kd`` of eq. (47) in place of the
model's (the two differ by the estimator's noise; using eq. 47's keeps
``k*u_d + kd = ū_d`` exactly), and compared with the measured rate and attitude
by :func:`identification.validation.forward_simulation.validate_models`. The paper reports
0.095 deg/s mean absolute roll-rate error.

The trace a maximum-likelihood identification stores. With the wind-state
estimator the library does not store eq. (46)'s profile but the wind its
Rauch-Tung-Striebel smoother sees: since issue #30 one draw from the smoother's
posterior (:mod:`identification.disturbance.wind_posterior`, ``trace_source`` "posterior
draw"), which has the identified wind's full power, with the smoother's
conditional mean kept beside it (``trace_mean``, ``estimate``) for the plots,
the comparison with a known wind and the diagnosis.

Defaults from evidence. ``scripts/disturbance_study.py`` identifies the model
with ``IntegralIdentifier()`` on seeded 300 s synthetic flights (seeds 1-4,
100 Hz) and compares the identified u_d with the true wind for Δt in {0.02,
0.05, 0.1, 0.2, 0.5} s and smoothing "auto" or 0-20 passes. Mean correlation /
RMS error [stick units] over the seeds, roll | pitch | yaw (true wind RMS
0.055 | 0.055 | 0.018)::

    flights with sweeps (the default synthetic flight)
    Δt 0.02 s, 5 passes      0.980 / 0.0110 | 0.972 / 0.0129 | 0.990 / 0.0028   <- default
    Δt 0.02 s, 8 passes      0.979 / 0.0116 | 0.974 / 0.0127 | 0.986 / 0.0034
    Δt 0.02 s, no smoothing  0.781 / 0.0434 | 0.636 / 0.0655 | 0.969 / 0.0046
    Δt 0.02 s, "auto"        same as no smoothing: chooses 0 passes, because the
                             sweeps make the stick (std 0.22) far wider than u_d
    Δt 0.05 s, 1 pass        0.968 / 0.0137 | 0.958 / 0.0157 | 0.983 / 0.0036
    Δt 0.2 s, no smoothing   0.938 / 0.0197 | 0.889 / 0.0272 | 0.979 / 0.0037
    Δt 0.5 s, no smoothing   0.923 / 0.0211 | 0.910 / 0.0227 | 0.929 / 0.0068

    hover without sweeps, truth parameters (the paper's assumption holds)
    Δt 0.02 s, 5 passes      0.981 / 0.0108 | 0.973 / 0.0126 | 0.992 / 0.0025
    Δt 0.02 s, "auto"        0.980 / 0.0110 | 0.974 / 0.0124 | 0.971 / 0.0045
                             (chooses 4.5 | 6.2 | 0 passes on average)

Short intervals resolve the gusts but amplify the rate noise (ū_d is a
difference quotient of the measured rate), and the moving averages remove that
noise again; long intervals need no smoothing but average the gusts away, and
smoothing them as well blurs the wind beyond its 0.5 Hz corner. So the defaults
are :data:`DEFAULT_INTERVAL` = 0.02 s (two samples at 100 Hz; two samples on
slower logs) and :data:`DEFAULT_SMOOTHING` = 5 passes — the paper's own count.
The paper's rule ("auto") matches the best fixed count when the pilot's stick
mirrors the gusts (hover), but not on identification flights with sweeps, so it
is offered and always reported (``auto_passes``) rather than the default. At the
defaults, simulating with the identified disturbance brings the mean absolute
rate error from 1.13 | 0.72 | 2.80 deg/s to 0.140 | 0.126 | 0.223 deg/s and the
detrended attitude error from 1.37 | 1.07 | 3.14° to 0.15 | 0.15 | 0.15° (paper,
roll: 0.095 deg/s and 0.28°). Unsmoothed profiles reproduce the rate more
closely (0.07 deg/s at Δt = 0.1 s) because they also absorb the noise, which is
why the rate error alone cannot choose the smoothing.
"""

from __future__ import annotations

import hashlib

import numpy as np
from scipy import stats

from heli_core.params import ModelParams
from heli_core.servo import pade_filter
from heli_core.terms import AXES, STICK_ROW, TERMS, evaluate_features

from ..errors import DisturbanceError, SimulationDivergedError
from ..flight import Flight
from ..preprocess import lowpass_flight, without_folded_lines
from ..validation.forward_simulation import validate_models
from ..validation.result import ValidationResult
from .profile import MODEL_LABELS, OFFSET, DisturbanceProfile, interval90
from .smoothing import check_smoothing, smooth, smoothing_rule
from .wind_posterior import WindPosterior

DEFAULT_INTERVAL = 0.02
"""Default Δt of eqs. (43)-(46) [s], chosen in ``scripts/disturbance_study.py`` (module
docstring); raised to two samples on flights logged below 100 Hz."""

DEFAULT_SMOOTHING = 5
"""Default number of 10-point moving-average passes, chosen in ``scripts/disturbance_study.py``."""

CONTROL_GAIN = ("k2", "k6", "k10")
"""Parameter that turns the equivalent input u_d into torque on each axis (eq. 42)."""


# ------------------------------------------------------------------- helpers
def source_of(flight: Flight) -> dict:
    """Name and SHA-256 of a flight: the logged file's, or of its arrays when it has none."""
    meta = flight.metadata
    name = str(meta.get("source", "unnamed flight"))
    if meta.get("sha256"):
        return {"name": name, "sha256": str(meta["sha256"]), "sha256_of": "file"}
    h = hashlib.sha256()
    for a in (flight.time, flight.rates, flight.attitude, flight.sticks):
        h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
    return {"name": name, "sha256": h.hexdigest(), "sha256_of": "arrays"}


def _intervals(flight: Flight, interval: float) -> int:
    """Samples per interval N for Δt = ``interval``; named errors for Δt out of range."""
    fs = flight.sample_rate
    if not isinstance(interval, (int, float, np.integer, np.floating)) or not np.isfinite(interval) or interval <= 0:
        raise DisturbanceError(f"interval Δt must be a positive number of seconds, got {interval!r}")
    if interval * fs < 2.0 - 1e-9:
        raise DisturbanceError(
            f"interval Δt = {interval:g} s is shorter than two samples ({2.0 / fs:g} s at {fs:.4g} Hz); "
            "eq. (46) needs at least two samples per interval"
        )
    if interval > flight.duration + 0.5 / fs:
        raise DisturbanceError(
            f"interval Δt = {interval:g} s is longer than the flight ({flight.duration:.4g} s); "
            "choose Δt well below the flight's length"
        )
    N = int(round(interval * fs))
    if (flight.n - 1) // N < 2:
        raise DisturbanceError(
            f"interval Δt = {interval:g} s fits {(flight.n - 1) // N} time(s) in the flight of "
            f"{flight.duration:.4g} s; need at least 2 intervals (a zero-mean u_d of one interval is 0)"
        )
    return N


# -------------------------------------------------------------- identification
def identify_disturbance(flight: Flight, params: ModelParams, interval: float | None = None,
                         prefilter: bool = True, smoothing=DEFAULT_SMOOTHING, axes=AXES,
                         simulate: bool = True, wind_torque=None) -> DisturbanceProfile:
    """Identify the piecewise-constant wind disturbance of a flight, eqs. (41)-(47).

    Parameters
    ----------
    flight : Flight
        The flight, as recorded (``prefilter`` applies the Section 3.1 filter).
    params : ModelParams
        Identified intrinsic parameters, held fixed; its control gains
        k2, k6, k10 turn torque into the equivalent input u_d (eq. 42).
    interval : float, optional
        Δt over which the disturbance is constant [s] (eq. 43); rounded to a
        whole number N >= 2 of samples. Default :data:`DEFAULT_INTERVAL`, or
        two samples when that is longer.
    prefilter : bool
        Zero-phase FIR low-pass 4/8 Hz on rates and sticks before eq. (46),
        as for the parameters (:func:`~identification.preprocess.lowpass_flight`),
        the gyro's folded vibration lines removed first
        (:func:`~identification.preprocess.without_folded_lines`).
    smoothing : "auto" or int
        Number of 10-point moving-average passes on the interval-level u_d
        (default :data:`DEFAULT_SMOOTHING`), or "auto" to choose them per axis
        by the distribution match of Section 3.3.
    axes : sequence of str
        Axes to identify.
    simulate : bool
        Simulate the model without and with the disturbance (Section 3.4) and
        keep the comparison in ``simulation``.
    wind_torque : array_like, shape (3, n), or WindPosterior, optional
        The wind torque at every sample about the model's offsets [rad/s^2], as
        the maximum-likelihood model's smoother estimates it. When given, it is
        the profile's ``trace`` (over the control gain, zero-mean) and ``kd``
        (the model's offset plus its mean): the disturbance the library stores
        and the environment replays; the eq. (46) profile is still computed and
        reported beside it. A :class:`~identification.disturbance.wind_posterior.WindPosterior`
        makes its first draw the ``trace`` (``trace_source`` "posterior draw": gusts
        with the identified wind's full power) and keeps its mean in ``trace_mean``
        and ``kd``.

    Returns
    -------
    DisturbanceProfile

    Raises
    ------
    DisturbanceError
        Δt shorter than two samples, longer than the flight or fitting fewer
        than two intervals; a bad ``smoothing``; an unknown axis; an axis whose
        control gain in ``params`` is zero.
    """
    smoothing = check_smoothing(smoothing)
    axes, rows = _checked_axes(axes, params)
    N = _intervals(flight, max(DEFAULT_INTERVAL, 2.0 / flight.sample_rate) if interval is None else interval)
    data = lowpass_flight(without_folded_lines(flight)[0]) if prefilter else flight
    torque = interval_torque(data, params, N)
    kd, ud_raw = _equivalent_input(torque, params.control_gains, rows)
    # Smoothing (Section 3.3): the paper's rule is evaluated for every pass count on
    # every axis (reported even when a fixed count is used), then applied or not.
    stick = np.asarray(flight.sticks[list(STICK_ROW)], dtype=float)
    cost, auto = smoothing_rule(ud_raw, stick, rows)
    passes = [(auto[i] if smoothing == "auto" else smoothing) if i in rows else 0 for i in range(3)]
    ud = _smoothed(ud_raw, passes, rows)
    # Piecewise-constant trace at the flight's samples (eq. 43); the tail holds the last interval.
    which = np.minimum(np.arange(data.n) // N, torque.shape[1] - 1)
    trace = ud[:, which]
    statistics = {a: _axis_statistics(ud[i], ud_raw[i], stick[i], passes[i], auto[i]) for a, i in zip(axes, rows)}
    trace_source, trace_mean, trace_draw = "eq46", None, None
    if isinstance(wind_torque, WindPosterior):
        trace_mean, kd = _smoother_trace(wind_torque.mean, params, kd, rows, data.n)
        trace, _ = _smoother_trace(wind_torque.draw, params, kd, rows, data.n)
        trace_source, trace_draw = "posterior draw", wind_torque.describe()
    elif wind_torque is not None:
        trace, kd = _smoother_trace(wind_torque, params, kd, rows, data.n)
        trace_source = "smoother"
    if wind_torque is not None:
        mean = trace if trace_mean is None else trace_mean
        for a, i in zip(axes, rows):
            statistics[a].update(_smoother_statistics(mean[i], ud[i, which], trace_source))
            if trace_mean is not None:
                statistics[a].update(draw_ud_std=float(trace[i].std()), draw_ud_interval90=interval90(trace[i]))
    profile = DisturbanceProfile(
        axes=axes, interval=round(N * (1.0 / data.sample_rate), 12), samples_per_interval=N,
        sample_rate=round(float(data.sample_rate), 9), time=np.asarray(flight.time),
        interval_starts=data.time[np.arange(torque.shape[1]) * N],
        torque=torque, kd=kd, control_gains=params.control_gains, ud_raw=ud_raw, ud=ud, trace=trace,
        collective=np.asarray(data.sticks[2], dtype=float), sticks=stick, passes=tuple(int(p) for p in passes),
        smoothing=smoothing, smoothing_cost=cost, statistics=statistics, params=params,
        prefilter=dict(data.metadata.get("prefilter", {})) if prefilter else None, source=source_of(flight),
        trace_source=trace_source, trace_mean=trace_mean, trace_draw=trace_draw,
    )
    if simulate:
        _attach_simulation(profile, data)
    return profile


def _equivalent_input(torque: np.ndarray, gains: np.ndarray, rows) -> tuple[np.ndarray, np.ndarray]:
    """The offsets ``kd = mean(ū_d)`` (eq. 47 with zero-mean u_d) and the equivalent input
    ``u_d = (ū_d - kd) / k`` on ``rows`` (zero elsewhere), eq. (42), before smoothing."""
    kd = torque.mean(axis=1)
    ud_raw = np.zeros_like(torque)
    for i in rows:
        ud_raw[i] = (torque[i] - kd[i]) / gains[i]
    return kd, ud_raw


def _smoothed(ud_raw: np.ndarray, passes, rows) -> np.ndarray:
    """``ud_raw`` smoothed by ``passes[i]`` moving averages on each of ``rows`` and re-centred (zero elsewhere)."""
    ud = np.zeros_like(ud_raw)
    for i in rows:
        ud[i] = smooth(ud_raw[i], passes[i])
        ud[i] -= ud[i].mean()  # the ends (nearest-value padding) move the mean slightly
    return ud


def _attach_simulation(profile: DisturbanceProfile, data: Flight) -> None:
    """Keep :func:`simulate_with_disturbance` in ``profile.simulation``, or why it diverged in
    ``profile.simulation_diverged`` (the profile stands either way)."""
    try:
        profile.simulation = simulate_with_disturbance(profile, data)
    except SimulationDivergedError as e:
        profile.simulation_diverged = str(e)


def _checked_axes(axes, params: ModelParams) -> tuple[tuple, list[int]]:
    """``axes`` as a tuple and their rows (0 roll, 1 pitch, 2 yaw); :class:`DisturbanceError` for an unknown
    axis or one whose control gain is zero (u_d = ū_d / k undefined)."""
    axes = tuple(axes)
    bad = [a for a in axes if a not in AXES]
    if bad or not axes:
        raise DisturbanceError(f"axes must be a non-empty subset of {AXES}, got {axes!r}")
    gains = params.control_gains
    for a in axes:
        if gains[AXES.index(a)] == 0.0:
            raise DisturbanceError(
                f"{a}: the model's control gain {CONTROL_GAIN[AXES.index(a)]} is 0, so u_d = ū_d / k is "
                "undefined; identify the model on this axis first"
            )
    return axes, [AXES.index(a) for a in axes]


def interval_torque(data: Flight, params: ModelParams, N: int) -> np.ndarray:
    """The piecewise-constant disturbance torque ū_{d,i} of every whole interval of ``N`` samples, eq. (46).

    Every model term but the offset, with the servo-side commands (eq. 31), is
    integrated by the trapezium rule from the first sample; each interval's
    integral is a difference of that running sum.

    Parameters
    ----------
    data : Flight
        The flight as used (prefiltered when the profile is).
    params : ModelParams
        The model, held fixed.
    N : int
        Samples per interval (at least 2).

    Returns
    -------
    ndarray, shape (3, (n - 1) // N)
        ū_d per axis and interval [rad/s^2].
    """
    fs = data.sample_rate
    dt = 1.0 / fs
    n = data.n
    starts = np.arange((n - 1) // N) * N
    ends = starts + N
    sticks3 = data.sticks[list(STICK_ROW)]
    cmd = np.array([pade_filter(sticks3[i], params.taus[i], fs, params.lags[i]) for i in range(3)])
    terms = [(TERMS[name], value) for name, value in params.values().items()
             if value != 0.0 and TERMS[name].feature != "1"]
    drive = np.zeros((3, n))
    if terms:
        F = evaluate_features([t.feature for t, _ in terms], data.rates, cmd, data.sticks[2])  # (m, n)
        np.add.at(drive, [t.axis for t, _ in terms], np.array([t.sign * v for t, v in terms])[:, None] * F)
    cum = np.concatenate([np.zeros((3, 1)), np.cumsum(0.5 * (drive[:, 1:] + drive[:, :-1]), axis=1) * dt], axis=1)
    width = N * dt
    return (data.rates[:, ends] - data.rates[:, starts] - (cum[:, ends] - cum[:, starts])) / width


def _smoother_trace(wind_torque, params: ModelParams, kd: np.ndarray, rows, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The profile's trace and offsets from the smoother's wind torque (3, n) about the model's offsets
    (its mean or a posterior draw).

    Returns the wind over the control gain, zero-mean, on ``rows`` (zero elsewhere), and ``kd`` with the
    model's offset plus the wind's mean on ``rows``.
    """
    wt = np.asarray(wind_torque, dtype=float)
    if wt.shape != (3, n) or not np.all(np.isfinite(wt[rows])):
        raise DisturbanceError(f"wind_torque must be finite with shape (3, {n}) (roll, pitch, yaw by sample), "
                               f"got shape {wt.shape}")
    gains = params.control_gains
    base_kd = np.array([params.get(name) for name in OFFSET])
    kd = kd.copy()
    trace = np.zeros((3, n))
    for i in rows:
        kd[i] = base_kd[i] + wt[i].mean()
        trace[i] = (wt[i] - wt[i].mean()) / gains[i]
    return trace, kd


def _axis_statistics(ud, ud_raw, stick, passes: int, auto: int) -> dict:
    """One axis' entry of :attr:`DisturbanceProfile.statistics`: u_d against the recorded stick (Section 3.3)."""
    ks = stats.ks_2samp(ud, stick - stick.mean())
    return {
        "passes": int(passes),
        "auto_passes": int(auto),
        "ud_mean": float(ud.mean()),
        "ud_std": float(ud.std()),
        "ud_interval90": interval90(ud),
        "ud_raw_std": float(ud_raw.std()),
        "stick_mean": float(stick.mean()),
        "stick_std": float(stick.std()),
        "stick_interval90": interval90(stick),
        "stick_centred_interval90": interval90(stick - stick.mean()),
        "ks_statistic": float(ks.statistic),
        "ks_pvalue": float(ks.pvalue),
    }


def _smoother_statistics(smoother_ud, eq46_ud, trace_source: str = "smoother") -> dict:
    """What one axis' statistics add when the trace is the smoother's (or a draw from its posterior): the
    smoother mean's spread and its agreement with the eq. (46) profile held at the samples."""
    return {
        "trace_source": trace_source,
        "smoother_ud_std": float(smoother_ud.std()),
        "smoother_ud_interval90": interval90(smoother_ud),
        "smoother_vs_eq46_correlation": float(np.corrcoef(smoother_ud, eq46_ud)[0, 1]),
    }


def simulate_with_disturbance(profile: DisturbanceProfile, flight: Flight) -> ValidationResult:
    """Simulate the model without and with the identified disturbance (Section 3.4).

    Parameters
    ----------
    profile : DisturbanceProfile
    flight : Flight
        The flight the profile was identified on, as it was used (prefiltered
        when the profile was): its sticks drive the model, its rates and
        attitude are the measurements.

    Returns
    -------
    ValidationResult
        Labels :data:`MODEL_LABELS`: the model as identified, and the model with
        the offsets of eq. (47) and the torque ``k*u_d`` held over each sample.
    """
    if flight.n != profile.time.size:
        raise DisturbanceError(f"flight has {flight.n} samples, the profile {profile.time.size}")
    models = {MODEL_LABELS[0]: profile.params, MODEL_LABELS[1]: profile.simulation_params()}
    return validate_models(flight, models, torque={MODEL_LABELS[1]: profile.torque_trace})
