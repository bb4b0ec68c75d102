"""The rate a log is fitted at: where its gyro's noise is white.

The wind-state model (:mod:`identification.likelihood.state_space`) measures the body rate with *white* noise.
A flight controller's gyro is low-pass filtered before it is logged (ArduPilot's ``INS_GYRO_FILTER``, a 2-pole
filter at 20 Hz by default on helicopters; PX4's ``IMU_GYRO_CUTOFF``; ``../shared/research/firmware-loops.md``),
and where the log is written well above that corner its noise is no longer white: neighbouring samples of it move
together. The likelihood then reads that noise as the aircraft's motion and the fit runs away — on the bench's
flights with the gyro through 20 Hz and logged at 100 Hz, dampings 2 to 45 times the truth and a "servo delay" of
0.13 s (docs/method.md, "A filtered gyro").

Fitted at a lower rate, where the filter's corner lies near the new Nyquist frequency, the noise is white again
and the same flights fit within a few per cent. Where the log states the filter's corner (ArduPilot's
``INS_GYRO_FILTER``; ``--gyro-filter``) the log is thinned until neighbouring samples of its filtered noise
correlate by at most :data:`WHITE_ENOUGH` (:func:`stated_every`), and the data are not asked: they may miss a filter
that does not inflate the damping but still halves the noise the fit reads, on which the closed-loop check builds
its world, and a flight controller's loop biases the damping differently at each rate, which the damping's test
below takes for a filter (the sluggish aircraft behind a stated 30 Hz filter: thinned again from 50 to 25 Hz on a
roll ratio of 2.9, its dampings then 22-98 % off). Where no corner is stated, whether a log needs it is decided by
the data, the way the damping reacts (:func:`choose_fit_rate`): the flight fitted at its rate and at half of it
(every second sample) with ``heli identify``'s timing (a servo delay and lag searched where the data suggest one: on a filtered gyro that is
where the fit runs away first, a "servo lag" of 0.1 s before a damping at the search's bound, while the fit without
them may look sound). A white gyro gives the two fits' dampings within a few per cent (the full rate's at most 1.08
times the half rate's on the bench's cells, usually below it); a filtered gyro's full-rate damping is inflated,
1.3 to 300 times the half rate's. Above :data:`RATIO`, and by :data:`Z` standard errors, on some axis the half
rate is taken and tried again against its own half, down to :data:`MIN_RATE`. The half rate is fitted first, and an
axis whose damping at the rate, fitted without the timing, already exceeds it so is not searched for a timing
(:func:`_dampings`): the timing can only decide the rate where the fit without it looks sound.

The estimator itself fits the flights it is given; the commands (``heli identify``, ``diagnose``, ``tune``, and
``refresh`` at its model's rate) call :func:`at_fit_rate` first, and so should a script that wants their choice.

Taking every ``m``-th sample needs no anti-aliasing filter here: the rates were low-passed by the gyro's filter
(that is why they are thinned), and a pilot's sticks are smooth. A flight controller's held commands are thinned
as they are; the hold search then finds what they are at the new rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .flight import Flight, make_flight

RATIO = 1.15
"""A log is fitted at half its rate where, on some axis, the damping fitted at its rate exceeds the one fitted at
half of it by this factor and by :data:`Z` standard errors (bench: white gyros at most 1.08 over 165 flights,
``scripts/fit_rate_study.py``; module docstring)."""

Z = 3.0
"""... and by this many standard errors of the difference (the half rate's relative error on both, combined as if
independent)."""

MIN_RATE = 20.0
"""No log is thinned below this rate [Hz]: a helicopter's attitude modes need it."""

