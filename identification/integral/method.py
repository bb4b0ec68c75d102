"""Integral-based parameter identification (Section 2.5.2, Fig. 5).

For each axis, e.g. roll (eq. 18), the data are partitioned into intervals
``[T_{i-1}, T_i)`` of equal length; within each interval the model is integrated
from the measured initial value (eq. 34)::

    p(t) - p(T_{i-1}) = sum_j k_j * s_j * int_{T_{i-1}}^t f_j dt            (32)-(33)

with the features ``f_j`` of :mod:`heli_core.terms` (``q*r``, ``u_lat``,
``p``, ``q``, ``1``), integrated by the trapezium rule (eq. 36). Stacking every
sample of every interval gives the linear least-squares problem of eq. (35),
solved for X = [k1, k2, k3, k4, kd1] (eq. 38). The solution defines the
per-interval approximation ``p_approx`` (eqs. 39-40), which replaces the
measured rate inside the integrals of the next iteration; iterations stop when
the least-squares error between ``p_approx`` and the data changes by less than
``tol`` (relative). Everything is vectorised over samples and intervals: the
sums within intervals are in :mod:`identification.integral.intervals`, one
axis' problem and its iteration in :mod:`identification.integral.axis`.

Wind and the pilot. Pilots fight gusts, so the stick is correlated with the
unmeasured wind torque, and an ordinary fit with a single constant offset kd
biases the damping and gain. The paper's own disturbance model (eqs. 41-43)
is piecewise constant; ``offsets="per_interval"`` (the default) fits it
*jointly*: each interval gets its own offset ``ū_{d,i}`` (eliminated exactly by
projecting the regressors on the within-interval time ramp), so the intrinsic
parameters are identified only from what happens *within* an interval, where
the wind has had little time to change. ``kd`` is then the mean of the
per-interval offsets (eq. 42 with zero-mean u_d). ``offsets="global"`` is the
plain single-offset fit of eq. (35). The bias of both on synthetic flights is
measured in ``scripts/identification_bias.py`` and reported in the README.

Servo delay (eq. 31). With ``delay="auto"`` the delay of each axis is chosen on
a grid as the one whose Padé-delayed command best explains the response (the
highest coefficient of determination of the integral fit, i.e. the best
correlation between the command-driven prediction and the measured rate); the
command is then passed through the first-order Padé filter
(:func:`heli_core.servo.servo_coefficients`, equal to ``control.pade(tau, 1)``).
"""

from __future__ import annotations

import time as _time

import numpy as np

from heli_core.params import ModelParams
from heli_core.servo import pade_filter, per_axis  # (pade_filter lived here before heli_core: still importable)
from heli_core.terms import AXES, COUPLED, DECOUPLED, EXTRA_PARAMS, STICK_ROW, TERMS

from ..errors import IdentifiabilityError, NotFittedError
from ..excitation import require_moving_sticks
from ..flight import Flight
from ..preprocess import DEFAULT_PASS_HZ, DEFAULT_STOP_HZ, lowpass_flight, without_folded_lines
from .axis import AxisFit, IntegralAxisSystem, IntervalSignals
from .intervals import pool_intervals, split_intervals

MIN_ROWS_PER_PARAM = 20
"""Fewest samples (over all intervals) per parameter fitted."""


