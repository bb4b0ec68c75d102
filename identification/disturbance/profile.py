"""The identified wind of one flight as data: :class:`DisturbanceProfile` (eqs. 41-47) and its comparison
with a known wind.

:func:`identification.disturbance.equivalent_input.identify_disturbance` builds a profile; the report's
section and Figs. 19-21 are drawn from it by :mod:`identification.reports.disturbance`, and the disturbance
library stores it (:meth:`DisturbanceProfile.to_trace`). A profile imports neither.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from heli_core.files import jsonable
from heli_core.params import ModelParams
from heli_core.terms import AXES

from ..validation.result import ValidationResult
from .smoothing import SMOOTHING_WINDOW

OFFSET = ("kd1", "kd2", "kd3")
"""Constant torque offset of each axis (eqs. 18, 21, 42)."""

MODEL_LABELS = ("no disturbance", "identified disturbance")
"""Labels of the two simulations in :attr:`DisturbanceProfile.simulation`."""


@dataclass(eq=False)
class DisturbanceProfile:
    """An identified wind-disturbance profile of one flight (eqs. 41-47).

    Built by :func:`~identification.disturbance.equivalent_input.identify_disturbance`. Arrays are ordered
    roll, pitch, yaw; rows of axes that were not identified are zero.

    Attributes
    ----------
    axes : tuple of str
        Axes identified.
    interval : float
        Δt actually used, ``samples_per_interval / sample_rate`` [s].
    samples_per_interval : int
        Samples per interval N (at least 2).
    sample_rate : float
        Flight sample rate [Hz].
    time : ndarray, shape (n,)
        Flight sample times [s].
    interval_starts : ndarray, shape (n_intervals,)
        Start time ``t_{i-1}`` of each interval [s].
    torque : ndarray, shape (3, n_intervals)
        Identified piecewise-constant torque ū_{d,i} of eq. (46) [rad/s^2].
    kd : ndarray, shape (3,)
        Offsets ``mean(ū_d)`` of eq. (47) [rad/s^2].
    control_gains : ndarray, shape (3,)
        k2, k6, k10 of the model [rad/s^2 per unit stick].
    ud_raw : ndarray, shape (3, n_intervals)
        Zero-mean equivalent input ``(ū_d - kd)/k`` before smoothing [stick units].
    ud : ndarray, shape (3, n_intervals)
        The same after smoothing, zero-mean [stick units].
    trace : ndarray, shape (3, n)
        ``ud`` held over each interval at the flight's samples (eq. 43) [stick units].
    collective : ndarray, shape (n,)
        Collective stick the yaw disturbance was identified with (after the
        prefilter when ``prefilter`` was on) [-1, 1].
    sticks : ndarray, shape (3, n)
        The pilot's recorded lat, lon, ped sticks (for the distribution match).
    passes : tuple of int
        Smoothing passes per axis (0 for axes not identified).
    smoothing : str or int
        ``"auto"`` or the fixed number of passes requested.
    smoothing_cost : ndarray, shape (3, MAX_PASSES + 1)
        Integrated squared difference between the fitted normals of u_d and of
        the stick for 0 .. MAX_PASSES passes (the paper's rule, evaluated
        whichever smoothing was used; NaN for axes not identified).
    statistics : dict
        Per identified axis: ``passes`` (used), ``auto_passes`` (the paper's
        rule), ``ud_mean``, ``ud_std``, ``ud_raw_std``, ``ud_interval90``,
        ``stick_mean``, ``stick_std``, ``stick_interval90`` (of the recorded
        stick), ``stick_centred_interval90``, ``ks_statistic``, ``ks_pvalue``.
    params : ModelParams
        The model the profile was identified with.
    prefilter : dict or None
        Prefilter settings, or None when the flight was used as recorded.
    source : dict
        ``name`` of the flight, its ``sha256`` and what was hashed
        (``sha256_of``: "file" for a logged flight, "arrays" otherwise).
    simulation : ValidationResult or None
        The model simulated without and with the identified disturbance
        (Section 3.4), labels :data:`MODEL_LABELS`; None when not simulated or
        when the simulation diverged.
    simulation_diverged : str or None
        Why the simulation was dropped, when the model diverged (the message of
        :class:`~identification.errors.SimulationDivergedError`).
    trace_source : {"eq46", "smoother", "posterior draw"}
        What ``trace`` and ``kd`` hold: the smoothed eq. (46) profile; the wind
        torque the maximum-likelihood model's Rauch-Tung-Striebel smoother
        estimated at every sample (its conditional mean,
        :meth:`identification.likelihood.estimator.MaximumLikelihoodIdentifier.wind_torque`);
        or a draw from that smoother's posterior (:mod:`identification.disturbance.wind_posterior`),
        over the control gain. The eq. (46) quantities (``torque``, ``ud_raw``,
        ``ud``) are kept either way, for the paper's comparison.
    trace_mean : ndarray, shape (3, n), or None
        With a posterior draw in ``trace``: the smoother's conditional mean over the
        control gain, zero-mean [stick units]: the best estimate of the wind that blew,
        for plots, the comparison with a known wind and the diagnosis. None otherwise.
    trace_draw : dict or None
        With a posterior draw in ``trace``: how it was drawn (``method``, ``seed``,
        ``draw``, ``n_draws``; :meth:`identification.disturbance.wind_posterior.WindPosterior.describe`).
    """

    axes: tuple
    interval: float
    samples_per_interval: int
    sample_rate: float
    time: np.ndarray
    interval_starts: np.ndarray
    torque: np.ndarray
    kd: np.ndarray
    control_gains: np.ndarray
    ud_raw: np.ndarray
    ud: np.ndarray
    trace: np.ndarray
    collective: np.ndarray
    sticks: np.ndarray
    passes: tuple
    smoothing: object
    smoothing_cost: np.ndarray
    statistics: dict
    params: ModelParams
    prefilter: dict | None
    source: dict
    simulation: ValidationResult | None = field(default=None)
    trace_source: str = "eq46"
    simulation_diverged: str | None = None
    trace_mean: np.ndarray | None = None
    trace_draw: dict | None = None

    @property
    def estimate(self) -> np.ndarray:
        """The best estimate of the wind u_d that blew, shape (3, n) [stick units]: the smoother's mean when
        ``trace`` is a posterior draw, else ``trace`` itself."""
        return self.trace if self.trace_mean is None else self.trace_mean

    @property
    def n_intervals(self) -> int:
        """Number of whole intervals of length Δt."""
        return int(self.torque.shape[1])

    @property
    def torque_trace(self) -> np.ndarray:
        """Disturbance torque ``k*u_d`` at the flight's samples, shape (3, n) [rad/s^2]."""
        return self.control_gains[:, None] * self.trace

    @property
    def smoothing_window(self) -> int:
        """Samples per pass of the smoother of eq. (46)
        (:data:`~identification.disturbance.smoothing.SMOOTHING_WINDOW`)."""
        return SMOOTHING_WINDOW

    def to_trace(self, **metadata):
        """This profile as a :class:`model_store.Trace` of the disturbance library (``metadata`` recorded
        under the entry's ``metadata``)."""
        from model_store.disturbance_library import Trace

        return Trace.from_profile(self, **metadata)

    def simulation_params(self) -> ModelParams:
        """The model with the offsets of eq. (47) in place of its own (Section 3.4)."""
        return self.params.with_values(**{OFFSET[AXES.index(a)]: float(self.kd[AXES.index(a)]) for a in self.axes})

    def to_dict(self) -> dict:
        """JSON-ready summary: settings, offsets, statistics, simulation errors (no histories)."""
        out = {
            "axes": list(self.axes),
            "interval_s": self.interval,
            "samples_per_interval": self.samples_per_interval,
            "n_intervals": self.n_intervals,
            "sample_rate_hz": self.sample_rate,
            "n_samples": int(self.time.size),
            "smoothing": {"mode": "auto" if self.smoothing == "auto" else "fixed",
                          "window": SMOOTHING_WINDOW,
                          "passes": {a: int(self.passes[AXES.index(a)]) for a in self.axes}},
            "kd": {a: float(self.kd[AXES.index(a)]) for a in self.axes},
            "model_kd": {a: self.params.get(OFFSET[AXES.index(a)]) for a in self.axes},
            "control_gains": {a: float(self.control_gains[AXES.index(a)]) for a in self.axes},
            "statistics": self.statistics,
            "prefilter": self.prefilter,
            "source": self.source,
            "simulation": None,
            "simulation_diverged": self.simulation_diverged,
        }
        if self.simulation is not None:
            sim = self.simulation.to_dict()
            out["simulation"] = {"rate_stats": sim["rate_stats"], "attitude_stats": sim["attitude_stats"]}
        return jsonable(out)


