"""The closed-loop check: fly the identified model again with the flight's own loop, fit it, and see what
the estimator returns where the truth is known.

A pilot who sees the aircraft puts into his sticks what the gyro did not measure: he reacts to the gusts
themselves, noise-free. The likelihood of the gyro alone, conditioned on the sticks, cannot use that, and
the damping bends to use it: on slow axes behind a noisy gyro the dampings came out 7-32 % high
(docs/method.md, "Where it does not hold"). The bias depends on the aircraft, the wind, the gyro and the
pilot together, so it is measured on the flight's own conditions, by a parametric bootstrap (Efron &
Tibshirani 1993, ch. 10; in system identification, a Monte Carlo check of the estimator on the identified
model):

1. per axis and flight, the pilot is fitted to the logged sticks (:mod:`identification.likelihood.pilot_model`);
   an axis whose sticks follow the logged gyro (a flight controller's loop: its commands are a function of
   what the log measured, and the likelihood conditioned on them is the right one) is not checked;
2. ``n_flights`` flights are flown by the identified axis model (eqs. 18/21 with the fitted gust model of
   eqs. 41-42, exactly discretised at the fitted input hold; gyro noise as fitted) under that pilot, who sees
   the simulated aircraft ``delay`` samples late, his sweeps and jitter (the fit's residual) replayed;
3. each is fitted as the flight was (same terms, hold, gust model, timing), and the mean relative error of the
   gain, the damping and a servo delay the search found is the estimator's bias there.

A bias larger than ``SIGNIFICANCE`` standard errors of its mean is removed from the fitted value (one step
of bootstrap bias correction, ``value * (1 - bias)``: the bias at the estimate stands for the bias at the
truth); a smaller one is reported and left. So is every bias of an axis whose biases do not point the loop's
way. That way has one direction: a pilot who opposes the motion puts into his sticks, with the opposite sign,
motion the gyro did not see, and the likelihood reads it as more damping and less control power (the
damping up, the gain's magnitude down, either of them within its noise: on every aircraft, pilot, gyro and wind
measured; behind a real 20 ms servo delay the paper aircraft's pitch gain moved +0.2-0.4 +- 0.3-0.6 % beside a
damping +5-7 +- 1-1.6 %, and the sluggish aircraft's yaw behind a 0.03 rad/s gyro the other way round, its gain
-0.9 to -1.8 +- 0.2-0.4 % beside a damping -2.0 to +0.3 +- 1.0-2.2 %). A bias the other way (the gain's magnitude
significantly up, or the damping significantly down) is the simulated world's own (an agile aircraft's yaw in
2 Hz Dryden gusts, its gust fitted at 7 Hz, gave +40 % on the damping with the gain +11 % where the flight's fit
was within 2.4 %), not the loop's. (Until 2026-12-04 a damping whose bias was down by any amount, within its
noise too, kept every bias of its axis: the sluggish yaw's gain bias was then removed or left by the sign of a
damping bias of +0.3 +- 1.3 % or -0.5 +- 2.2 %.)

An axis with a servo delay or lag is flown through its servo (eq. 31, Padé, discretised exactly as the likelihood
does, :func:`~identification.likelihood.state_space.servo_step`) and its flights fitted with the flight's timing
settings (the delay searched again as it was found, or held at the user's value). Axes whose stick was found to
be logged late (a negative alignment) or with terms driven by other axes' rates are not flown (the one-axis loop
does not carry them), nor axes whose gyro shows next to no noise (a log filtered before it was written); each
says why.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import MappingProxyType, SimpleNamespace

import numpy as np

from heli_core.terms import AXES, STICK_ROW

from ..errors import IdentifiabilityError
from ..flight import Flight
from ..validation.fit_warnings import CONTROLLER_SOURCES, FASTER_LOOP, input_source
from ..validation.model_verdict import bound_side
from .axis_likelihood import MIN_SERVO_DELAY, AxisLikelihood
from .axis_pool import map_axes
from .pilot_model import AxisSignals, PilotModel, fit_pilot, reaction_delay
from .state_space import covariance_root, discrete_model, rts_smooth, servo_increments, servo_step, wind_block

CLOSED_LOOP_MODES = ("auto", "report")
"""``"auto"``: check and remove a significant bias; ``"report"``: check and leave the fit as it is."""

N_FLIGHTS = 8
"""Flights flown per check (each is one more fit of the flight's length)."""

SIGNIFICANCE = 2.0
"""A bias is removed when its mean exceeds this many standard errors of the mean over the flights flown."""

CONCLUSIVE = (1.0, 3.0)
"""A bias within these many standard errors of zero is inconclusive: more flights are flown (up to the
check's ``max_flights``). At the paper's wind 8 flights decide; at twice the wind a +5 % damping bias took 16-24."""

SETTLE = 3000
"""Samples the simulated loop flies before the record starts (the gusts and the pilot settle)."""

MIN_NOISE_SHARE = 0.02
"""An axis whose fitted gyro noise is below this share of the rate's standard deviation is not checked: the
bias needs a noisy gyro (none measured without one, docs/method.md), and a log filtered before it was written
has no noise for the pilot fit to tell a pilot's sticks from a controller's by."""

MAX_LOOP_TICKS = 40
"""Most ticks of a flight controller's loop flown per logged sample (:func:`loop_ticks`: a 4 kHz loop logged at
100 Hz)."""

MAX_RATE_RATIO = 2.0
"""A simulated loop whose rate's standard deviation is further than this factor from the logged one's is not
the flight's loop (the pilot's fit failed); the axis is then not checked."""


@dataclass(frozen=True, eq=False)
class AxisCheck:
    """The closed-loop check of one axis.

    Attributes
    ----------
    axis : str
    checked : bool
        Flown and fitted; when False, ``reason`` says why not.
    reason : str
    pilots : tuple of dict
        Per flight, the fitted pilot (:meth:`PilotModel.describe`).
    fitted : dict
        The estimate before the check: gain and damping.
    bias : dict
        Mean relative error of each over the flights flown (fitted value less the model's, over the model's).
    bias_se : dict
        Its standard error.
    corrected : dict
        The values after the check: the fitted ones less the significant biases.
    loops_direction : bool
        The biases point the loop's way (:func:`loops_direction`: neither the damping significantly down nor the
        gain's magnitude significantly up); only then is one removed.
    flights : int
        The check's flights fitted on this axis: every batch flown until its damping was clearly not biased up
        (or no axis was in doubt).
    loop_ticks : int
        Ticks of the flight controller's loop flown per logged sample (:func:`loop_ticks`; 1: the loop flown at
        the log's rate).
    """

    axis: str
    checked: bool
    reason: str = ""
    pilots: tuple = ()
    fitted: dict = field(default_factory=dict)
    bias: dict = field(default_factory=dict)
    bias_se: dict = field(default_factory=dict)
    corrected: dict = field(default_factory=dict)
    loops_direction: bool = True
    flights: int = 0
    loop_ticks: int = 1

    @property
    def removed(self) -> tuple:
        """Parameters whose bias was significant (their value corrected)."""
        return tuple(k for k in self.bias if self.corrected.get(k) != self.fitted.get(k))

    def describe(self) -> dict:
        """JSON-ready."""
        return {"axis": self.axis, "checked": self.checked, "reason": self.reason, "pilots": list(self.pilots),
                "fitted": self.fitted, "bias": self.bias, "bias_se": self.bias_se, "corrected": self.corrected,
                "loops_direction": self.loops_direction, "removed": list(self.removed), "flights": self.flights,
                "loop_ticks": self.loop_ticks}


@dataclass(frozen=True)
class ClosedLoopCheck:
    """What the closed-loop check found, per axis (:class:`AxisCheck`), with its settings."""

    axes: dict
    n_flights: int
    seed: int
    mode: str
    time: float
    hold: object = None  # the hold decided in the loop's world (identification.likelihood.hold_check.HoldCheck)
    delays: dict = field(default_factory=dict)  # servo delays tested (identification.likelihood.delay_check)

    def describe(self) -> dict:
        """JSON-ready (``model.json``'s ``fit_statistics.closed_loop``)."""
        return {"method": "parametric bootstrap in the flight's closed loop", "mode": self.mode,
                "n_flights": self.n_flights, "seed": self.seed, "significance": SIGNIFICANCE,
                "time_s": self.time, "axes": {a: c.describe() for a, c in self.axes.items()},
                "hold": None if self.hold is None else self.hold.describe(),
                "delays": {a: d.describe() for a, d in self.delays.items()}}

    def headline(self) -> str:
        """What was flown, in a few words (a report's or the terminal's heading of :meth:`lines`)."""
        if not self.n_flights:
            return "no axis flown"
        if len({c.flights for c in self.axes.values() if c.checked and c.flights}) < 2:
            return f"{self.n_flights} flights of the model flown under the pilot fitted to the sticks and fitted again"
        fitted = ", ".join(f"{a} {c.flights}" for a, c in self.axes.items() if c.checked and c.flights)
        return (f"{self.n_flights} flights of the model flown under the pilot fitted to the sticks and fitted again "
                f"({fitted}: an axis clear of the loop's bias is not fitted further)")

    def lines(self) -> list[str]:
        """One line per axis, for a report or the terminal."""
        out = []
        for axis, c in self.axes.items():
            if not c.checked:
                out.append(f"{axis}: not checked: {c.reason}")
                continue
            parts = []
            for k, b in c.bias.items():
                verdict = "removed" if k in c.removed else "left"
                parts.append(f"{k} {100 * b:+.1f} ± {100 * c.bias_se[k]:.1f} % ({verdict})")
            found = against_the_loop(c.bias, c.bias_se, *list(c.bias)[:2], c.loop_ticks)  # gain, damping (_biases)
            other = "" if c.loops_direction else f" (not the loop's direction: {found}; left)"
            out.append(f"{axis}: {_who_flew(c)}; bias " + "; ".join(parts) + other)
        out += [d.line() for d in self.delays.values()]
        if self.hold is not None:
            out.append(self.hold.line())
        return out


def _who_flew(c: AxisCheck) -> str:
    """Who flew an axis' loop, as :meth:`ClosedLoopCheck.lines` says it."""
    if c.loop_ticks > 1:
        return (f"a flight controller's commands, its loop flown at {c.loop_ticks} ticks a logged sample (the rate "
                "the log states)")
    delays = ", ".join(f"{p['reaction_delay_s']:.2f}" for p in c.pilots)
    return f"pilot sees the aircraft (reaction {delays} s)"


def loop_ticks(flight, dt: float | None = None) -> int:
    """Ticks of a flight controller's loop per sample of ``flight`` (its samples ``dt`` apart, default its own): the
    loop's rate over the samples', rounded, where the inputs are a flight controller's commands and the log states a
    loop faster than them by :data:`~identification.validation.fit_warnings.FASTER_LOOP` (at most
    :data:`MAX_LOOP_TICKS`); else 1. Such a loop corrects the aircraft inside each logged sample, and the model,
    driven by the sampled commands, reads that as damping (docs/method.md): the check flies it at its own rate."""
    source, loop = input_source(getattr(flight, "metadata", {}) or {})
    rate = 1.0 / dt if dt else flight.sample_rate
    if source not in CONTROLLER_SOURCES or loop is None or loop <= FASTER_LOOP * rate:
        return 1
    return int(min(MAX_LOOP_TICKS, round(loop / rate)))


@dataclass(frozen=True, eq=False)
class _AxisLoop:
    """One axis of one flight as the simulated loop flies it."""

    Ad: np.ndarray
    g0: np.ndarray
    g1: np.ndarray
    noise_root: np.ndarray  # a root of the process noise's covariance
    noise_std: float
    gain: float  # torque per stick unit
    other: np.ndarray  # the rest of the known torque (offset, collective terms) per sample
    pilot: PilotModel
    angle0: float
    dt: float  # the log's sample
    servo: np.ndarray  # (e_rz, e_zz, h0 rate, h0 servo, h1 rate, h1 servo): the stick's path (_stick_path)
    ticks: int = 1  # the loop's ticks per sample (loop_ticks): Ad, g0, g1, noise_root and servo are a tick's


def _names(ident, a: int, fit, data) -> tuple[str, str, tuple]:
    """(gain name, damping name, the terms fitted) of axis ``a`` as ``fit`` was fitted (``data`` its
    likelihood's :class:`~identification.likelihood.axis_likelihood.AxisData`)."""
    kept = ident._kept_terms(a, fit)
    own = [n for n in data.names if "@" not in n]
    return own[data.servo_row], ident.axis_problem(a, kept, ident.flights_, 0).damping_name, kept


def _skip_reason(ident, a: int, fit, data) -> str:
    """Why axis ``a`` (``fit``, its likelihood's ``data``) is not flown, or empty."""
    damping = _names(ident, a, fit, data)[1]
    side = bound_side(fit.params[damping], ident.damping_bounds) if damping else None
    if side is not None:  # the model verdict names it; nothing downstream is built on it here
        return f"its damping {damping} is at the {side} bound of the search (the data did not place it)"
    share = fit.noise_std / max(float(np.std(np.concatenate(data.y))), 1e-300)
    fast = any(loop_ticks(f, data.dt) > 1 for f in ident.flights_)  # its bias needs no noise (docs/method.md)
    if share < MIN_NOISE_SHARE and not fast:
        return (f"the gyro shows next to no white noise ({100 * share:.2g} % of the rate's std; a log filtered before "
                "it was written): there is nothing in the rate a pilot could see better than it")
    if fit.delay < -MIN_SERVO_DELAY:
        return ("its stick was found logged late (a negative alignment): the loop flies a servo, not a log's "
                "timing")
    if data.causal_rows:
        return "the axis' model reads other axes' rates; the one-axis loop does not fly them"
    if data.servo_row is None:
        return "no stick term"
    return ""


def has_servo(fit) -> bool:
    """Axis ``fit`` has a servo state: a delay (Padé) or a lag."""
    return fit.delay > MIN_SERVO_DELAY or fit.lag > 0.0


def _stick_path(fit, damping: float, g0, g1, dt: float, hold=None) -> np.ndarray:
    """The stick's path into the rate over a step ``dt`` of the loop (:attr:`_AxisLoop.servo`), the stick between
    steps as ``hold`` has it (default the fit's): through the servo of ``fit`` when it has one
    (:func:`~identification.likelihood.state_space.servo_step`), else directly (``g0``, ``g1`` of the rate; the gust
    states take no input)."""
    if not has_servo(fit):
        return np.array([0.0, 0.0, g0[0], 0.0, g1[0], 0.0])
    e_rz, e_zz, h0, h1 = servo_step(damping, max(fit.delay, 0.0), dt, fit.input_hold if hold is None else hold, fit.lag)
    return np.array([e_rz, e_zz, h0[0], h0[1], h1[0], h1[1]])


def _step_pieces(fit, model: tuple, dt: float, hold) -> tuple:
    """Axis ``fit``'s model (its likelihood's unpacked ``model``) over one step ``dt`` of the loop, the stick between
    steps as ``hold`` has it: ``(Ad, g0, g1, noise root, servo)`` (:class:`_AxisLoop`)."""
    Ad, g0, g1, Qd = discrete_model(*model, dt, hold, fit.wind["model"])
    return Ad, g0, g1, covariance_root(Qd) * fit.noise_std, _stick_path(fit, model[0], g0, g1, dt, hold)


def _tick_pieces(fit, data, ticks: int) -> tuple:
    """:func:`_step_pieces` over one tick of a flight controller's loop, ``ticks`` a logged sample of ``data``: the
    controller holds its command over each of its ticks."""
    return _step_pieces(fit, AxisLikelihood(data).unpack(fit.state), data.dt / ticks, "zoh")


def _signals(ident, a: int, fit, data) -> tuple[list, list]:
    """Per fitted flight, axis ``a``'s :class:`AxisSignals` and its loop's pieces ``(Ad, g0, g1, noise root,
    gain, other torque, servo)``, from its likelihood's ``data``."""
    own = [n for n in data.names if "@" not in n]
    theta = np.array([fit.params[n] for n in own])
    model = AxisLikelihood(data).unpack(fit.state)
    Ad, g0, g1, root, servo = _step_pieces(fit, model, data.dt, fit.input_hold)
    row = data.servo_row
    _, cw, _ = wind_block(fit.wind["model"], 1.0, 1.0)  # the gust states' sum, the same for every T, zeta
    signals, pieces = [], []
    for i, flight in enumerate(ident.flights_):
        regs = data.regressors[i][:len(own)]
        other = theta @ regs + fit.flight_offsets[i] - theta[row] * regs[row]  # all but the stick's torque
        stick = flight.sticks[STICK_ROW[a]]
        gain = (float(np.sign(regs[row] @ stick)) or 1.0) * theta[row]
        if has_servo(fit):  # the stick through the servo, exactly as the likelihood has it
            direct = theta[row] * servo_increments(data.servo_sticks[i], model[0], max(fit.delay, 0.0), data.dt,
                                                   fit.input_hold, fit.lag)
            states = rts_smooth(data.y[i], other, *model, data.dt, fit.input_hold, fit.wind["model"], direct)
        else:
            states = rts_smooth(data.y[i], other + theta[row] * regs[row], *model, data.dt, fit.input_hold,
                                fit.wind["model"])
        signals.append(AxisSignals(stick, np.unwrap(flight.attitude[a]), states[0], data.y[i], cw @ states[1:],
                                   data.dt))
        pieces.append((Ad, g0, g1, root, gain, other, servo))
    return signals, pieces


def _loops(ident, data: dict) -> tuple[dict, dict]:
    """The loop of each axis of ``data`` (axis -> its likelihood's data) in every fitted flight, its pilot's delay
    shared by the flight's axes, and the logged :class:`AxisSignals` it was fitted to: two dicts of lists (one
    item per flight)."""
    axes = list(data)
    built = {axis: _signals(ident, AXES.index(axis), ident.axes_[axis], data[axis]) for axis in axes}
    loops = {axis: [] for axis in axes}
    if not axes:
        return loops, {}
    for i, flight in enumerate(ident.flights_):
        ticks = loop_ticks(flight, data[axes[0]].dt)
        # a controller faster than its log: its law reads the state the sample it commands (a tick before it)
        d = 0 if ticks > 1 else reaction_delay([built[axis][0][i] for axis in axes])
        for axis in axes:
            sig = built[axis][0][i]
            Ad, g0, g1, root, gain, other, servo = built[axis][1][i]
            if ticks > 1:
                Ad, g0, g1, root, servo = _tick_pieces(ident.axes_[axis], data[axis], ticks)
            loops[axis].append(_AxisLoop(Ad, g0, g1, root, ident.axes_[axis].noise_std, gain, other,
                                         fit_pilot(sig, d), float(sig.angle[0]), sig.dt, servo, ticks))
    return loops, {axis: built[axis][0] for axis in axes}


_COMPILED = {}


def _compiled_fly():
    """:func:`_fly` compiled by numba, once per process (numba imported only when a check runs)."""
    if "fly" not in _COMPILED:
        import numba

        _COMPILED["fly"] = numba.njit(cache=True)(_fly)
    return _COMPILED["fly"]


def _fly(Ad, g0, g1, kicks, noise, gain, other, delay, coef, angle_mean, rest, dt, angle0, servo):  # pragma: no cover
    """The loop over samples: returns the gyro, the angle and the sticks (each (n,)).

    ``kicks`` (m, n) are the process noise, ``noise`` (n,) the gyro's; the stick drives the rate through
    ``servo`` (:attr:`_AxisLoop.servo`, its state settled on the trim), the other torque through ``g0``, ``g1``;
    ``other`` and ``rest`` are padded with their first value and zeros over the settling samples. The pilot's
    stick at k reads the angle (about ``angle_mean``), the rate, the gyro's noise and the angle's integral
    ``delay`` samples before, plus ``rest[k]``, clipped to the stick's range
    (:class:`~identification.likelihood.pilot_model.PilotModel`)."""
    m, n = Ad.shape[0], rest.size
    rate = np.zeros(n)
    angle = np.zeros(n)
    integral = np.zeros(n)
    u = np.zeros(n)
    x = np.zeros(m)
    angle[0] = angle0
    trim = -other[0] / gain
    u[0] = trim
    z = trim
    for k in range(n):
        rate[k] = x[0]
        if k > 0:
            integral[k] = integral[k - 1] + dt * (angle[k] - angle_mean)
        if k + 1 == n:
            break
        j = k + 1
        if j >= delay:
            i = j - delay
            v = (coef[0] + coef[1] * (angle[i] - angle_mean) + coef[2] * rate[i] + coef[3] * noise[i]
                 + coef[4] * integral[i] + rest[j])
        else:
            v = trim
        u[j] = min(1.0, max(-1.0, v))
        now, nxt = other[k], other[j]
        y = np.empty(m)
        for r in range(m):
            s = g0[r] * now + g1[r] * nxt + kicks[r, k]
            for c in range(m):
                s += Ad[r, c] * x[c]
            y[r] = s
        y[0] += gain * (servo[0] * z + servo[2] * u[k] + servo[4] * u[j])
        z = servo[1] * z + servo[3] * u[k] + servo[5] * u[j]
        angle[j] = angle[k] + 0.5 * dt * (x[0] + y[0])
        x = y
    return rate + noise, angle, u


def _between(x: np.ndarray, m: int) -> np.ndarray:
    """``x`` at ``m`` ticks a sample, linearly interpolated between its samples (the last held)."""
    if m == 1:
        return x
    ticks = np.arange(x.size * m) / m
    return np.interp(ticks, np.arange(x.size), x)


def _fly_loop(loop: _AxisLoop, rng: np.random.Generator) -> tuple:
    """One simulated flight of ``loop``: gyro, angle and stick at the log's samples, each (n,).

    A loop of ``loop.ticks`` > 1 is a flight controller's, flown at its own rate: its law reads the state a tick
    before each tick's command, the rest of its command and the other torque held over each logged sample, and the
    log keeps every ``ticks``-th tick (the command logged is the one its sample starts with)."""
    m = loop.ticks
    n = (loop.pilot.rest.size + SETTLE) * m
    kicks = loop.noise_root @ rng.standard_normal((loop.Ad.shape[0], n))
    noise = loop.noise_std * rng.standard_normal(n)
    rest = _between(np.concatenate([np.zeros(SETTLE), loop.pilot.rest]), m)
    other = np.repeat(np.concatenate([np.full(SETTLE, loop.other[0]), loop.other]), m)
    p = loop.pilot
    gyro, angle, u = _compiled_fly()(loop.Ad, loop.g0, loop.g1, kicks, noise, loop.gain, other, max(1, p.delay * m),
                                     p.coefficients, p.angle_mean, rest, loop.dt / m, loop.angle0, loop.servo)
    return gyro[SETTLE * m::m], angle[SETTLE * m::m], u[SETTLE * m::m]


def _implausible(loop: _AxisLoop, logged: AxisSignals) -> str:
    """Why the simulated loop is not the flight's (empty when it is): a pilot fitted to the sticks that does
    not hold the identified model drives the simulated rates far from the logged ones or the sticks to their
    stops."""
    gyro, _, u = _fly_loop(loop, np.random.default_rng(0))
    ratio = float(np.std(gyro) / max(np.std(logged.gyro), 1e-12))
    stops = float(np.mean(np.abs(u) >= 1.0))
    logged_stops = float(np.mean(np.abs(logged.stick) >= 1.0))
    if not np.isfinite(ratio) or not 1.0 / MAX_RATE_RATIO <= ratio <= MAX_RATE_RATIO or stops > logged_stops + 0.02:
        return (f"the pilot fitted to the sticks does not fly the identified model as the flight went (simulated "
                f"rate std x{ratio:.2f} the logged, sticks at their stops {100 * stops:.0f} % of the time)")
    return ""


def unflyable(loops: list, signals: list) -> str:
    """Why an axis' ``loops`` (one per flight, beside the logged ``signals`` they were fitted to) are not the
    loop the check models, or empty: sticks that follow the logged gyro, or a pilot who does not fly the model as
    the flight went (:func:`_implausible`)."""
    if any(loop.pilot.flies_on == "sensors" and loop.ticks == 1 for loop in loops):
        return ("its sticks follow the logged gyro's noise (a loop closed on the logged sensors, as a flight "
                "controller's): the likelihood conditioned on them is the right one")
    return next(filter(None, (_implausible(lp, sig) for lp, sig in zip(loops, signals))), "")


def world_loops(world, axes) -> tuple[dict, str]:
    """The loops of ``world``'s axes ``axes`` (an estimator, or a world of :func:`with_fits`) as the check flies
    them (:func:`_loops`), and why they cannot be flown, empty when they can: the first of the check's own reasons
    not to fly an axis (:func:`_skip_reason`, :func:`unflyable`) that one of them has."""
    data = {axis: world._fitted_data(AXES.index(axis), world.axes_[axis], world.flights_, 0) for axis in axes}
    why = next(filter(None, (_skip_reason(world, AXES.index(axis), world.axes_[axis], data[axis]) for axis in axes)),
               "")
    if why:
        return {}, why
    loops, signals = _loops(world, data)
    return loops, next(filter(None, (unflyable(loops[axis], signals[axis]) for axis in axes)), "")


def flown_flights(ident, axis: str, loops: list, rng: np.random.Generator) -> list:
    """``ident``'s flights with axis ``axis``' gyro, attitude and stick replaced by one simulated flight of each
    of its ``loops`` (one per fitted flight); the other axes as logged."""
    a = AXES.index(axis)
    flights = []
    for flight, loop in zip(ident.flights_, loops):
        gyro, angle, u = _fly_loop(loop, rng)
        rates, attitude, sticks = flight.rates.copy(), flight.attitude.copy(), flight.sticks.copy()
        rates[a], attitude[a], sticks[STICK_ROW[a]] = gyro, np.angle(np.exp(1j * angle)), u
        meta = {k: v for k, v in flight.metadata.items() if k not in ("units_check", "vibration_lines")}
        flights.append(Flight(flight.time, rates, attitude, sticks, MappingProxyType(meta), flight.extra))
    return flights


def with_fits(ident, fits: dict):
    """``ident`` seen with the axis fits ``fits`` in place of its own: what this module's functions read of an
    estimator (the hold's and the delay's worlds, :mod:`~identification.likelihood.hold_check`,
    :mod:`~identification.likelihood.delay_check`)."""
    world = SimpleNamespace(**{k: getattr(ident, k) for k in ("flights_", "max_nfev", "damping_bounds")})
    world.axes_ = {**ident.axes_, **fits}
    for method in ("_param_names", "_kept_terms", "axis_problem", "_fitted_data", "_delays", "_lags"):
        setattr(world, method, getattr(ident, method))
    return world


def fitted_timing(ident, axis: str) -> dict:
    """The timing settings axis ``axis``' flights flown by the check are fitted with (:func:`axis_refit`'s
    ``delay``, ``servo_lag``): the flight's own (``ident``'s setting for the axis: searched again as it was found, or
    the user's value) for what its fit has, none for what it has not."""
    fit, a = ident.axes_[axis], AXES.index(axis)
    return {"delay": ident._delays()[a] if fit.delay > MIN_SERVO_DELAY else None,
            "servo_lag": ident._lags()[a] if fit.lag > 0.0 else None}


def axis_refit(ident, axis: str, kept: tuple, flights: list, hold, delay=None, servo_lag=None):
    """Axis ``axis`` of ``ident`` fitted again on ``flights`` as the check fits its flights: the terms ``kept``,
    its gust model, at input hold ``hold``, no vibration removal, and no delay or lag (``delay``, ``servo_lag``:
    the estimator's settings for them, e.g. "auto", profiled). Returns the estimator.

    Raises
    ------
    IdentifiabilityError
        The fit refused the flights (a simulated loop that left the stick still)."""
    fit = ident.axes_[axis]
    return type(ident)(structure={AXES.index(axis): kept}, input_hold=hold, delay=delay, servo_lag=servo_lag,
                       wind_model=fit.wind["model"], remove_vibration=False, axes=(axis,),
                       max_nfev=ident.max_nfev, workers=1).fit(flights)


def checked_values(fit, axis: str, names: tuple, searched_delay: bool) -> dict:
    """The values the check measures the bias of, from axis ``axis``' ``fit``: the gain and the damping (``names``,
    :func:`_names`), in that order, and the servo delay (``tau_<axis>``) when the flight's fit searched it."""
    values = {k: float(fit.params[k]) for k in names[:2]}
    if searched_delay:
        values[f"tau_{axis}"] = float(fit.delay)
    return values


def _searched_delay(ident, axis: str) -> bool:
    """Axis ``axis``' servo delay was found by the search (not given by the user): the check measures its bias."""
    return fitted_timing(ident, axis)["delay"] in ("auto", "detect")


def _replicate(ident, loops: dict, checked: dict, seed: int, b: int, fitted: tuple | None = None) -> dict:
    """Fly replicate ``b`` of every checked axis and fit it as the flight was, the axes of ``fitted`` only (default
    all; every checked axis is flown, so that an axis' flights are the same draws whichever others are fitted):
    ``{axis: {name: value}}``."""
    rng = np.random.default_rng([seed, b])
    out = {}
    for axis, names in checked.items():
        flights = flown_flights(ident, axis, loops[axis], rng)
        if fitted is not None and axis not in fitted:
            continue
        try:
            again = axis_refit(ident, axis, names[2], flights, ident.axes_[axis].input_hold,
                               **fitted_timing(ident, axis))
        except IdentifiabilityError as exc:  # the simulated loop left the stick still, or the fit refused it
            out[axis] = str(exc)
            continue
        out[axis] = checked_values(again.axes_[axis], axis, names, _searched_delay(ident, axis))
    return out


def check_settings(mode, n_flights) -> None:
    """Raise ``ValueError`` unless ``mode`` is None or one of :data:`CLOSED_LOOP_MODES` and ``n_flights`` a whole
    number >= 2 (a mean and its error): an estimator's ``closed_loop`` and ``closed_loop_flights``."""
    if mode not in (None,) + CLOSED_LOOP_MODES:
        raise ValueError(f"closed_loop must be None or one of {CLOSED_LOOP_MODES}, got {mode!r}")
    if not (isinstance(n_flights, (int, np.integer)) and not isinstance(n_flights, bool) and n_flights >= 2):
        raise ValueError(f"closed_loop_flights must be a whole number >= 2, got {n_flights!r}")


def check_closed_loop(ident, n_flights: int = N_FLIGHTS, seed: int = 0, mode: str = "auto",
                      workers=None, max_flights: int | None = None) -> ClosedLoopCheck:
    """Check a fitted :class:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier` in its flights'
    closed loop (module docstring). Does not change ``ident``; :func:`apply_check` does.

    The flights are flown in batches of ``n_flights``, up to ``max_flights`` (default three batches), another
    batch while a bias is neither clearly there nor clearly not (:data:`CONCLUSIVE`); an axis whose damping is
    clearly not biased the loop's way is not fitted again (its flights are still flown, so that the others' are
    the same draws).

    Raises
    ------
    ValueError
        ``n_flights`` below 2 or ``mode`` not in :data:`CLOSED_LOOP_MODES`.
    """
    import time

    if mode is None:
        raise ValueError(f"closed_loop must be one of {CLOSED_LOOP_MODES} to run the check, got None")
    check_settings(mode, n_flights)
    t0 = time.perf_counter()
    max_flights = 3 * n_flights if max_flights is None else max(int(max_flights), n_flights)
    results, checked = {}, {}
    data = {axis: ident._fitted_data(AXES.index(axis), fit, ident.flights_, 0) for axis, fit in ident.axes_.items()}
    reasons = {axis: _skip_reason(ident, AXES.index(axis), fit, data[axis]) for axis, fit in ident.axes_.items()}
    loops, signals = _loops(ident, {axis: data[axis] for axis, why in reasons.items() if not why})
    for axis, fit in ident.axes_.items():
        if reasons[axis]:
            results[axis] = AxisCheck(axis, False, reasons[axis])
            continue
        pilots = tuple(loop.pilot.describe(loop.dt) for loop in loops[axis])
        why = unflyable(loops[axis], signals[axis])
        results[axis] = AxisCheck(axis, not why, why, pilots, loop_ticks=max(loop.ticks for loop in loops[axis]))
        if not why:
            checked[axis] = _names(ident, AXES.index(axis), fit, data[axis])
    runs, fitting = [], tuple(checked)
    while fitting and len(runs) < max_flights:
        start = len(runs)
        batch = range(start, min(start + n_flights, max_flights))
        runs += map_axes(lambda b: _replicate(ident, loops, checked, seed, b, fitting), batch, workers)
        for axis in list(checked):
            failed = next((run[axis] for run in runs if isinstance(run.get(axis), str)), None)
            if failed is not None:
                results[axis] = replace(results[axis], checked=False,
                                        reason=f"a flight flown by the check could not be fitted ({failed})")
                del checked[axis]
        biases = {a: b for a, b in _biases(ident, checked, runs).items() if a in fitting}
        if not _inconclusive(biases):
            break
        # an axis whose damping shows no bias the loop's way is not fitted again while another is in doubt:
        # nothing of it would be removed; one whose bias is clear is, its correction the surer for it
        fitting = tuple(a for a in biases if _damping_z(biases[a][1]) > CONCLUSIVE[0])
    for axis, (fitted, rel) in _biases(ident, checked, runs).items():
        bias = {k: float(r.mean()) for k, r in rel.items()}
        se = {k: float(r.std(ddof=1) / np.sqrt(r.size)) for k, r in rel.items()}
        gain, damping = checked[axis][:2]
        loops_bias = loops_direction(bias, se, gain, damping, results[axis].loop_ticks)
        corrected = {k: (v * (1.0 - bias[k]) if mode == "auto" and loops_bias and abs(bias[k]) > SIGNIFICANCE * se[k]
                         else v) for k, v in fitted.items()}
        results[axis] = replace(results[axis], fitted=fitted, bias=bias, bias_se=se, corrected=corrected,
                                loops_direction=loops_bias, flights=int(rel[damping].size))
    return ClosedLoopCheck(results, len(runs), int(seed), mode, time.perf_counter() - t0)


def against_the_loop(bias: dict, se: dict, gain: str, damping: str, ticks: int = 1) -> str:
    """What points against the loop's way (module docstring), empty when nothing does: the gain's magnitude
    significantly up, or the damping significantly down (``bias``, ``se``: relative, by parameter name). A flight
    controller's loop flown at its own rate (``ticks`` > 1) reads as damping alone: its gain's bias is a few tenths
    of a per cent either way (the bench's autopilot 4x faster than its log: -1.4 to +0.5 % beside dampings +14 to
    +17 %), so only the damping's direction counts there."""
    if ticks == 1 and bias[gain] >= SIGNIFICANCE * se[gain]:
        return "the gain's magnitude up beyond its noise"
    if bias[damping] <= -SIGNIFICANCE * se[damping]:
        return "the damping down beyond its noise"
    return ""


def loops_direction(bias: dict, se: dict, gain: str, damping: str, ticks: int = 1) -> bool:
    """The biases point the loop's way: nothing :func:`against_the_loop`."""
    return not against_the_loop(bias, se, gain, damping, ticks)


def _biases(ident, checked: dict, runs: list) -> dict:
    """Per checked axis, its fitted gain and damping (in that order; the delay after them when searched) and their
    relative errors over the ``runs`` that fitted it."""
    out = {}
    for axis, names in checked.items():
        fitted = checked_values(ident.axes_[axis], axis, names, _searched_delay(ident, axis))
        out[axis] = fitted, {k: np.array([run[axis][k] / v - 1.0 for run in runs if axis in run])
                             for k, v in fitted.items()}
    return out


def _inconclusive(biases: dict) -> bool:
    """True while some damping's bias points the loop's way (up) by between :data:`CONCLUSIVE` standard errors
    of its mean: the next batch of flights is flown (a damping biased down is not removed whatever its size;
    the gains' biases are a few tenths of a per cent: they do not decide it)."""
    return any(CONCLUSIVE[0] < _damping_z(rel) < CONCLUSIVE[1] for _, rel in biases.values())


def _damping_z(rel: dict) -> float:
    """The damping's mean relative error over its standard error, from an axis' relative errors (:func:`_biases`)."""
    r = list(rel.values())[1]  # the damping (_biases)
    return float(r.mean() / max(r.std(ddof=1) / np.sqrt(r.size), 1e-300))


def apply_check(ident, check: ClosedLoopCheck, which: str = "corrected") -> None:
    """Set ``ident``'s values after the check (:attr:`AxisCheck.corrected`; ``which="fitted"``: back to those
    before it): the axis fits' parameters and servo delay, the damping in their search vectors (the smoother and
    the wind draws use it) and ``params_``. The fitted values stay in ``check``."""
    for axis, c in check.axes.items():
        if c.removed:
            set_axis_values(ident, axis, getattr(c, which))


def set_axis_values(ident, axis: str, values: dict) -> None:
    """Give axis ``axis`` of ``ident`` the checked ``values`` (:func:`checked_values`' keys: the gain, the damping,
    in that order, and ``tau_<axis>`` when present): its fit's parameters and servo delay, the damping in its
    search vector (the smoother and the wind draws use it) and ``params_``."""
    fit = ident.axes_[axis]
    chosen = dict(values)
    delay = chosen.pop(f"tau_{axis}", fit.delay)
    params = {**fit.params, **chosen}
    state = np.array(fit.state, dtype=float, copy=True)
    state[0] = list(chosen.values())[1]  # the damping (gain first: _biases); the search vector starts with it
    ident.axes_[axis] = replace(fit, params=params, state=state, delay=delay)
    ident.params_ = ident.params_.with_values(**chosen, **{f"tau_{axis}": delay})