class IntegralIdentifier:
    """Identify the attitude model with the integral method of Fig. 5.

    Parameters
    ----------
    structure : {"decoupled", "coupled"} or dict
        Which parameters to fit: the decoupled models of Section 3.2, the
        coupled model of eqs. (18)-(24), or a dict ``{axis_index: (names...)}``.
    extra_terms : sequence of str
        Catalogue terms (:data:`heli_core.terms.EXTRA_PARAMS`) fitted in
        addition, e.g. ``("nld1",)``.
    interval : float
        Length of the intervals ``T_i - T_{i-1}`` [s].
    offsets : {"per_interval", "global"}
        Joint piecewise-constant disturbance offsets (default) or one constant
        offset kd per axis (eq. 35 as written).
    disturbance_order : int
        With ``offsets="per_interval"``: degree of the polynomial in time that
        models the disturbance torque within one interval (0 is the paper's
        piecewise-constant ū_d of eq. 43; 1 and 2 follow a smoothly varying gust
        through the interval).
    input_hold : {"linear", "zoh"}
        How inputs behave between samples: "linear" integrates them with the
        trapezium rule (eq. 36; right for a pilot's continuously moving sticks),
        "zoh" with the left rectangle (exact for commands a digital controller
        holds over each sample, as in the environment).
    prefilter : bool
        Zero-phase FIR low-pass, pass 4 Hz / stop 8 Hz, on rates and sticks (Section 3.1).
    remove_folded : bool or None
        First take out of the gyro the vibration lines a slow log folded below 8 Hz (or up to half its rate),
        which no low-pass can remove (:func:`identification.vibration.remove_folded_lines`). None (default): with
        the prefilter, as part of preparing a raw flight (``prefilter=False`` says the flight comes prepared).
        The bench's 27 Hz line logged at 25 Hz folds to 2 Hz and put the dampings 31-35 % RMS off; on a log
        with no such line nothing is removed.
    pass_hz, stop_hz : float
        Filter band edges [Hz].
    delay : None, float, sequence of 3 float, or "auto"
        Servo delay per axis [s]; "auto" searches ``delay_grid``.
    delay_grid : sequence of float
        Candidate delays for ``delay="auto"`` [s] (default 0 to 0.5 s in 10 ms).
    max_iter : int
        Iterations of eqs. (39)-(40).
    tol : float
        Relative change of the least-squares error that stops the iteration.
    axes : sequence of str
        Axes to identify.

    Attributes
    ----------
    params_ : ModelParams
        Identified model (axes not identified stay 0).
    axes_ : dict of str to AxisFit
    fit_time_ : float
        Wall time of ``fit`` [s].
    flights_ : list of Flight
        The (filtered) flights the model was fitted on.
    vibration_lines_ : list of list of dict
        Per flight, the folded lines removed from its gyro (``axis``, ``frequency_hz``, ``amplitude``,
        ``folded``).
    """

    def __init__(self, structure="decoupled", extra_terms=(), interval: float = 1.0, offsets: str = "per_interval",
                 prefilter: bool = True, pass_hz: float = DEFAULT_PASS_HZ, stop_hz: float = DEFAULT_STOP_HZ,
                 disturbance_order: int = 2, input_hold: str = "linear", delay=None, delay_grid=None,
                 max_iter: int = 20, tol: float = 1e-3, axes=AXES, remove_folded: bool | None = None):
        self.structure = structure
        self.extra_terms = extra_terms
        self.interval = interval
        self.offsets = offsets
        self.prefilter = prefilter
        self.pass_hz = pass_hz
        self.stop_hz = stop_hz
        self.disturbance_order = disturbance_order
        self.input_hold = input_hold
        self.delay = delay
        self.delay_grid = delay_grid
        self.max_iter = max_iter
        self.tol = tol
        self.axes = axes
        self.remove_folded = remove_folded

    # ----------------------------------------------------------------- set-up
    def _param_names(self) -> dict[int, tuple[str, ...]]:
        if isinstance(self.structure, dict):
            base = {int(k): tuple(v) for k, v in self.structure.items()}
        elif self.structure == "decoupled":
            base = dict(DECOUPLED)
        elif self.structure == "coupled":
            base = dict(COUPLED)
        else:
            raise ValueError(f"structure must be 'decoupled', 'coupled' or a dict, got {self.structure!r}")
        for name in self.extra_terms:
            if name not in EXTRA_PARAMS:
                raise ValueError(f"unknown extra term {name!r}; known: {', '.join(EXTRA_PARAMS)}")
            axis = TERMS[name].axis
            base[axis] = tuple(base.get(axis, ())) + (name,)
        for axis, names in base.items():
            for name in names:
                if name not in TERMS or TERMS[name].axis != axis:
                    raise ValueError(f"parameter {name!r} does not act on axis {axis}")
        return base

    def _delays(self) -> list:
        return per_axis("delay", self.delay, 2.0)  # the delays ModelParams accepts

    # ------------------------------------------------------------------- fit
    def fit(self, flight) -> "IntegralIdentifier":
        """Identify the parameters of every requested axis.

        Parameters
        ----------
        flight : Flight or sequence of Flight
            One flight, or several flights of the same sample rate: their
            intervals are pooled into one least-squares problem (eq. 35), which
            is possible because every interval restarts from measured data (eq. 34).

        Raises
        ------
        IdentifiabilityError
            A flight is too short for the intervals, the flights' sample rates
            differ, or an axis is not excited (the normalised least-squares
            problem is ill-conditioned; its condition number is reported).
        """
        t0 = _time.perf_counter()
        self._check_settings()
        flights = [flight] if isinstance(flight, Flight) else list(flight)
        if not flights:
            raise ValueError("fit needs at least one flight")
        require_moving_sticks(flights, self.axes)
        names = self._param_names()
        delays = self._delays()
        prepared = [self._prepared(f) for f in flights]
        self.vibration_lines_ = [found for _, found in prepared]
        datas = [f for f, _ in prepared]
        intervals = _PooledIntervals(datas, self.interval)
        fits = {}
        values = {}
        for axis_name in self.axes:
            a = AXES.index(axis_name)
            axis_params = names.get(a, ())
            if not axis_params:
                continue
            if len(axis_params) * MIN_ROWS_PER_PARAM > intervals.n_samples:
                raise IdentifiabilityError(
                    f"{axis_name}: {intervals.n_samples} samples for {len(axis_params)} parameters; need at least "
                    f"{len(axis_params) * MIN_ROWS_PER_PARAM}"
                )
            tau = self._axis_delay(a, axis_params, delays[a], intervals)
            fit = self._fit_axis(a, axis_params, intervals.signals(a, tau), max_iter=self.max_iter, check=True)
            fit = AxisFit(**{**fit.__dict__, "delay": tau})
            fits[axis_name] = fit
            values.update(fit.params)
            values[f"tau_{axis_name}"] = tau
        self.axes_ = fits
        self.params_ = ModelParams().with_values(**values)
        self.flights_ = datas
        self.fit_time_ = _time.perf_counter() - t0
        return self

    def prepared(self, flight: Flight) -> Flight:
        """``flight`` as this identifier fits it (Section 3.1): the folded lines' sensor share taken out of its
        gyro (``remove_folded``), then the zero-phase prefilter (``prefilter``)."""
        return self._prepared(flight)[0]

    def _prepared(self, flight: Flight) -> tuple[Flight, list]:
        """:meth:`prepared` and the folded lines removed from it."""
        found = []
        if self.prefilter if self.remove_folded is None else self.remove_folded:
            flight, found = without_folded_lines(flight)
        return (lowpass_flight(flight, self.pass_hz, self.stop_hz) if self.prefilter else flight), found

    def _check_settings(self):
        if self.offsets not in ("per_interval", "global"):
            raise ValueError(f"offsets must be 'per_interval' or 'global', got {self.offsets!r}")
        if self.input_hold not in ("linear", "zoh"):
            raise ValueError(f"input_hold must be 'linear' or 'zoh', got {self.input_hold!r}")
        if int(self.disturbance_order) != self.disturbance_order or not 0 <= self.disturbance_order <= 3:
            raise ValueError(f"disturbance_order must be an integer 0..3, got {self.disturbance_order!r}")

    def _axis_delay(self, a: int, axis_params, delay, intervals: "_PooledIntervals") -> float:
        """The servo delay of axis ``a`` [s]: ``delay`` as given, or with ``"auto"`` the candidate of
        ``delay_grid`` whose Padé-delayed command best explains the response (highest R² of one iteration)."""
        if delay != "auto":
            return float(delay)
        candidates = self.delay_grid if self.delay_grid is not None else np.arange(0.0, 0.501, 0.01)
        scores = [self._fit_axis(a, axis_params, intervals.signals(a, tau), max_iter=1, check=False).r2
                  for tau in candidates]
        return float(candidates[int(np.argmax(scores))])

    def _fit_axis(self, a, axis_params, signals: IntervalSignals, max_iter: int, check: bool) -> AxisFit:
        """Eqs. (32)-(40) for one axis (:class:`~identification.integral.axis.IntegralAxisSystem`)."""
        system = IntegralAxisSystem(a, axis_params, signals, self.offsets == "per_interval", self.disturbance_order,
                                    self.input_hold == "zoh")
        return system.fit(max_iter, self.tol, check)

    # ----------------------------------------------------------------- use
    def _check_fitted(self):
        if not hasattr(self, "params_"):
            raise NotFittedError("this IntegralIdentifier is not fitted yet; call fit(flight) first")

    def predict(self, flight: Flight) -> np.ndarray:
        """Forward-simulate the identified model with the flight's sticks; rates (3, n) [rad/s]."""
        self._check_fitted()
        from heli_core.physics import forward_rates

        return forward_rates(self.params_, flight)

    def summary(self) -> dict:
        """JSON-ready fit statistics per axis."""
        self._check_fitted()
        return {
            name: {
                "params": f.params, "std_errors": f.std_errors, "delay_s": f.delay,
                "condition_number": f.condition, "r2": f.r2, "iterations": len(f.history),
                "lsq_error_history": list(f.history),
            }
            for name, f in self.axes_.items()
        }