def interval90(x) -> list[float]:
    """The 5th and 95th percentiles of ``x``: its central 90 % interval."""
    lo, hi = np.percentile(x, [5.0, 95.0])
    return [float(lo), float(hi)]


def compare_with_truth(profile: DisturbanceProfile, true_ud) -> dict[str, dict[str, float]]:
    """How well the identified u_d matches a known wind (synthetic flights).

    The identified u_d is the profile's best estimate (:attr:`DisturbanceProfile.estimate`): the
    smoother's mean when the stored trace is a posterior draw, whose own departures from the mean are
    the posterior's spread, not estimation error.

    Parameters
    ----------
    profile : DisturbanceProfile
    true_ud : array_like, shape (3, n)
        True equivalent input u_d per axis at the flight's samples, e.g.
        :attr:`identification.bench.synthetic.SyntheticFlight.wind` [stick units].

    Returns
    -------
    dict
        Per identified axis: ``correlation`` (Pearson, of the sample-rate
        traces), ``rms_error`` and ``rms_truth`` (RMS of the zero-mean true
        input) [stick units].
    """
    true_ud = np.asarray(true_ud, dtype=float)
    estimate = profile.estimate
    if true_ud.shape != estimate.shape:
        raise ValueError(f"true_ud must have shape {estimate.shape} (roll, pitch, yaw by sample), got {true_ud.shape}")
    out = {}
    for a in profile.axes:
        i = AXES.index(a)
        t = true_ud[i] - true_ud[i].mean()
        e = estimate[i]
        out[a] = {
            "correlation": float(np.corrcoef(e, t)[0, 1]),
            "rms_error": float(np.sqrt(np.mean((e - t) ** 2))),
            "rms_truth": float(np.sqrt(np.mean(t * t))),
        }
    return out