WHITE_ENOUGH = 0.3
"""Where a log states its gyro filter's corner (:func:`~identification.validation.fit_warnings.gyro_filter`), it is
fitted no faster than the rate whose neighbouring samples of the filtered noise correlate by at most this much
(:func:`filtered_noise_correlation`; :func:`stated_every`). The bench's autopilot behind a 20 Hz filter, logged at
100 Hz (correlation 0.58): the fit read the gyro's noise at half its std (0.0017 rad/s against 0.0033) and gave the
rest to the aircraft's motion, and the closed-loop check's world built on it moved the dampings 23-70 % off; at 50 Hz
(0.13) it read 0.0031 and the check ended within 2 % (docs/method.md)."""

DAMPINGS = {"roll": "k3", "pitch": "k7", "yaw": "k11"}


@dataclass(frozen=True)
class FitRate:
    """The rate a log is fitted at, and what decided it.

    Attributes
    ----------
    every : int
        The log's samples per fitted sample (1: fitted at the log's own rate).
    log_hz : float
        The log's rate [Hz].
    steps : tuple of (float, dict)
        Per rate tried, the rate [Hz] and per axis the damping fitted there over the one fitted at half of it.
    corner : float or None
        The gyro filter's corner the log states [Hz] where it thinned the log (:func:`stated_every`), else None.
    """

    every: int
    log_hz: float
    steps: tuple = ()
    corner: float | None = None

    @property
    def hz(self) -> float:
        """The rate fitted at [Hz]."""
        return self.log_hz / self.every

    def describe(self) -> str:
        """One sentence for the terminal and the report."""
        def ratios(step):
            rate, by_axis = step
            return f"at {rate:g} Hz " + ", ".join(f"{axis} {value:.2f}" for axis, value in by_axis.items())

        tried = "; ".join(ratios(s) for s in self.steps)
        if self.corner is not None:
            return (f"fitted at {self.hz:g} Hz, every {nth(self.every)} sample of the {self.log_hz:g} Hz log: its gyro "
                    f"is stated low-passed at {self.corner:g} Hz (by the log's parameters or --gyro-filter), whose noise "
                    f"is not white faster (neighbouring samples correlate by more than {WHITE_ENOUGH:g}, and the "
                    "likelihood, which takes it for white, reads part of it as motion)")
        if self.every == 1:
            return (f"fitted at the log's {self.log_hz:g} Hz: the dampings fitted there and at half of it agree "
                    f"(their ratio {tried}; a filtered gyro's is above {RATIO:g})" if self.steps else
                    f"fitted at the log's {self.log_hz:g} Hz")
        return (f"fitted at {self.hz:g} Hz, every {nth(self.every)} sample of the {self.log_hz:g} Hz log: the gyro's "
                f"noise is not white at the log's rate (a flight controller's gyro filter), and the likelihood, which "
                f"takes it for white, read it as motion: the damping fitted at a rate over the one at half of it "
                f"was {tried} (white gyros at most about 1.08, so above {RATIO:g} the half rate is taken)")


def nth(k: int) -> str:
    """"2nd", "4th": the ordinal of a thinning."""
    suffix = "th" if k % 100 in (11, 12, 13) else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
    return f"{k}{suffix}"


def thinned(flight: Flight, every: int) -> Flight:
    """Every ``every``-th sample of ``flight`` (its extra columns too), with its metadata saying so."""
    if every == 1:
        return flight
    keep = slice(None, None, every)
    meta = {**flight.metadata, "fit_every": int(every)}
    return make_flight(flight.time[keep], flight.rates[:, keep], np.ascontiguousarray(flight.sticks[:, keep]),
                       attitude=flight.attitude[:, keep], metadata=meta,
                       extra={k: np.ascontiguousarray(v[keep]) for k, v in flight.extra.items()})


