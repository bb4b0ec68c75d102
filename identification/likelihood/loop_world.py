"""The closed loop's world (:mod:`identification.likelihood.closed_loop`): which axes of a fitted flight can be
flown again, the loop of each as its flight had it, and its flights.

The loop of an axis is the identified model (eqs. 18/21 with the fitted gust model of eqs. 41-42, exactly
discretised; a servo delay or lag through the servo of eq. 31) under the pilot fitted to its logged sticks
(:mod:`identification.likelihood.pilot_model`), who sees the simulated aircraft his reaction delay late, his sweeps
and jitter replayed. A flight controller whose loop runs faster than its log (:func:`~identification.validation.fit_warnings.loop_ticks`) is flown at its
own rate instead: the model discretised over one of its ticks with the command held, its law reading the state a
tick before each command, the rest of its command (the pilot's setpoint through it) moving linearly between the
logged samples, and the log keeping every ``ticks``-th tick. Inside each logged sample such a loop corrects the
aircraft, and a model driven by the sampled commands reads that as damping (the bench's autopilot 4x faster than
its 100 Hz log: dampings 20-45 % high; docs/method.md, "A flight controller faster than its log"); flown at its
rate, the world makes that bias too, and the check removes it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType, SimpleNamespace

import numpy as np

from heli_core.terms import AXES, STICK_ROW

from ..flight import Flight
from ..validation.fit_warnings import (gyro_filter, log_ticks, loop_ticks, unstated_filter,  # what the log states
                                      without_gyro_filter)
from ..validation.model_verdict import bound_side
from .axis_likelihood import MIN_SERVO_DELAY, AxisLikelihood
from .pilot_model import AxisSignals, PilotModel, fit_pilot, reaction_delay
from .state_space import covariance_root, discrete_model, rts_smooth, servo_increments, servo_step, wind_block

SETTLE = 3000
"""Samples the simulated loop flies before the record starts (the gusts and the pilot settle)."""

MIN_NOISE_SHARE = 0.02
"""An axis whose fitted gyro noise is below this share of the rate's standard deviation is not checked: the
bias needs a noisy gyro (none measured without one, docs/method.md), and a log filtered before it was written
has no noise for the pilot fit to tell a pilot's sticks from a controller's by."""

MAX_CORNER_SHARE = 0.9
"""A stated gyro filter is flown where its corner is below this share of the loop tick's Nyquist rate."""

MAX_RATE_RATIO = 2.0
"""A simulated loop whose rate's standard deviation is further than this factor from the logged one's is not
the flight's loop (the pilot's fit failed); the axis is then not checked."""


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
    # (b0, b1, b2, a1, a2) of the gyro's low-pass at a tick (gyro_biquad); empty: none flown
    gyro_filter: np.ndarray = field(default_factory=lambda: np.zeros(0))


def axis_names(ident, a: int, fit, data) -> tuple[str, str, tuple]:
    """(gain name, damping name, the terms fitted) of axis ``a`` as ``fit`` was fitted (``data`` its
    likelihood's :class:`~identification.likelihood.axis_likelihood.AxisData`)."""
    kept = ident._kept_terms(a, fit)
    own = [n for n in data.names if "@" not in n]
    return own[data.servo_row], ident.axis_problem(a, kept, ident.flights_, 0).damping_name, kept


