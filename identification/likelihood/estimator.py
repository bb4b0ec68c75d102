"""Maximum-likelihood identification with a stochastic wind state (filter-error method).

The integral method of Fig. 5 (:mod:`identification.integral.method`) treats the
wind as piecewise-smooth offsets and is biased when a pilot fights broadband
turbulence: the stick is correlated with the part of the gust the offsets
cannot follow. This estimator models the gust instead. Per axis, e.g. roll
(eq. 18 with the wind of eqs. 41-42 as a random process)::

    p'  = -k3 p + k2 c_lat + sum_j s_j theta_j f_j + kd1 + w_slow + w_fast
    w_i' = -w_i / T_i + nu_i,         E[w_i^2] = sigma_i^2   (first-order Gauss-Markov)
    y_k = p(t_k) + v_k,               E[v_k^2] = R           (white gyro noise)

``c_lat`` is the command after the servo delay (the Padé model of eq. 31),
``f_j`` the other features of the axis' terms (:mod:`heli_core.terms`;
rates of the other axes enter as measured, causally, never filtered), and the
damping term (the feature equal to the axis' own rate) sits in the state
matrix. The model is discretised exactly (matrix exponential; the inputs
either linearly interpolated between samples, a pilot's hand, or held, a
digital controller; the process noise by Van Loan's method), the steady-state
Kalman filter (discrete algebraic Riccati equation) gives the one-step
prediction errors (innovations), and the likelihood, with the noise scale
concentrated out, is minimised over the damping and the wind model
(``scipy.optimize.least_squares``) while the parameters that enter linearly
(control gain, offsets, couplings, added terms) are solved exactly at every
step (variable projection, :mod:`identification.likelihood.axis_likelihood`). The
innovations are computed by linear filters (``scipy.signal.lfilter``), never by
a Python loop over samples.

The result is consistent under closed-loop piloting: the pilot's stick may
depend on past gusts, because the filter predicts the gust from the past
rates, and what is left is white. Standard errors come from the Fisher
information of the innovations (Gauss-Newton approximation). The servo delay is
chosen by profiling the likelihood over a grid of delays. The Rauch-Tung-Striebel
smoother of the fitted model estimates the wind torque at every sample
(:meth:`MaximumLikelihoodIdentifier.wind_torque`), the disturbance the library
stores and the environment replays.

Several flights share the aircraft's parameters; each flight keeps its own
offset ``kd`` (the trim and the day's mean wind) and its own filter start.

How the sticks move between samples is a coordinate of the search too (a hold
fraction, :mod:`identification.likelihood.input_hold`), decided once for the log from every
axis' estimate; with ``delay="auto"`` a negative alignment is a log whose input
column lags, applied as a shift of the stick by whole samples
(:attr:`MaximumLikelihoodIdentifier.input_shifts_`).

The search of one axis' likelihood (its data at a delay, the gust models tried, the optimum's standard
errors and wind levels) is :class:`~identification.likelihood.axis_search.AxisProblem`, one object of what
every search of the axis shares; this module holds the estimator's decisions over it: the delay profiled, the
log's hold, its shifts, the terms the data cannot carry. Its result type is
:mod:`identification.likelihood.axis_fit`, the likelihood :mod:`identification.likelihood.axis_likelihood`.
"""

from __future__ import annotations

import time as _time
from dataclasses import replace
from functools import partial

import numpy as np
from threadpoolctl import threadpool_limits

from heli_core.params import ModelParams
from heli_core.servo import per_axis
from heli_core.terms import AXES, DECOUPLED, STICK_ROW, TERMS

from ..errors import IdentifiabilityError, NotFittedError
from ..excitation import on_static_input, require_moving_sticks, static_collective
from ..flight import Flight
from ..integral.method import IntegralIdentifier
from ..preprocess import shift_inputs
from ..validation.fit_warnings import log_ticks, loop_ticks
from ..vibration import remove_common_lines
from .axis_fit import MLAxisFit, model_values
from .axis_likelihood import MIN_SERVO_DELAY, AxisData, AxisLikelihood
from .axis_pool import check_workers, map_axes
from .axis_search import BURN_IN, DAMPING_BOUNDS, MAX_SHIFT, AxisProblem, WindFit
from .closed_loop import N_FLIGHTS, ClosedLoopCheck, apply_check
from .closed_loop import check_settings as check_closed_loop_settings
from .input_hold import (HOLDS, check_hold, decide_hold, hold_alternative, std_errors_with_hold,
                         undecided_against)
from .loop_checks import run_checks
from .servo_lag import profile_lag
from .state_space import HOLD_INDEX, WIND_MODELS, concentrated_nll, rts_smooth, wind_block

DEFAULT_DELAY_GRID = np.round(np.arange(-MAX_SHIFT, 0.5001, 0.01), 4)
"""Alignments profiled by ``delay="auto"`` [s]; from the best, the alignment is searched jointly with the rest.
A positive one is the servo delay (Padé, eq. 31), a negative one a log whose input column lags the response
(:attr:`MaximumLikelihoodIdentifier.input_shifts_`)."""

MIN_PROFILE_DAMPING = 0.05
"""A damping [1/s] below which the undelayed fit is not held for the alignment profile of ``delay="auto"``."""

NOMINAL_DAMPING = 1.0
"""The damping [1/s] the alignment profile holds instead (a 1 s time constant, the order of a small
helicopter's rate response) when the undelayed fit's is not positive and the integral method's start is not."""