def _dampings(flights, every: int, half: dict | None = None, ratio: float = RATIO) -> dict | None:
    """Per axis ``(damping, its standard error)`` the estimator fits to ``flights`` thinned by ``every`` with
    ``heli identify``'s timing (the servo delay and lag searched where the data suggest one; no closed-loop check),
    None where it refuses them. ``half``: the dampings fitted at half this rate, where known; an axis whose damping
    fitted without the timing already exceeds its half rate's (:func:`_exceeds`) is not searched for a timing
    (``MaximumLikelihoodIdentifier.timing_gate``): the rate is thinned whatever a timing would add, and on a
    filtered gyro the timing's searches at a damping run away are the choice's slowest part (a 200 Hz log behind a
    20 Hz filter: 17 s of its 41 on one core, roll and pitch at the search's bound)."""
    from .errors import IdentifiabilityError
    from .likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier

    ident = MaximumLikelihoodIdentifier(**CLI_TIMING, closed_loop=None)
    if half:
        ident.timing_gate = lambda axis, d: axis in half and _exceeds(d, *half[axis], ratio)
    try:
        fitted = ident.fit([thinned(f, every) for f in flights])
    except (IdentifiabilityError, ValueError, np.linalg.LinAlgError):  # a refusal at either rate: the log's stands
        return None
    return {axis: (float(fit.params[DAMPINGS[axis]]), float(fit.std_errors.get(DAMPINGS[axis], np.inf)))
            for axis, fit in fitted.axes_.items() if DAMPINGS[axis] in fit.params}


def _inflated(here: dict, half: dict, ratio: float) -> tuple[dict, bool]:
    """Per axis the damping at a rate over the one at half of it, and whether some axis' exceeds ``ratio`` by more
    than :data:`Z` standard errors of the difference (so that a short flight's spread is not taken for a filter).
    Both fits are given the half rate's relative error: the log's rate holds at least the half rate's information,
    and the standard error of a fit run away to the search's bound is itself unbounded, which would hide it."""
    by_axis, inflated = {}, False
    for axis, (d, _) in here.items():
        if axis not in half or not (d > 0 and half[axis][0] > 0):
            continue
        by_axis[axis] = d / half[axis][0]
        inflated = inflated or _exceeds(d, *half[axis], ratio)
    return by_axis, inflated


def _exceeds(d: float, d_half: float, se_half: float, ratio: float = RATIO) -> bool:
    """A damping ``d`` fitted at a rate exceeds ``d_half`` fitted at half of it (standard error ``se_half``) by
    ``ratio`` and by :data:`Z` standard errors of the difference (:func:`_inflated`)."""
    if not (d > 0 and d_half > 0):
        return False
    return d / d_half > ratio and d - d_half > Z * float(np.hypot(se_half, se_half * d / d_half))


def filtered_noise_correlation(corner_hz: float, spacing_s: float) -> float:
    """The correlation of white noise passed through a 2-pole Butterworth low-pass at ``corner_hz`` between two
    samples ``spacing_s`` apart: ``exp(-a) (cos a + sin a)``, ``a = 2 pi corner spacing / sqrt 2`` (the analogue
    filter's autocorrelation, damping ratio 1/sqrt 2; the firmware's digital one at its kHz loop is near it)."""
    a = 2.0 * np.pi * corner_hz * spacing_s / np.sqrt(2.0)
    return float(np.exp(-a) * (np.cos(a) + np.sin(a)))


def stated_every(flights, log_hz: float, min_rate: float = MIN_RATE) -> tuple[int, float | None]:
    """``(every, corner)``: the least halving of a ``log_hz`` log whose samples of the gyro noise, low-passed at the
    corner its flights state (the highest, where they differ), correlate by at most :data:`WHITE_ENOUGH`, no lower
    than ``min_rate``; ``(1, None)`` where a flight states none."""
    from .validation.fit_warnings import gyro_filter

    corners = [gyro_filter(getattr(f, "metadata", {}) or {}) for f in flights]
    if not corners or None in corners:
        return 1, None
    corner, every = max(corners), 1
    while (filtered_noise_correlation(corner, every / log_hz) > WHITE_ENOUGH
           and log_hz / (2 * every) >= min_rate):
        every *= 2
    return every, (corner if every > 1 else None)