def skip_reason(ident, a: int, fit, data) -> str:
    """Why axis ``a`` (``fit``, its likelihood's ``data``) is not flown, or empty."""
    damping = axis_names(ident, a, fit, data)[1]
    side = bound_side(fit.params[damping], ident.damping_bounds) if damping else None
    if side is not None:  # the model verdict names it; nothing downstream is built on it here
        return f"its damping {damping} is at the {side} bound of the search (the data did not place it)"
    share = fit.noise_std / max(float(np.std(np.concatenate(data.y))), 1e-300)
    fast = log_ticks(ident.flights_, data.dt) > 1  # a controller's loop: its bias needs no noise (docs/method.md)
    if share < MIN_NOISE_SHARE and not fast:
        return (f"the gyro shows next to no white noise ({100 * share:.2g} % of the rate's std; a log filtered before "
                "it was written): there is nothing in the rate a pilot could see better than it")
    if fast and unstated_filter(ident.flights_):
        return ("its gyro was low-passed before it was logged (the fit's rate was lowered for it) and the log does "
                "not state the filter's corner, which the flight controller's law reads through: the loop's world "
                "cannot fly it (state it: --gyro-filter HZ, ArduPilot's INS_GYRO_FILTER)")
    if fit.delay < -MIN_SERVO_DELAY:
        return ("its stick was found logged late (a negative alignment): the loop flies a servo, not a log's "
                "timing")
    if data.causal_rows:
        return "the axis' model reads other axes' rates; the one-axis loop does not fly them"
    if data.servo_row is None:
        return "no stick term"
    return ""


def gyro_biquad(flight, tick: float) -> np.ndarray:
    """``(b0, b1, b2, a1, a2)`` of the 2-pole Butterworth low-pass ``flight``'s log states its gyro passed
    (:func:`~identification.validation.fit_warnings.gyro_filter`), designed at the loop's tick ``tick`` [s] as the
    firmware designs it (bilinear, ArduPilot's ``LowPassFilter2p``); empty where none is stated or its corner is
    not below the tick's Nyquist rate (nothing the world's ticks could fly)."""
    corner = gyro_filter(flight.metadata)
    if corner is None or corner >= MAX_CORNER_SHARE * 0.5 / tick:
        return np.zeros(0)
    from scipy.signal import butter

    b, a = butter(2, corner, fs=1.0 / tick)
    return np.array([b[0], b[1], b[2], a[1], a[2]], dtype=float)


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
        if has_servo(fit) or data.corner(i) is not None:  # the stick's path, exactly as the likelihood has it
            direct = theta[row] * servo_increments(data.servo_sticks[i], model[0], max(fit.delay, 0.0), data.dt,
                                                   fit.input_hold, fit.lag, data.corner(i))
            states = rts_smooth(data.y[i], other, *model, data.dt, fit.input_hold, fit.wind["model"], direct)
        else:
            states = rts_smooth(data.y[i], other + theta[row] * regs[row], *model, data.dt, fit.input_hold,
                                fit.wind["model"])
        signals.append(AxisSignals(stick, np.unwrap(flight.attitude[a]), states[0], data.y[i], cw @ states[1:],
                                   data.dt))
        pieces.append((Ad, g0, g1, root, gain, other, servo))
    return signals, pieces


def axis_loops(ident, data: dict) -> tuple[dict, dict]:
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
        # the filter runs at the controller's loop: flown where the world flies that loop
        biquad = gyro_biquad(flight, data[axes[0]].dt / ticks) if ticks > 1 else np.zeros(0)
        # a controller faster than its log: its law reads the state the sample it commands (a tick before it)
        d = 0 if ticks > 1 else reaction_delay([built[axis][0][i] for axis in axes])
        for axis in axes:
            sig = built[axis][0][i]
            Ad, g0, g1, root, gain, other, servo = built[axis][1][i]
            if ticks > 1:
                Ad, g0, g1, root, servo = _tick_pieces(ident.axes_[axis], data[axis], ticks)
            loops[axis].append(_AxisLoop(Ad, g0, g1, root, ident.axes_[axis].noise_std, gain, other,
                                         fit_pilot(sig, d), float(sig.angle[0]), sig.dt, servo, ticks, biquad))
    return loops, {axis: built[axis][0] for axis in axes}


_COMPILED = {}


def _compiled_fly():
    """:func:`_fly` compiled by numba, once per process (numba imported only when a check runs)."""
    if "fly" not in _COMPILED:
        import numba

        _COMPILED["fly"] = numba.njit(cache=True)(_fly)
    return _COMPILED["fly"]


