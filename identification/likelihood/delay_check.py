"""A servo delay the closed loop's world makes too: tested by flying the delay-free model under the pilot.

``delay="detect"`` keeps a servo delay where the likelihood ratio over the undelayed fit passes
:data:`~identification.likelihood.estimator.MIN_LR_DELAY` (20; a one-sample servo delay scored 46-370 on 300 s
bench flights, effect-free ones 0-4). A pilot who sees the aircraft behind a noisy gyro gives the likelihood a
second optimum: on the sluggish aircraft with held sticks, 2 of 10 effect-free flights put a 11.7 ms delay there
at LR 23-24, the damping with it +44-53 %, and the closed-loop check could not fly the axis (its loop carries
no delay). Flown again delay-free under the pilot fitted to the sticks, the same aircraft's world made that
optimum on 1 of 10 of its flights (LR 23.0 at 11.8 ms): the delay is the loop's, not the servo's.

So, for an axis whose delay was found by the search (not given by the user) and whose sticks a pilot who sees
the aircraft moved: the axis is fitted delay-free (at the log's hold), flown ``n_flights`` times under the pilot,
and each flight is fitted without a delay and with the delay profiled. Where the delay-free world reproduces the
flight's delay — a flight within one sample of it at a likelihood ratio of at least :data:`REPRODUCED_SHARE` of
the flight's — the delay is the loop's: the axis takes its delay-free fit. Where it does not, the delay stands
(real 10 ms delays scored LR 32-107 behind the same gyro, 46-370 on the bench's flights; the loop's optimum
21-30), and the closed-loop check flies the axis through it, removing the bias the loop gives the damping and
the delay. The test can only remove a delay its world reproduces; one it misses stays as ``delay="detect"``
found it, and is checked.

A flight controller whose loop runs faster than its log (:func:`~identification.validation.fit_warnings.loop_ticks`)
moves its command inside each logged sample, and the likelihood, which sees the command once a sample, reads that
motion as a servo's timing: a delay or a lag of a few milliseconds. On the bench's autopilot 4x faster than its log,
effect-free flights put a yaw delay of 4.5-6.1 ms at LR 25-43 on 100 Hz logs; on 200 Hz logs (the sluggish aircraft,
eight flights) delays of 3.7-6.8 ms and lags of 6.7-7.3 ms, its dampings +53 to +84 % with them and +16 to +39 % on
the axes without one; fitted with no timing, the check brought them within 9.7 %. The check's world flies the loop
without that motion's signature: it made none of those delays (0 of 16 flights) or lags (0 of 8). Neither the
autopilot's D-term low-pass nor its sensors make it: a PD on the true state, one tick late, makes 5.5-8.5 ms delays
too (docs/method.md, "A servo timing a fast loop makes"). A timing (delay plus lag) found within
:data:`LOOP_TIMING` (or one logged sample, if longer) of such a flight is therefore the loop's without a world flown
(:attr:`DelayCheck.inside_sample`), also where the check then cannot fly the axis (the bench's autopilot behind a
gyro filter the log does not state, fitted at 50 Hz: its dampings +12 to +15 % with its 5 ms delay, -7 to -14 %
without it, and a delay a quarter of the sample long is one no fixed-step simulation at the log's rate can follow:
the model kept with it diverged in the forward simulation at 0.1 s); a longer one (the catalogue's servos of 30-80
ms) is tested as above, a delay by the world, a lag as the search found it. A real servo faster than
:data:`LOOP_TIMING` behind such a loop cannot be told from the loop's own motion in the log, and is not kept.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from heli_core.terms import AXES

from ..errors import IdentifiabilityError
from .axis_likelihood import MIN_SERVO_DELAY
from .axis_pool import map_axes
from .closed_loop import axis_refit
from ..validation.fit_warnings import log_ticks
from .loop_world import flown_flights, with_fits, world_loops

N_DELAY_FLIGHTS = 16
"""Flights of the delay-free world flown per delay tested (the loop's optimum appeared on 1 of 10)."""

REPRODUCED_SHARE = 0.8
"""A flight of the delay-free world reproduces the flight's delay when its likelihood ratio reaches this share of
the flight's, within one sample of its delay. The delay-free world's loop optima sit at LR 21-27 (sluggish
aircraft, noisy gyro: 20.9-22.6 for a flight whose own loop-made delay scored 22.7, 21.8-27.3 for one whose real
10 ms delay scored 45.4, which half its LR had taken for the loop's)."""

LOOP_TIMING = 0.010
"""A servo timing (delay plus lag) within this [s], or within one logged sample where that is longer, of a flight
controller's loop faster than its log is the loop's (module docstring: the bench's loops made 3.7-8.5 ms on 100 and
200 Hz logs; one logged sample was the rule until 2026-12-05, and the 200 Hz logs' 5.4-7.3 ms passed it)."""


@dataclass(frozen=True)
class DelayCheck:
    """One axis' servo delay tested in the delay-free closed loop.

    Attributes
    ----------
    axis : str
    delay : float
        The delay the fit had found [s].
    flight_lr : float or None
        Its likelihood ratio over the delay-free fit, ``2 (nll_none - nll_delay)``, as the check fits.
    world : list of (float, float)
        Per flight of the delay-free world, the delay profiled and its likelihood ratio.
    loops : bool
        The world reproduced the delay: it is the loop's.
    removed : bool
        It was removed from the fit (:func:`remove_delay`, the check's mode "auto").
    reason : str
        Why it was not tested, when it was not.
    dt : float
        The log's sample interval [s] (a delay within one of the flight's is the same delay).
    inside_sample : int
        Ticks of a flight controller's loop per logged sample where the timing lies within :func:`loop_timing` of a
        loop faster than the log (module docstring): the loop's without a world flown; else 0.
    lag : float
        The servo lag the fit had found with the delay [s] (0: none; a lag is tested only as the loop's).
    """

    axis: str
    delay: float
    flight_lr: float | None = None
    world: list = field(default_factory=list)
    loops: bool = False
    reason: str = ""
    dt: float = 0.01
    removed: bool = False
    fit: object = field(default=None, repr=False, compare=False)  # the delay-free fit
    inside_sample: int = 0
    lag: float = 0.0

    def describe(self) -> dict:
        """JSON-ready."""
        return {"axis": self.axis, "delay_s": self.delay, "flight_lr": self.flight_lr,
                "world": [list(w) for w in self.world], "loops": self.loops, "removed": self.removed,
                "reason": self.reason, "inside_sample": self.inside_sample, "lag_s": self.lag}

    def line(self) -> str:
        """One line for a report or the terminal."""
        what = f"{self.axis}: servo delay {1000 * self.delay:.1f} ms"
        if self.lag > 0.0:
            what = f"{self.axis}: servo lag {1000 * self.lag:.1f} ms" + (
                f" behind a delay of {1000 * self.delay:.1f} ms" if self.delay > MIN_SERVO_DELAY else "")
        if self.reason:
            return f"{what} not tested in the loop's world ({self.reason})"
        if self.inside_sample:
            verdict = "the axis is fitted without it" if self.removed else "reported, kept"
            bound = loop_timing(self.dt)
            within = (f"{1000 * bound:.0f} ms ({bound / self.dt:.3g} logged "
                      f"sample{'s' if bound > self.dt * (1 + 1e-6) else ''})")
            return (f"{what} (LR {self.flight_lr:.1f}) lies within {within} of a flight controller's loop "
                    f"{self.inside_sample}x faster than the log, whose command moves inside each sample where the "
                    f"log does not see it, and the likelihood reads that as a servo's timing: the loop's ({verdict}; "
                    f"a servo this fast cannot be told from it in this log: if one is known, --delay SECONDS fits it)")
        seen = sum(1 for d, lr in self.world if self.reproduces(d, lr))
        verdict = ("not reproduced: it stands" if not self.loops else
                   "the loop's: the axis is fitted without it" if self.removed else "the loop's (reported, kept)")
        return (f"{what} (LR {self.flight_lr:.1f}) made by {seen} of {len(self.world)} flights of the delay-free "
                f"loop: {verdict}")

    def reproduces(self, delay: float, lr: float) -> bool:
        """A world's flight with ``delay`` at likelihood ratio ``lr`` makes the flight's delay: within one sample
        of it, at :data:`REPRODUCED_SHARE` of its likelihood ratio or more."""
        return abs(delay - self.delay) <= self.dt * (1.0 + 1e-6) and lr >= REPRODUCED_SHARE * self.flight_lr


def loop_timing(dt: float) -> float:
    """The longest servo timing (delay plus lag) [s] a flight controller's loop faster than its log of samples ``dt``
    apart is taken to make (:data:`LOOP_TIMING`, or one sample where that is longer)."""
    return max(LOOP_TIMING, float(dt))


def _within_loop_timing(fit, dt: float) -> bool:
    """An axis fit's servo timing, its delay (a negative alignment counts none) plus its lag, lies within
    :func:`loop_timing` of a log of samples ``dt`` apart: what a flight controller faster than it makes."""
    return max(float(fit.delay), 0.0) + float(fit.lag) <= loop_timing(dt) * (1.0 + 1e-6)


def delay_candidates(ident) -> list:
    """The axes whose servo delay the search found (``delay="detect"`` or ``"auto"``), without a lag; and, where
    every flight is a flight controller's logged slower than its loop (:func:`~identification.validation.fit_warnings.log_ticks`), the axes
    whose searched delay or lag adds up to no more than :func:`loop_timing` (the loop's, module docstring)."""
    modes, flights = ident._delays(), getattr(ident, "flights_", ())
    fast = bool(flights) and log_ticks(flights) > 1
    dt = float(flights[0].dt) if flights else 0.0
    out = []
    for axis, fit in ident.axes_.items():
        if modes[AXES.index(axis)] not in ("auto", "detect"):
            continue
        timed = fit.delay > MIN_SERVO_DELAY or fit.lag > 0.0
        if (fit.delay > MIN_SERVO_DELAY and fit.lag == 0.0) or (fast and timed and _within_loop_timing(fit, dt)):
            out.append(axis)
    return out


def _lr(ident, axis: str, kept: tuple, flights: list, hold, with_fit: bool = True) -> tuple[float, float, object]:
    """(delay profiled, ``2 (nll_none - nll_delay)``, the delay-free fit or None) of axis ``axis`` over
    ``flights``. Without ``with_fit`` the delay-free likelihood is the profile's own undelayed fit
    (:attr:`~identification.likelihood.axis_fit.MLAxisFit.undelayed_nll`: the same searches, the same number to
    1e-11), not a second fit: a world's flights need only the ratio."""
    free = axis_refit(ident, axis, kept, flights, hold, delay="auto").axes_[axis]
    none = axis_refit(ident, axis, kept, flights, hold).axes_[axis] if with_fit else None
    nll_none = none.nll if none is not None else free.undelayed_nll
    return float(free.delay), float(max(2.0 * (nll_none - free.nll), 0.0)), none


def check_delay(ident, axis: str, min_lr: float, n_flights: int = N_DELAY_FLIGHTS, seed: int = 0,
                workers=None) -> DelayCheck:
    """Test axis ``axis``' servo delay in the delay-free closed loop (module docstring); ``min_lr`` is the
    likelihood ratio at which the estimator keeps a delay (the flight's own refit must keep it too). Does not
    change ``ident``; :func:`remove_delay` does."""
    a, fit = AXES.index(axis), ident.axes_[axis]
    decision = getattr(ident, "hold_decision_", None) or {}
    hold = decision.get("fraction", fit.input_hold)  # the log's hold where decided, else the axis' own
    dt = float(ident.flights_[0].dt)
    kept = ident._kept_terms(a, fit)
    ticks = log_ticks(ident.flights_, dt)
    if ticks > 1 and _within_loop_timing(fit, dt):
        return _the_loops_timing(ident, axis, kept, hold, ticks)
    try:
        flight = _lr(ident, axis, kept, ident.flights_, hold)
    except IdentifiabilityError as exc:
        return DelayCheck(axis, fit.delay, reason=f"the axis could not be fitted without it ({exc})", dt=dt)
    if flight[1] < min_lr:
        return DelayCheck(axis, fit.delay, flight[1], reason=f"refitted at the log's hold the flight itself does not "
                          f"keep it (LR {flight[1]:.1f})", dt=dt)
    null_fit = replace(flight[2], dropped=fit.dropped)
    world = with_fits(ident, {axis: null_fit})
    loops, why = world_loops(world, (axis,))  # the closed-loop check's own reasons not to fly an axis
    if why:
        return DelayCheck(axis, fit.delay, reason=why, dt=dt)

    def one(b):
        flights = flown_flights(world, axis, loops[axis], np.random.default_rng([seed, b, 7]))
        try:
            return _lr(ident, axis, kept, flights, hold, with_fit=False)[:2]
        except IdentifiabilityError as exc:
            return str(exc)

    runs = map_axes(one, range(n_flights), workers)
    refused = next((r for r in runs if isinstance(r, str)), None)
    if refused is not None:
        return DelayCheck(axis, fit.delay, flight[1], reason=f"a flight of the loop could not be fitted ({refused})",
                          dt=dt)
    check = DelayCheck(axis, flight[0], flight[1], [tuple(r) for r in runs], dt=dt, fit=null_fit)
    return replace(check, loops=any(check.reproduces(d, lr) for d, lr in check.world))


def _the_loops_timing(ident, axis: str, kept: tuple, hold, ticks: int) -> DelayCheck:
    """Axis ``axis``' timing, within :func:`loop_timing` of a flight controller's loop ``ticks`` times faster than
    its log, taken for the loop's (module docstring): the axis fitted without a delay or lag at the log's ``hold``,
    and the likelihood ratio the timing had over it (as fitted, at that hold)."""
    fit, dt = ident.axes_[axis], float(ident.flights_[0].dt)
    try:
        none = axis_refit(ident, axis, kept, ident.flights_, hold).axes_[axis]
    except IdentifiabilityError as exc:
        return DelayCheck(axis, fit.delay, reason=f"the axis could not be fitted without it ({exc})", dt=dt,
                          lag=fit.lag)
    lr = float(max(2.0 * (none.nll - fit.nll), 0.0))
    return DelayCheck(axis, max(float(fit.delay), 0.0), lr, loops=True, dt=dt,
                      fit=replace(none, dropped=fit.dropped), inside_sample=ticks, lag=float(fit.lag))


def remove_delay(ident, check: DelayCheck) -> DelayCheck:
    """Give axis ``check.axis`` of ``ident`` its delay- and lag-free fit where the delay was
    the loop's (``params_`` follows: its delay and lag 0). Returns ``check``, marked ``removed`` when it was."""
    if not check.loops:
        return check
    fit = check.fit
    ident.axes_[check.axis] = fit
    ident.params_ = ident.params_.with_values(**fit.params, **{f"tau_{check.axis}": 0.0, f"lag_{check.axis}": 0.0})
    return replace(check, removed=True)