MIN_LR_DELAY = 20.0
"""Smallest likelihood-ratio statistic ``2 (NLL_undelayed - NLL_aligned)`` at which ``delay="auto"`` keeps the
alignment it searched (else the undelayed fit). Timing is where a model is misspecified in small ways the
chi-square law does not know (a hold between samples, a digital controller's sample of lag): on effect-free
bench flights this search scored 0-4 and the diagnosis' alignment candidate up to 12.2; a servo delay of one
sample (10 ms) scored 46-370 on 300 s flights (docs/method.md). The likelihood diagnosis' alignment floor is the same number
(:data:`identification.diagnosis.likelihood_diagnoser.MIN_LR_ALIGNMENT`)."""

DETECT_NFEV = 3
"""Likelihood evaluations (iterations) of ``delay="detect"``'s search of a delay from the undelayed fit: it
only has to tell whether the data support one (the full profile then places it). Three reach 96-100 % of the
converged search's likelihood ratio on flights with a one-sample servo delay (LR 58-356) and cost 0.02-0.09 s
an axis; effect-free axes score 0-4."""

CLI_TIMING = {"delay": "detect", "servo_lag": "detect"}
"""The timing settings ``heli identify`` fits with by default (this class' own default is ``delay=None``,
``servo_lag=None``): the studies that judge "the defaults" fit with these, so that they judge what a user gets."""

SUPPORT_Z = 3.0
"""With ``select_terms``: a term beyond the decoupled model is kept when ``|value| >= SUPPORT_Z * se``
(two-sided 0.3 % level, about Bonferroni 1 % over the coupled model's five extra terms)."""