def _fly(Ad, g0, g1, kicks, noise, gain, other, delay, coef, angle_mean, rest, dt, angle0, servo,
         biquad):  # pragma: no cover
    """The loop over samples: returns the gyro, the angle and the sticks (each (n,)).

    Where ``biquad`` is not empty (:func:`gyro_biquad`) the rate passes that low-pass before the law reads it and the
    gyro returned is it (``noise`` is then the filtered noise).

    ``kicks`` (m, n) are the process noise, ``noise`` (n,) the gyro's; the stick drives the rate through
    ``servo`` (:attr:`_AxisLoop.servo`, its state settled on the trim), the other torque through ``g0``, ``g1``;
    ``other`` and ``rest`` are padded with their first value and zeros over the settling samples. The pilot's
    stick at k reads the angle (about ``angle_mean``), the rate, the gyro's noise and the angle's integral
    ``delay`` samples before, plus ``rest[k]``, clipped to the stick's range
    (:class:`~identification.likelihood.pilot_model.PilotModel`)."""
    m, n = Ad.shape[0], rest.size
    filtered = biquad.size == 5
    s0 = s1 = 0.0
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
        if filtered:  # transposed direct form II, from rest: the settling samples start it
            raw = x[0]
            rate[k] = biquad[0] * raw + s0
            s0 = biquad[1] * raw - biquad[3] * rate[k] + s1
            s1 = biquad[2] * raw - biquad[4] * rate[k]
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
        angle[j] = angle[k] + 0.5 * dt * (x[0] + y[0])  # the true rate's
        x = y
    return rate + noise, angle, u


def _between(x: np.ndarray, m: int) -> np.ndarray:
    """``x`` at ``m`` ticks a sample, linearly interpolated between its samples (the last held)."""
    if m == 1:
        return x
    ticks = np.arange(x.size * m) / m
    return np.interp(ticks, np.arange(x.size), x)


def fly_loop(loop: _AxisLoop, rng: np.random.Generator) -> tuple:
    """One simulated flight of ``loop``: gyro, angle and stick at the log's samples, each (n,).

    A loop of ``loop.ticks`` > 1 is a flight controller's, flown at its own rate: its law reads the state a tick
    before each tick's command, the rest of its command (the setpoint it adds) moves linearly between the logged
    samples (held, the bench's autopilot 4x faster than its log measured +5 / +6 / +4 % where its flights read
    +22 / +16 / +19 %: docs/method.md), the other torque is held over each, and the log keeps every ``ticks``-th
    tick (the command logged is the one its sample starts with)."""
    m = loop.ticks
    n = (loop.pilot.rest.size + SETTLE) * m
    kicks = loop.noise_root @ rng.standard_normal((loop.Ad.shape[0], n))
    noise = loop.noise_std * rng.standard_normal(n)
    if loop.gyro_filter.size:  # the noise filtered as the rate is, its std at the log's as fitted
        noise = _filtered_noise(noise, loop.gyro_filter, m)
    rest = _between(np.concatenate([np.zeros(SETTLE), loop.pilot.rest]), m)
    other = np.repeat(np.concatenate([np.full(SETTLE, loop.other[0]), loop.other]), m)
    p = loop.pilot
    gyro, angle, u = _compiled_fly()(loop.Ad, loop.g0, loop.g1, kicks, noise, loop.gain, other, max(1, p.delay * m),
                                     p.coefficients, p.angle_mean, rest, loop.dt / m, loop.angle0, loop.servo,
                                     loop.gyro_filter)
    return gyro[SETTLE * m::m], angle[SETTLE * m::m], u[SETTLE * m::m]


def _filtered_noise(white: np.ndarray, biquad: np.ndarray, every: int) -> np.ndarray:
    """``white`` gyro noise at the loop's ticks through ``biquad`` (:func:`gyro_biquad`), scaled so that its std
    is ``white``'s: the noise the fit measured is the filtered one, seen every ``every``-th tick."""
    from scipy.signal import lfilter

    out = lfilter(biquad[:3], np.r_[1.0, biquad[3:]], white)
    scale = np.std(white) / max(float(np.std(out[::every])), 1e-300)
    return out * scale