def choose_fit_rate(flights, ratio: float = RATIO, min_rate: float = MIN_RATE) -> FitRate:
    """The rate ``flights`` (one log's, at one rate) are fitted at (module docstring): where the log states its gyro
    filter, halved until its noise is white enough there (:func:`stated_every`), the data not asked; else halved
    while, on some axis, the damping fitted at a rate exceeds the one fitted at half of it by ``ratio``, and the half
    rate is at least ``min_rate``.

    Raises
    ------
    ValueError
        Flights of different rates.
    """
    from .validation.fit_warnings import gyro_filter

    flights = list(flights)
    rates = {round(f.sample_rate, 6) for f in flights}
    if len(rates) != 1:
        raise ValueError(f"expected flights of one sample rate, got {sorted(rates)} Hz")
    log_hz = round(float(flights[0].sample_rate), 6)  # a clock's last bits (100.00000000000213) are no rate
    every, corner = stated_every(flights, log_hz, min_rate)
    if all(gyro_filter(f.metadata) for f in flights):  # the filter stated: nothing for the data to guess
        return FitRate(every, log_hz, (), corner)
    steps, here = [], None
    while log_hz / (2 * every) >= min_rate:
        half = _dampings(flights, 2 * every, ratio=ratio)  # first: it gates the timing's search at this rate
        here = _dampings(flights, every, half, ratio) if here is None else here
        if here is None or half is None:
            break
        by_axis, inflated = _inflated(here, half, ratio)
        steps.append((log_hz / every, by_axis))
        if not inflated:
            break
        every, here = 2 * every, half
    return FitRate(every, log_hz, tuple(steps))


def every_for(log_hz: float, hz: float) -> int:
    """The thinning that fits a ``log_hz`` log at ``hz``: a whole number of its samples per fitted sample.

    Raises
    ------
    ValueError
        ``hz`` not the log's rate divided by a whole number.
    """
    every = int(round(log_hz / hz)) if hz > 0 else 0
    if every < 1 or abs(log_hz / every - hz) > 1e-6 * log_hz:
        raise ValueError(f"a fit rate is the log's rate divided by a whole number ({log_hz:g}, {log_hz / 2:g}, "
                         f"{log_hz / 3:g} ... Hz for this log), got {hz:g} Hz")
    return every


def at_fit_rate(flights, setting="auto") -> tuple[list, FitRate]:
    """``flights`` (one log's, at one rate) as they are fitted, and the :class:`FitRate` that says why: ``setting``
    "auto" (:func:`choose_fit_rate`), "log" (the log's rate) or a rate in Hz (:func:`every_for`). Thinned flights
    carry the reason in ``metadata["fit_rate"]``, which the fit's warnings repeat, and in ``metadata["fit_rate_by"]``
    what decided it: ``"corner"`` (a stated gyro filter), ``"data"`` (the dampings' test: a filtered gyro) or
    ``"asked"`` (a rate the user gave)."""
    flights = list(flights)
    log_hz = round(float(flights[0].sample_rate), 6)  # a clock's last bits (100.00000000000213) are no rate
    if setting == "auto":
        chosen = choose_fit_rate(flights)
    elif setting == "log":
        chosen = FitRate(1, log_hz)
    else:
        chosen = FitRate(every_for(log_hz, float(setting)), log_hz)
    if chosen.every == 1:
        return flights, chosen
    asked = f"fitted at {chosen.hz:g} Hz, every {nth(chosen.every)} sample of the {log_hz:g} Hz log, as asked"
    reason = chosen.describe() if chosen.steps or chosen.corner else asked
    by = "corner" if chosen.corner else "data" if chosen.steps else "asked"  # why (loop_world reads it)
    return [thinned(f, chosen.every).with_metadata(fit_rate=reason, fit_rate_by=by) for f in flights], chosen