class MaximumLikelihoodIdentifier:
    """Identify the attitude model by maximum likelihood with a stochastic wind state.

    Scikit-learn style: the constructor stores the settings, :meth:`fit`
    returns ``self`` and sets the attributes ending in ``_``.

    Parameters
    ----------
    structure : {"decoupled", "coupled"} or dict
        Parameters to fit, as for :class:`~identification.integral.method.IntegralIdentifier`.
    extra_terms : sequence of str
        Catalogue terms fitted in addition (:data:`heli_core.terms.EXTRA_PARAMS`).
    input_hold : "auto", "linear", "zoh" or float in [0, 1]
        How the sticks move between samples: ``u(t) = u_k + a (u_{k+1} - u_k) (t - t_k)/dt`` with ``a`` the
        hold fraction, 1 (``"linear"``) a pilot's hand sampled, 0 (``"zoh"``) a command held over its sample
        (a digital radio link, a flight controller). ``"auto"`` (default) estimates ``a`` per axis with every
        other parameter, as MATLAB's ``greyest`` would with a free ``InterSample``: a log rarely says which,
        and assuming the wrong one biases the damping by 15-19 % (docs/method.md).
    delay : None, float, sequence of 3 float, "auto" or "detect"
        Servo delay per axis [s] (Padé, eq. 31); "auto" profiles the likelihood
        over ``delay_grid`` (damping and wind held at the undelayed fit), then searches the delay jointly
        with every other parameter from the best, and keeps it where the likelihood ratio against no delay
        reaches :data:`MIN_LR_DELAY`; its standard error is reported as ``tau_<axis>``. A
        negative alignment found by "auto" is no servo delay but a log whose input column lags the
        response: the axis' stick is advanced by it (:attr:`input_shifts_`) and the model's delay is 0.
        "detect" (``heli identify``'s default) fits without a delay, searches the alignment a few steps from
        there, and profiles as "auto" only the axes where that finds one the data support: an unmodelled
        servo delay of 10 ms biased the dampings by 8-35 % (RMS per bench cell), of 80 ms by 76-135 %
        (docs/method.md), and testing for one costs a short search per axis.
    delay_grid : sequence of float, optional
        Candidate alignments for ``delay="auto"`` [s] (default -0.6 to 0.5 s in 10 ms).
    wind_model : {"auto", "gm2", "gm_so"}
        Gust model (:data:`WIND_MODELS`); "auto" fits both and keeps the one of
        higher likelihood per axis (they have the same number of parameters).
    remove_vibration : bool
        Remove narrow spectral lines above ``vibration_min_hz`` (rotor
        vibration) from the gyro by regression on their sinusoids before the fit.
    vibration_min_hz : float
        Lowest frequency treated as vibration [Hz]; below it only the lines a slow log folded there,
        told from the motion by the attitude
        (:func:`identification.vibration.remove_folded_lines`).
    axes : sequence of str
        Axes to identify.
    max_nfev : int
        Largest number of likelihood evaluations per search.
    select_terms : bool
        Keep a term beyond the decoupled model (k1, k4, k5, k8, k9, catalogue terms) only where the data
        support it: terms with ``|value| < SUPPORT_Z * se`` are dropped, weakest first, refitting each time.
    servo_lag : None, float, sequence of 3 float, "auto" or "detect"
        The servo's first-order lag per axis [s] (None: none); "auto" profiles the likelihood over
        :data:`identification.likelihood.servo_lag.LAG_GRID` (the delay searched with it when ``delay="auto"``) and
        keeps the best lag only where the data support it (:func:`identification.likelihood.servo_lag.profile_lag`).
        "detect" (``heli identify``'s default) does so only on the axes where the delay's search
        (``delay="auto"`` or ``"detect"``) found a servo delay: an unmodelled 40 ms lag left the dampings 10-14 %
        low with the delay alone (56-74 % with neither); elsewhere the fit is unchanged.
    closed_loop : None, "auto" or "report"
        The closed-loop check (:mod:`identification.likelihood.closed_loop`): ``closed_loop_flights`` flights
        of the fitted model flown under the pilot fitted to the sticks and fitted again, where that pilot sees
        the aircraft rather than the gyro; "auto" removes a gain's or damping's bias where it is significant
        (:attr:`closed_loop_`), "report" only measures it, None (default here; ``heli identify`` checks)
        skips it. A pilot who sees the aircraft behind a noisy gyro biased slow axes' dampings 7-32 % high.
    closed_loop_flights : int
        Flights flown by the check (each costs about one fit of the axis).
    workers : int or None
        Processes the axes are fitted in side by side (:mod:`identification.likelihood.axis_pool`; the result is the
        same bit for bit): None (default) the cores other work leaves idle, or ``HELI_WORKERS``; 1 one after
        another.

    Attributes
    ----------
    params_ : ModelParams
    axes_ : dict of str to MLAxisFit
    flights_ : list of Flight
        The flights as fitted (vibration lines removed, sticks advanced by :attr:`input_shifts_`).
    hold_decision_ : dict or None
        With ``input_hold="auto"``, the log's hold decided from every axis' estimate (:func:`decide_hold`):
        the axes whose estimate lay further from it than its standard error are fitted again at it.
    hold_alternative_ : dict or None
        Where the data reject neither named hold (:func:`~identification.likelihood.input_hold.undecided_against`),
        every axis fitted at the other (:func:`~identification.likelihood.input_hold.hold_alternative`: its values,
        standard errors, the likelihood ratio and weight), for the doubt it leaves on the values
        (:func:`~identification.likelihood.input_hold.std_errors_with_hold`); else None.
    input_shifts_ : dict of str to float
        Per axis, the shift applied to its stick [s]: negative where ``delay="auto"`` found the log's input
        column late (``metadata["input_shift_s"]`` of :attr:`flights_`), else 0.
    static_collective_ : float or None
        The collective's standard deviation when it does not vary (its terms not fitted), else None.
    fit_time_ : float
        Wall time of ``fit`` [s].
    vibration_lines_ : list of list of dict
        Lines removed, per flight (axis, frequency [Hz], amplitude [rad/s]).
    closed_loop_ : ClosedLoopCheck or None
        What the closed-loop check found (the values before it in its ``fitted``), or None when not run.
    """

    method = "maximum likelihood (filter error, Gauss-Markov wind)"
    damping_bounds = DAMPING_BOUNDS
    """The interval each damping is searched in [1/s] (a damping at a bound was not placed by the data)."""
    timing_gate = None
    """With ``delay="detect"``: None, or ``gate(axis, damping)``, called with an axis' damping fitted without a timing;
    where True its timing is not searched (the undelayed fit stands). The fit rate's choice sets it on its fits
    (:func:`identification.fit_rate._dampings`): a damping already inflated there needs no timing to decide."""

    def __init__(self, structure="decoupled", extra_terms=(), input_hold="auto", delay=None,
                 delay_grid=None, wind_model: str = "auto", remove_vibration: bool = True,
                 vibration_min_hz: float = 8.0, axes=AXES, max_nfev: int = 100, select_terms: bool = False,
                 servo_lag=None, closed_loop=None, closed_loop_flights: int = N_FLIGHTS, workers=None):
        self.structure = structure
        self.extra_terms = extra_terms
        self.input_hold = input_hold
        self.delay = delay
        self.delay_grid = delay_grid
        self.wind_model = wind_model
        self.remove_vibration = remove_vibration
        self.vibration_min_hz = vibration_min_hz
        self.axes = axes
        self.max_nfev = max_nfev
        self.select_terms = select_terms
        self.servo_lag = servo_lag
        self.closed_loop = closed_loop
        self.closed_loop_flights = closed_loop_flights
        self.workers = workers

    # ----------------------------------------------------------------- set-up
    def _param_names(self) -> dict[int, tuple[str, ...]]:
        return IntegralIdentifier(structure=self.structure, extra_terms=self.extra_terms)._param_names()

    def _delays(self) -> list:
        return per_axis("delay", self.delay, 2.0, ("auto", "detect"))  # the delays ModelParams accepts

    def _lags(self) -> list:
        return per_axis("servo_lag", self.servo_lag, 1.0, ("auto", "detect"))  # the lags ModelParams accepts

    def _check_settings(self):
        self._lags()  # a bad servo_lag is named before any work
        check_hold(self.input_hold)
        check_workers(self.workers)
        if self.wind_model not in ("auto",) + WIND_MODELS:
            raise ValueError(f"wind_model must be 'auto' or one of {WIND_MODELS}, got {self.wind_model!r}")
        if not (isinstance(self.max_nfev, (int, np.integer)) and self.max_nfev >= 5):
            raise ValueError(f"max_nfev must be a whole number >= 5, got {self.max_nfev!r}")
        if not self.vibration_min_hz > 0:
            raise ValueError(f"vibration_min_hz must be > 0 Hz, got {self.vibration_min_hz!r}")
        check_closed_loop_settings(self.closed_loop, self.closed_loop_flights)

    def _clean(self, flight: Flight) -> tuple[Flight, list]:
        if not self.remove_vibration:
            return flight, []
        rows = list(STICK_ROW)
        rates, commands, found = remove_common_lines(flight.rates, flight.sticks[rows], flight.sample_rate,
                                                     self.vibration_min_hz, flight.attitude,
                                                     faster_loop=loop_ticks(flight) > 1)
        sticks = flight.sticks
        if any(ln.get("signal") == "command" for ln in found):
            sticks = np.array(flight.sticks, dtype=float, copy=True)
            sticks[rows] = commands
        meta = type(flight.metadata)({**flight.metadata, "vibration_lines": found})
        return Flight(flight.time, rates, flight.attitude, sticks, meta, flight.extra), found

    # ------------------------------------------------------------------- fit
    def fit(self, flight) -> "MaximumLikelihoodIdentifier":
        """Identify every requested axis from one flight or several (shared parameters, own offsets).

        Raises
        ------
        IdentifiabilityError
            Flights of different sample rates, a flight too short, or an axis whose
            regressors are not excited.
        """
        t0 = _time.perf_counter()
        self._check_settings()
        # The likelihood works on 3x3 to 4x4 matrices and long 1-D filters: BLAS threads only cost here.
        with threadpool_limits(limits=1, user_api="blas"):
            self._fit(flight)
        self.fit_time_ = _time.perf_counter() - t0
        return self

    def _fit(self, flight):
        flights = [flight] if isinstance(flight, Flight) else list(flight)
        if not flights:
            raise ValueError("fit needs at least one flight")
        require_moving_sticks(flights, self.axes)
        fs = flights[0].sample_rate
        for f in flights[1:]:
            if abs(f.sample_rate - fs) > 1e-3 * fs:
                raise IdentifiabilityError(
                    f"flights must share one sample rate to be pooled; got {fs:.3f} Hz and {f.sample_rate:.3f} Hz")
        burn = int(round(BURN_IN * fs))
        for f in flights:
            if f.n < 4 * burn + 50:
                raise IdentifiabilityError(
                    f"flight of {f.duration:.2f} s is too short for the likelihood fit; need at least "
                    f"{(4 * burn + 50) / fs:.1f} s")
        cleaned = [self._clean(f) for f in flights]
        flights = [c[0] for c in cleaned]
        names = self._param_names()
        self.static_collective_ = static_collective(flights)
        static = {a: tuple(p for p in names[a] if on_static_input(p, self.static_collective_ is not None))
                  for a in names}
        names = {a: tuple(p for p in names[a] if p not in static[a]) for a in names}
        # The integral method (Fig. 5) on the same structure is the starting point.
        # (on the flights as cleaned above: their folded lines are out already)
        start = IntegralIdentifier(structure=names, delay=0.0, axes=self.axes, remove_folded=False).fit(flights)
        delays, lags = self._delays(), self._lags()
        controller = log_ticks(flights)  # > 1: a controller's commands, slower than its loop

        def one_axis(axis_name, delay=None):
            a = AXES.index(axis_name)
            problem = self.axis_problem(a, names[a], flights, burn)
            fit = self._fit_axis(problem, start.params_, delays[a] if delay is None else delay, lags[a])
            whole = round(fit.delay * fs) / fs
            late = fit.delay < (-MIN_SERVO_DELAY if controller > 1 else -0.5 / fs)
            if late and abs(whole - fit.delay) > 1e-9:
                # a late input column is late by whole samples of the log's clock: the fraction of a sample
                # is the hold's (the two trade against each other and the damping, 8 % on a 150 s flight), or,
                # for a controller faster than its log, its loop's inside the sample: the bench's autopilot 4x
                # faster than its 50 Hz log put roll 4 ms late, its damping 16 % high where the check measured
                # +31 % on a world without it
                fit = self._refit(problem, fit, tau=whole)
            if self.select_terms:
                fit = self._supported(problem, fit, start.params_)
            if static[a]:  # terms of an input that does not vary: not fitted, listed as dropped
                fit = replace(fit, dropped=tuple(fit.dropped) + static[a])
            return fit

        fitted = [axis for axis in self.axes if names.get(AXES.index(axis))]
        controller_hold = self._controller_hold(controller, fitted, names, flights, burn, start.params_)
        fits = dict(zip(fitted, map_axes(one_axis, fitted, self.workers)))
        detected = [a for a in fitted if delays[AXES.index(a)] == "detect"]
        if any(fits[a].delay_profile for a in detected):
            # the log's timing is shared by its channels: where one axis' timing was questioned, every axis is
            # profiled (the T-REX hover's yaw, whose pedal barely moves it, is late as its sticks are)
            rest = [a for a in detected if not fits[a].delay_profile and not self._gated(a, fits[a])]
            fits.update(zip(rest, map_axes(partial(one_axis, delay="auto"), rest, self.workers)))
        self.hold_decision_ = controller_hold or self._decide_log_hold(fits, flights, burn)
        self._decided_hold = None
        flights = self._apply_shifts(fits, flights)
        self.axes_ = fits
        self.params_ = ModelParams().with_values(**model_values(fits))
        self.flights_ = flights
        self.vibration_lines_ = [c[1] for c in cleaned]
        self.closed_loop_ = None
        if self.closed_loop is not None:
            self.closed_loop_check(self.closed_loop)

    def closed_loop_check(self, mode: str = "auto") -> ClosedLoopCheck:
        """Run the closed-loop check on the fitted model (:mod:`identification.likelihood.closed_loop`, with a
        found servo delay tested and the hold decided again in the loop's world where the loop's bias could reach
        them: :mod:`identification.likelihood.loop_checks`): in mode "auto" the significant biases are removed
        from :attr:`params_` and :attr:`axes_` (a delay the loop makes, and a hold its world rejects, too); the
        result is kept in :attr:`closed_loop_` and ``closed_loop`` records the mode (as a fit with
        ``closed_loop=mode`` does).

        Raises
        ------
        NotFittedError
            Before :meth:`fit`.
        ValueError
            ``mode`` not in :data:`~identification.likelihood.closed_loop.CLOSED_LOOP_MODES`.
        """
        self._check_fitted()
        if getattr(self, "closed_loop_", None) is not None:  # checked before: from the values as fitted again
            apply_check(self, self.closed_loop_, "fitted")
            self.closed_loop_ = None
        with threadpool_limits(limits=1, user_api="blas"):
            check = run_checks(self, mode, self.closed_loop_flights, MIN_LR_DELAY, workers=self.workers)
        apply_check(self, check)
        self.closed_loop, self.closed_loop_ = mode, check
        return check

    def _gated(self, axis: str, fit: MLAxisFit) -> bool:
        """Whether :attr:`timing_gate` kept ``axis``' undelayed ``fit`` from a timing search (asked again of the
        damping it was asked of: the undelayed fit stood)."""
        damping = next((p for p in fit.params if TERMS[p].effect == "damping"), None)
        return (self.timing_gate is not None and damping is not None
                and bool(self.timing_gate(axis, fit.params[damping])))

    def _controller_hold(self, ticks: int, axes: list, names: dict, flights, burn: int, start) -> dict | None:
        """With ``input_hold="auto"`` on a flight controller's commands logged slower than its loop (``ticks`` > 1 a
        sample): the log's hold decided before its timing, from the axes fitted with their hold searched and no
        delay or lag, held wherever the data do not reject it (:func:`decide_hold`'s ``prefer``), and put in force
        (``_decided_hold``) for the fits that follow. Returns the decision (``preferred`` says why), else None.

        Such a controller holds each command over one of its ticks, and its loop moves the command inside each
        logged sample, which the likelihood reads both ways: on the bench's autopilot 4x faster than its log, the
        sluggish aircraft's axes read 0.49 +- 3.6 / 0.57 +- 0.81 / 1.0 +- 2.1 on one flight (neither named hold
        rejected, interpolated taken), and searched with the timing the yaw took a 13 ms servo lag and ended +104 %
        (+148 % decided held afterwards, the lag kept), where decided held first it ended -0.1 %. A log whose data
        reject held keeps theirs: the real Betaflight quad (a 4 kHz loop fitted at 200 Hz) rejects it by a
        likelihood ratio of 7065 (6035 decided after the timing), and the bench's agile aircraft and 50 Hz paper
        log read fractions of 0.31-0.36 (held rejected by 16-21), with dampings within 3 % after the check."""
        self._decided_hold = None  # searched below, whatever an earlier fit decided
        if ticks <= 1 or self.input_hold != "auto" or not axes:
            return None

        def plain(axis):
            a = AXES.index(axis)
            return self._fit_axis(self.axis_problem(a, names[a], flights, burn), start, 0.0, 0.0)

        fits = dict(zip(axes, map_axes(plain, axes, self.workers)))
        decision = decide_hold({a: (f.input_hold, f.input_hold_se) for a, f in fits.items()},
                               sum(f.n_samples for f in fits.values()) / len(fits), prefer="zoh")
        decision["preferred"] = (f"a flight controller's commands, its loop {ticks}x faster than the log: held over "
                                 "each of its ticks where the data do not reject it, decided before the timing")
        self._decided_hold = decision["fraction"]
        self.hold_alternative_ = None
        return decision

    def _decide_log_hold(self, fits: dict, flights, burn) -> dict | None:
        """With ``input_hold="auto"``: one hold for the log from every axis' estimate (:func:`decide_hold`, a
        named hold unless the data reject it); an axis whose estimate lies further from it than its standard
        error is searched again at it from its optimum (in ``fits``). Returns the decision, else None."""
        self._decided_hold = None
        self.hold_alternative_ = None
        if self.input_hold != "auto" or not fits:
            return None
        decision = decide_hold({a: (f.input_hold, f.input_hold_se) for a, f in fits.items()},
                               sum(f.n_samples for f in fits.values()) / len(fits))
        self._decided_hold = decision["fraction"]

        def at_hold(axes):  # searched again from their optima in fits, at the hold in force
            return dict(zip(axes, map_axes(lambda axis: self._refit_at_hold(axis, fits[axis], flights, burn), axes,
                                           self.workers)))

        fits.update(at_hold([axis for axis, fit in fits.items()
                             if abs(fit.input_hold - self._decided_hold) > (fit.input_hold_se or 0.0)]))
        other = undecided_against(decision)
        if other is not None:  # the data reject neither named hold: the fit at the other, for the doubt it leaves
            self._decided_hold = HOLDS[other]
            self.hold_alternative_ = hold_alternative(other, fits, at_hold(list(fits)), decision["threshold"])
        self._decided_hold = None
        return decision

    def _apply_shifts(self, fits: dict, flights: list) -> list:
        """A log whose input lags (a negative alignment found by ``delay="auto"``): its sticks advanced, the
        axis' delay 0 and its shift recorded (in ``fits``, :attr:`input_shifts_`). Returns the flights."""
        shifts = [min(fits[a].delay, 0.0) if a in fits else 0.0 for a in AXES]
        self.input_shifts_ = dict(zip(AXES, shifts))
        if min(shifts) >= 0.0:
            return flights
        for a, shift in zip(AXES, shifts):
            if shift < 0.0:
                fits[a] = replace(fits[a], delay=0.0, input_shift=shift)
        return [shift_inputs(f, shifts) for f in flights]

    def axis_problem(self, a: int, names, flights, burn: int, free_damping: bool | None = None) -> AxisProblem:
        """Axis ``a``'s likelihood over ``flights`` with the parameters ``names``, searched at the hold in force
        (:meth:`_hold`) with this estimator's budget; ``free_damping`` None: the damping is searched when
        ``names`` hold one."""
        return AxisProblem(a, tuple(names), flights, burn, self._hold(), self.max_nfev, free_damping)

    def _kept_terms(self, a: int, fit: MLAxisFit) -> tuple:
        """The terms axis ``a``'s ``fit`` kept: the structure's, less those it dropped."""
        return tuple(p for p in self._param_names()[a] if p not in fit.dropped)

    def _fitted_data(self, a: int, fit: MLAxisFit, flights, burn: int) -> AxisData:
        """The likelihood's data of axis ``a`` as ``fit`` was fitted (its terms, delay, gust model and lag) over
        ``flights`` (aligned and cleaned as :attr:`flights_` are)."""
        return self.axis_problem(a, self._kept_terms(a, fit), flights, burn).data(fit.delay, fit.wind["model"],
                                                                                  fit.lag)

    def _refit_at_hold(self, axis_name: str, fit: MLAxisFit, flights, burn: int) -> MLAxisFit:
        """Axis ``axis_name`` searched again from its optimum ``fit`` at the hold in force (:meth:`_hold`), its
        terms kept; a shift (a negative delay) stays whole."""
        a = AXES.index(axis_name)
        return self._refit(self.axis_problem(a, self._kept_terms(a, fit), flights, burn), fit,
                           tau=fit.delay if fit.delay < 0.0 else None)

    def _supported(self, problem: AxisProblem, fit: MLAxisFit, start_params) -> MLAxisFit:
        """Drop, one at a time, the terms beyond the decoupled model whose ``|value / se|`` is below
        :data:`SUPPORT_Z`, refitting the axis after each; the dropped terms are listed in ``fit.dropped``."""
        a, names, dropped = problem.axis, tuple(problem.names), []
        while True:
            extra = [p for p in names if p not in DECOUPLED[a]]
            z = {p: abs(fit.params[p]) / fit.std_errors[p] if fit.std_errors[p] > 0 else np.inf for p in extra}
            weakest = min(z, key=z.get, default=None)
            if weakest is None or z[weakest] >= SUPPORT_Z:
                return replace(fit, dropped=tuple(dropped))
            names = tuple(p for p in names if p != weakest)
            dropped.append(weakest)
            # delay and lag stay
            fit = self._fit_axis(replace(problem, names=names), start_params, fit.delay, fit.lag)

    def _hold(self):
        """The hold in force: the user's, the flight's once decided (:func:`decide_hold`), or "auto"."""
        return getattr(self, "_decided_hold", None) if self.input_hold == "auto" and \
            getattr(self, "_decided_hold", None) is not None else self.input_hold

    def _fit_axis(self, problem: AxisProblem, start_params, delay, lag=0.0) -> MLAxisFit:
        """One axis fitted at servo delay ``delay`` and lag ``lag`` (seconds, "auto": profiled, or "detect":
        profiled where the delay's search found a servo delay)."""
        first = problem.on(problem.flights[:1]).data(0.0)
        damping_name = problem.damping_name
        free = damping_name is not None
        damping0 = float(-TERMS[damping_name].sign * start_params.get(damping_name)) if free else 0.0
        x0 = np.array([max(damping0, 0.1) if free else 0.0, np.log(4.0), np.log(0.3), np.log(100.0), np.log(100.0),
                       problem.hold_start()])
        models = WIND_MODELS if self.wind_model == "auto" else (self.wind_model,)
        fixed_lag = 0.0 if lag in ("auto", "detect") else float(lag)
        profile, undelayed = [], None
        if delay == "auto":
            found, profile, undelayed = self._profile_delay(problem, x0, models, fixed_lag)
        elif delay == "detect":
            found, profile, undelayed = self._detect_delay(problem, x0, models, fixed_lag)
        else:
            found = problem.best(float(delay), x0, models, lag=fixed_lag)
        free_tau = delay == "auto" or (delay == "detect" and found.tau != 0.0)
        lag_profile, lag_lr = (), None
        # "detect": a servo whose delay the data show may lag too (a late input column has no servo to lag)
        lagged = lag == "auto" or (lag == "detect" and free_tau and found.tau > 0.0)
        if lagged and first.servo_row is not None:  # an axis without its stick has no servo
            fixed_lag, found, lag_profile, lag_lr = profile_lag(problem, found, models, free_tau)
        fit = self._finish_axis(problem, found, fixed_lag, free_tau, profile, lag_profile, lag_lr)
        if undelayed is not None:  # the profile's undelayed fit, for a likelihood ratio against no delay
            fit = replace(fit, undelayed_nll=float(concentrated_nll(undelayed, fit.n_samples)))
        return fit

    def _detect_delay(self, problem: AxisProblem, x0, models, lag: float) -> tuple[WindFit, list, float | None]:
        """``delay="detect"``: the undelayed fit (the same searches as ``delay=None``), then a short search of
        the alignment with every other parameter from it, in its gust model; only where that moves the
        likelihood ratio past :data:`MIN_LR_DELAY` (a servo delay, or an input logged late) is the axis profiled
        as with ``"auto"``. Otherwise the undelayed fit, unchanged. Returns the optimum, the profile (empty
        when not profiled) and the undelayed fit's cost (None when not profiled)."""
        undelayed = problem.per_kind(0.0, x0, models, lag=lag)
        kind = min(undelayed, key=lambda k: undelayed[k][3])
        cost, x, _, aic = undelayed[kind]
        if self.timing_gate is not None and problem.searches_damping and self.timing_gate(
                AXES[problem.axis], float(-x[0] / TERMS[problem.damping_name].sign)):
            return WindFit(cost, x, kind, 0.0), [], None  # decided without a timing (timing_gate)
        aic_free = problem.per_kind(0.0, {kind: x}, (kind,), DETECT_NFEV, free_tau=True, lag=lag)[kind][3]
        if 2.0 * (aic - aic_free) < MIN_LR_DELAY:
            return WindFit(cost, x, kind, 0.0), [], None
        return self._profile_delay(problem, x0, models, lag, undelayed)

    def _profile_delay(self, problem: AxisProblem, x0, models, lag: float,
                       undelayed: dict | None = None) -> tuple[WindFit, list, float]:
        """``delay="auto"``: the likelihood over a grid of delays with the damping and wind of the undelayed fit
        held (the linear parameters solved at each), then every parameter and the delay searched from the best.
        ``undelayed``: :meth:`AxisProblem.per_kind` at no delay, when already searched. Returns the optimum,
        the profile ``[(delay, cost)]`` and the undelayed fit's cost (the best gust model's)."""
        grid = np.asarray(self.delay_grid if self.delay_grid is not None else DEFAULT_DELAY_GRID, dtype=float)
        undelayed = undelayed or problem.per_kind(0.0, x0, models, lag=lag)
        kind = min(undelayed, key=lambda k: undelayed[k][3])
        xb = np.array(undelayed[kind][1], dtype=float)
        if problem.searches_damping and xb[0] < MIN_PROFILE_DAMPING:
            # an undelayed fit with a damping of the wrong sign (a log whose input lags by a large
            # fraction of the response time): held at it, the profile ranks alignments by how well
            # an unstable model fits, so it is held at the integral method's start or a nominal one
            xb[0] = max(x0[0], NOMINAL_DAMPING)
        profile = []
        for tau in grid:
            like = AxisLikelihood(problem.data(float(tau), kind, lag))
            e = like.residual(xb)
            profile.append((float(tau), 0.5 * float(e @ e)))
        tau0 = min(profile, key=lambda p: p[1])[0]
        # the held damping biases the grid's best: every wind model is searched from it together with the
        # delay, each from its own undelayed fit (a second-order gust started from a first-order one stalls)
        fits = {}
        for start in ({k: v[1] for k, v in undelayed.items()}, x0):  # two starts: the likelihood is multimodal
            for k, v in problem.per_kind(tau0, start, models, free_tau=True, lag=lag).items():
                if k not in fits or v[3] < fits[k][3]:
                    fits[k] = v
        kind = min(fits, key=lambda k: fits[k][3])
        cost, x, tau, aic = fits[kind]
        base = min(undelayed, key=lambda k: undelayed[k][3])
        # the undelayed fit stands where the data do not support an alignment (twice the Akaike difference is the
        # likelihood ratio: the gust models have as many parameters; a delay of a few ms fitted to the timing
        # conventions of a log biased the damping, effect-free autopilot flights, 180 s: 5.5 % RMS against 2.6 %),
        # and where the alignment makes a stable axis unstable: neither a servo delay nor a late column does that
        # (the T-REX hover's yaw, 2 % of its rate from its pedal, took 0.48 s with its damping 0.18 -> -0.24 and
        # its gain's sign flipped, k10 0.86 -> -5.4, and the model diverged)
        unsupported = 2.0 * (undelayed[base][3] - aic) < MIN_LR_DELAY
        destabilising = problem.searches_damping and x[0] <= 0.0 < undelayed[base][1][0]
        if unsupported or destabilising:
            kind = base
            cost, x, tau = undelayed[base][0], undelayed[base][1], 0.0
        return WindFit(cost, x, kind, tau), profile, float(undelayed[base][0])

    def _finish_axis(self, problem: AxisProblem, found: WindFit, lag, free_tau, profile=(), lag_profile=(),
                     lag_lr=None) -> MLAxisFit:
        """The fit of the axis at the searched optimum ``found`` (its model part, gust model and delay)."""
        data = problem.data(found.tau, found.kind, lag)
        like = AxisLikelihood(data, free_tau)
        x = np.append(found.x, found.tau) if free_tau else found.x
        solution = like.solve_linear(x)
        n_burnt = int(sum(len(y) - problem.burn for y in data.y))
        fit = problem.result(like, x, solution, float(found.tau), found.kind,
                             tuple((t, float(concentrated_nll(c, n_burnt))) for t, c in profile))
        return replace(fit, lag=float(lag), lag_profile=lag_profile, lag_lr=lag_lr)

    def _refit(self, problem: AxisProblem, fit: MLAxisFit, tau: float | None = None) -> MLAxisFit:
        """The axis searched again from its optimum ``fit``: at the hold of ``problem`` (the log's, once
        decided) and at delay ``tau`` when given (else its own, searched again when profiled and the data
        supported one: a delay the profile rejected stays 0), its gust model and lag kept. The few steps from a
        nearby optimum, not a new fit."""
        x0 = np.array(fit.state, dtype=float)
        fixed = problem.fixed()
        if HOLD_INDEX in fixed:
            x0[HOLD_INDEX] = fixed[HOLD_INDEX]
        free_tau = tau is None and self._delays()[problem.axis] in ("auto", "detect") and fit.delay != 0.0
        kind = fit.wind["model"]
        found = problem.per_kind(fit.delay if tau is None else tau, x0, (kind,), free_tau=free_tau, lag=fit.lag)
        _, x, tau, _ = found[kind]
        refit = self._finish_axis(problem, WindFit(found[kind][0], x, kind, tau), fit.lag, free_tau)
        return replace(refit, delay_profile=fit.delay_profile, lag_profile=fit.lag_profile, lag_lr=fit.lag_lr,
                       dropped=fit.dropped, undelayed_nll=fit.undelayed_nll)

    # ----------------------------------------------------------------- use
    def _check_fitted(self):
        if not hasattr(self, "params_"):
            raise NotFittedError("this MaximumLikelihoodIdentifier is not fitted yet; call fit(flight) first")

    def aligned(self, flight: Flight) -> Flight:
        """``flight`` with its sticks advanced by :attr:`input_shifts_` (itself when there are none)."""
        self._check_fitted()
        shifts = [self.input_shifts_.get(a, 0.0) for a in AXES]
        return shift_inputs(flight, shifts) if min(shifts) < 0.0 else flight

    def predict(self, flight: Flight) -> np.ndarray:
        """Forward-simulate the identified model with the flight's sticks (aligned, :meth:`aligned`); rates
        (3, n) [rad/s]."""
        self._check_fitted()
        from heli_core.physics import forward_rates

        return forward_rates(self.params_, self.aligned(flight))

    def wind_torque(self, flight: Flight | int = 0) -> np.ndarray:
        """The smoother's estimate of the wind torque at every sample, shape (3, n) [rad/s^2].

        The Rauch-Tung-Striebel smoother of the fitted model runs over the flight
        (an index into the fitted flights, or a new flight, whose vibration lines are
        removed first) and returns the gust states' sum plus the flight's offset
        less the model's: the disturbance torque of eq. (41) about the model's
        offset ``kd``. Rows of axes not identified are zero.
        """
        self._check_fitted()
        if isinstance(flight, Flight):
            flight, index = self._clean(self.aligned(flight))[0], None
        else:
            index = int(flight)
            flight = self.flights_[index]
        out = np.zeros((3, flight.n))
        for axis_name, fit in self.axes_.items():
            a = AXES.index(axis_name)
            data = self._fitted_data(a, fit, [flight], 0)
            own = [n for n in data.names if "@" not in n]
            off_name = next((n.split("@")[0] for n in data.names if "@" in n), None)
            theta = np.array([fit.params[n] for n in own])
            drive = theta @ data.regressors[0][:len(own)]
            shift = 0.0
            if off_name is not None:
                if index is not None:
                    shift = fit.flight_offsets[index] - fit.params[off_name]
                drive = drive + fit.params[off_name] + shift
            states = rts_smooth(data.y[0], drive, *AxisLikelihood(data).unpack(fit.state), data.dt, fit.input_hold,
                                fit.wind["model"])
            _, cw, _ = wind_block(fit.wind["model"], 1.0, 1.0)  # the same sum for every T, zeta
            out[a] = cw @ states[1:] + shift
        return out

    def summary(self) -> dict:
        """JSON-ready fit statistics per axis."""
        self._check_fitted()
        return {
            name: {
                "params": f.params, "std_errors": f.std_errors, "delay_s": f.delay,
                "condition_number": f.condition, "r2": f.r2, "prediction_r2": f.prediction_r2,
                "wind": f.wind, "noise_std": f.noise_std, "nll": f.nll, "n_samples": f.n_samples,
                "flight_offsets": list(f.flight_offsets),
                "dropped_terms": list(f.dropped),
                "delay_profile": [list(p) for p in f.delay_profile],
                "servo_lag_s": f.lag, "servo_lag_profile": [list(p) for p in f.lag_profile],
                "servo_lag_lr": f.lag_lr,
                "input_hold": f.input_hold, "input_hold_se": f.input_hold_se,
                "mean_square_innovation": list(f.history),
                **({"std_errors_with_hold": std_errors_with_hold(f.params, f.std_errors, self.hold_alternative_, name)}
                   if getattr(self, "hold_alternative_", None) else {}),
            }
            for name, f in self.axes_.items()
        }