def _implausible(loop: _AxisLoop, logged: AxisSignals) -> str:
    """Why the simulated loop is not the flight's (empty when it is): a pilot fitted to the sticks that does
    not hold the identified model drives the simulated rates far from the logged ones or the sticks to their
    stops."""
    gyro, _, u = fly_loop(loop, np.random.default_rng(0))
    ratio = float(np.std(gyro) / max(np.std(logged.gyro), 1e-12))
    stops = float(np.mean(np.abs(u) >= 1.0))
    logged_stops = float(np.mean(np.abs(logged.stick) >= 1.0))
    if not np.isfinite(ratio) or not 1.0 / MAX_RATE_RATIO <= ratio <= MAX_RATE_RATIO or stops > logged_stops + 0.02:
        return (f"the pilot fitted to the sticks does not fly the identified model as the flight went (simulated "
                f"rate std x{ratio:.2f} the logged, sticks at their stops {100 * stops:.0f} % of the time)")
    return ""


def unflyable(loops: list, signals: list) -> str:
    """Why an axis' ``loops`` (one per flight, beside the logged ``signals`` they were fitted to) are not the
    loop the check models, or empty: sticks that follow the logged gyro (:func:`on_logged_sensors`), or a pilot who
    does not fly the model as the flight went (:func:`_implausible`)."""
    if on_logged_sensors(loops):
        return ("its sticks follow the logged gyro's noise (a loop closed on the logged sensors, as a flight "
                "controller's): the likelihood conditioned on them is the right one")
    return implausible(loops, signals)


def implausible(loops: list, signals: list) -> str:
    """Why an axis' simulated ``loops`` are not the flight's (:func:`_implausible` of the first that is not), or
    empty."""
    return next(filter(None, (_implausible(lp, sig) for lp, sig in zip(loops, signals))), "")


def on_logged_sensors(loops: list) -> bool:
    """Some of an axis' ``loops`` closes on the sensors the log holds, at the log's rate (a flight controller's):
    the likelihood, conditioned on its sticks, has no bias of it to check. Its world is still the flight's, and the
    check flies it for the integral method's reading alone (:func:`~.closed_loop.check_closed_loop`)."""
    return any(loop.pilot.flies_on == "sensors" and loop.ticks == 1 for loop in loops)


def world_loops(world, axes) -> tuple[dict, str]:
    """The loops of ``world``'s axes ``axes`` (an estimator, or a world of :func:`with_fits`) as the check flies
    them (:func:`axis_loops`), and why they cannot be flown, empty when they can: the first of the check's own reasons
    not to fly an axis (:func:`skip_reason`, :func:`unflyable`) that one of them has."""
    data = {axis: world._fitted_data(AXES.index(axis), world.axes_[axis], world.flights_, 0) for axis in axes}
    why = next(filter(None, (skip_reason(world, AXES.index(axis), world.axes_[axis], data[axis]) for axis in axes)),
               "")
    if why:
        return {}, why
    loops, signals = axis_loops(world, data)
    return loops, next(filter(None, (unflyable(loops[axis], signals[axis]) for axis in axes)), "")


def flown_flights(ident, axis: str, loops: list, rng: np.random.Generator) -> list:
    """``ident``'s flights with axis ``axis``' gyro, attitude and stick replaced by one simulated flight of each
    of its ``loops`` (one per fitted flight); the other axes as logged. A loop that flew no gyro filter (a pilot's,
    at the log's rate) logs a white gyro: its flight states no filter, so that its fits do not move one to the
    input side (:mod:`~identification.likelihood.gyro_path`) that the world never flew."""
    a = AXES.index(axis)
    flights = []
    for flight, loop in zip(ident.flights_, loops):
        gyro, angle, u = fly_loop(loop, rng)
        rates, attitude, sticks = flight.rates.copy(), flight.attitude.copy(), flight.sticks.copy()
        rates[a], attitude[a], sticks[STICK_ROW[a]] = gyro, np.angle(np.exp(1j * angle)), u
        meta = {k: v for k, v in flight.metadata.items() if k not in ("units_check", "vibration_lines")}
        if not loop.gyro_filter.size:  # the world's gyro is white: no filter for its fits to move to the input
            meta = without_gyro_filter(meta)
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