class _PooledIntervals:
    """The intervals of every flight laid out as one set (eq. 34 restarts each from measured data).

    Parameters
    ----------
    datas : sequence of Flight
        The (filtered) flights, of one sample rate.
    interval : float
        Length of the intervals [s].

    Raises
    ------
    IdentifiabilityError
        Flights of different sample rates, an interval under two samples, or fewer than two intervals.
    """

    def __init__(self, datas, interval: float):
        fs = datas[0].sample_rate
        for d in datas[1:]:
            if abs(d.sample_rate - fs) > 1e-3 * fs:
                raise IdentifiabilityError(
                    f"flights must share one sample rate to be pooled; got {fs:.3f} Hz and {d.sample_rate:.3f} Hz"
                )
        N = int(round(interval * fs))
        if N < 2:
            raise IdentifiabilityError(f"interval {interval} s holds {N} samples at {fs:.1f} Hz; need at least 2")
        counts = [(d.n - 1) // N for d in datas]
        n_int = sum(counts)
        if n_int < 2:
            raise IdentifiabilityError(
                f"flight of {sum(d.duration for d in datas):.2f} s holds {n_int} interval(s) of {interval} s; "
                "need at least 2 (use a longer flight or shorter intervals)"
            )
        self.datas, self.fs, self.N, self.counts = datas, fs, N, counts
        self.n_samples = n_int * N
        # Every signal as (samples 1..N of each interval (n_int, N), first sample of each interval (n_int,)).
        self.rates = self.split(lambda d: d.rates)
        self.col = self.split(lambda d: d.sticks[2])
        self.sticks = [self.split(lambda d, i=i: d.sticks[i]) for i in STICK_ROW]
        self.start_times = np.concatenate([d.time[: m * N : N] for d, m in zip(datas, counts)])

    def split(self, signal) -> tuple:
        """``signal(flight)`` of every flight as ``(inner, first)`` over all the intervals."""
        return pool_intervals([split_intervals(signal(d), m, self.N) for d, m in zip(self.datas, self.counts)])

    def signals(self, a: int, tau: float) -> IntervalSignals:
        """The signals of axis ``a``'s fit, its command through the Padé servo delay ``tau`` (eq. 31)."""
        cmd = list(self.sticks)
        if tau > 0:
            i = STICK_ROW[a]
            cmd[a] = self.split(lambda d: pade_filter(d.sticks[i], tau, self.fs))
        return IntervalSignals(self.rates, ([c[0] for c in cmd], [c[1] for c in cmd]), self.col, 1.0 / self.fs,
                               self.start_times)
