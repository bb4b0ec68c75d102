"""Warnings about an identification the data cannot support well: weak fits, short flights, unexcited axes.

An identifier returns numbers for any data it is given; whether they mean anything
depends on the data. :func:`fit_warnings` looks at the flights and the per-axis fit
quality and returns one line per concern, for the terminal and the report:

* **Weak fit** -- the model explains less than :data:`MIN_R2` of an axis' rate
  variance (R², the share of variance explained). A real ArduCopter log fitted at
  2 % is a model of noise: the input source (``heli import --inputs``), the segment
  or the logging rate is usually the cause. The R² that judges a maximum-likelihood
  model is its 0.5 s-ahead prediction's (:func:`identification.validation.judged_fit.judged_r2`), not the share the sticks
  explain alone: that one is low for a correct model when the wind dominates the axis
  (on the project's own 300 s synthetic flight, yaw 0.24 with every yaw parameter within
  2 % of the truth; 0.5 s ahead 0.66), and the one-step prediction's is near 1 for any
  model sampled fast (0.985 on a Betaflight fit whose damping sits at its search bound;
  0.5 s ahead 0.10).
* **Short flight** -- a flight shorter than :data:`MIN_DURATION_S`: too few
  independent gusts and manoeuvres for the parameters (and the wind statistics of
  eqs. 41-47) to settle. Several flights are fitted together (one set of parameters and
  gust statistics): they are judged by their total (the airborne runs of one log, ``heli
  import --segment each``, are often shorter one by one).
* **Barely excited axis** -- the axis' stick moves with a standard deviation below
  :data:`~identification.excitation.MIN_STICK_STD` (half a percent of the [-1, 1] range) or its rate below
  :data:`MIN_RATE_STD` (half a degree per second): the control gain and damping of
  that axis are then not identifiable from the data, whatever R² says.

* **Hold in doubt** (:func:`hold_warning`) -- the log rejects neither held nor interpolated sticks
  (:func:`identification.likelihood.input_hold.undecided_against`) and the values fitted at the two differ by
  more than their standard errors: the line says by how much and what would decide it.
* **Stick noise the aircraft did not feel** (:func:`stick_noise_warning`) -- the sticks moved between the log's
  samples (:mod:`identification.likelihood.stick_noise`): the line names the axes and what avoids it.
* **A flight controller's loop faster than the fit** (:func:`controller_loop_warning`) -- the inputs are its
  commands, and its loop (stated by the log, or unknown) runs faster than the rate they are fitted at: what the
  closed-loop check removed where it flew the loop at its stated rate, and what to state where it could not.

The functions are pure: they read the flights and the figures and return strings (the figures that judge a
fitted model come from :mod:`identification.validation.judged_fit`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np

from heli_core.deprecation import module_getattr
from heli_core.terms import AXES

from ..excitation import AXIS_STICK, MIN_STICK_STD, from_a_log, static_collective
from ..likelihood.input_hold import other_hold
from ..log_band import log_band

MIN_R2 = 0.30
"""Least share of an axis' rate variance a fit should explain."""
MIN_DURATION_S = 60.0
"""s: least length of a flight."""
MIN_RATE_STD = math.radians(0.5)
"""rad/s: least standard deviation of an axis' rate."""


def _label(flight, k: int, n: int) -> str:
    """Flight ``k`` of ``n`` as a warning names it: its source file quoted, else its place among several ('')."""
    meta = getattr(flight, "metadata", {}) or {}
    source = meta.get("source")
    return f"'{source}'" if source else (f"{k + 1} of {n}" if n > 1 else "")


def _name(flight, k: int, n: int) -> str:
    return f"flight {_label(flight, k, n)}".strip()


def fit_warnings(flights, r2: Mapping | None = None, r2_label: str = "fit", *, min_r2: float = MIN_R2,
                 min_duration_s: float = MIN_DURATION_S, min_stick_std: float = MIN_STICK_STD,
                 min_rate_std: float = MIN_RATE_STD) -> list[str]:
    """One-line warnings about what the flights and the fit quality cannot support (module docstring).

    Parameters
    ----------
    flights : Flight or iterable of Flight
        The flights identified from (anything with ``time`` (n,), ``rates`` (3, n), ``sticks`` (4, n) and
        ``metadata``).
    r2 : mapping of str to float, optional
        Share of variance the model explains per axis (``"roll"``, ``"pitch"``, ``"yaw"``), as
        :func:`~identification.validation.judged_fit.judged_r2` gives it; None or NaN for an axis that was not fitted, ``-inf`` for a prediction
        that diverged. Without it only the data are checked.
    r2_label : str
        What ``r2`` is, for the warning ("fit", :data:`~identification.validation.judged_fit.AHEAD_LABEL`).
    min_r2, min_duration_s, min_stick_std, min_rate_std : float
        Thresholds (defaults :data:`MIN_R2`, :data:`MIN_DURATION_S`, :data:`~identification.excitation.MIN_STICK_STD`
        [stick],
        :data:`MIN_RATE_STD` [rad/s]).

    Returns
    -------
    list of str
        Flights first (in order), then per axis (roll, pitch, yaw) excitation and fit; empty when all is well.
    """
    if hasattr(flights, "time"):
        flights = [flights]
    flights = list(flights) if isinstance(flights, Iterable) else [flights]
    out: list[str] = []
    durations = [float(f.time[-1] - f.time[0]) if len(f.time) > 1 else 0.0 for f in flights]
    if len(flights) > 1 and sum(durations) < min_duration_s:  # the fit's parameters are the flights' together
        each = ", ".join(f"{_label(f, k, len(flights))} {d:.1f} s"
                         for k, (f, d) in enumerate(zip(flights, durations)))
        out.append(f"the {len(flights)} flights ({each}) last {sum(durations):.1f} s in all, shorter than "
                   f"{min_duration_s:.0f} s: too short for the parameters and the wind statistics to settle; "
                   "identify from longer flights or more of them")
    for k, (f, duration) in enumerate(zip(flights, durations)):
        if len(flights) == 1 and duration < min_duration_s:
            out.append(f"{_name(f, k, len(flights))} lasts {duration:.1f} s, shorter than {min_duration_s:.0f} s: "
                       "too short for the parameters and the wind statistics to settle; identify from a longer "
                       "flight or several flights")
        band = log_band(f) if hasattr(f, "sample_rate") else None
        if band is not None and band.filtered:
            out.append(f"{_name(f, k, len(flights))}: {band.describe()}")
    # thinned to where its gyro's noise is white (identification.fit_rate): one reason for a log's flights
    out += list(dict.fromkeys(f.metadata["fit_rate"] for f in flights if getattr(f, "metadata", {}).get("fit_rate")))
    corners = sorted({c for c in (gyro_filter(getattr(f, "metadata", {}) or {}) for f in flights) if c is not None})
    if corners:  # identification.likelihood.gyro_path
        stated = ", ".join(f"{c:g} Hz ({1e3 * math.sqrt(2.0) / (2.0 * math.pi * c):.1f} ms of lag)" for c in corners)
        out.append(f"the gyro is stated low-passed at {stated}: the maximum-likelihood fit passes the sticks through "
                   "that filter, so that its lag is the sensor's, not read as the aircraft's (the model written is the "
                   "aircraft's)")
    collective = static_collective(flights) if flights else None
    imported = bool(flights) and from_a_log(flights)
    if collective is not None:
        out.append(f"the collective does not vary (std {round(collective, 6):g} within each flight): the collective torque "
                   "(k12) and gain scheduling are not fitted (with a constant collective they are the offset and "
                   "the control gain again)")
    if flights:
        sticks = np.concatenate([np.asarray(f.sticks, dtype=float) for f in flights], axis=1)
        rates = np.concatenate([np.asarray(f.rates, dtype=float) for f in flights], axis=1)
        for i, axis in enumerate(AXES):
            stick, row = AXIS_STICK[axis]
            s_std, r_std = float(np.std(sticks[row])), float(np.std(rates[i]))
            if s_std < min_stick_std or r_std < min_rate_std:
                out.append(f"{axis} is barely excited: the {stick} stick varies by {s_std:.3g} (std; "
                           f"{100 * s_std / 2:.2g} % of its [-1, 1] range) and the {axis} rate by "
                           f"{math.degrees(r_std):.2g} deg/s (std); its gain and damping are not identifiable "
                           f"from these data (fly sweeps on {stick}"
                           + (", or check the input source: heli import --inputs)" if imported else ")"))
    ticks = _log_ticks(flights)
    for axis in AXES:
        value = None if r2 is None else r2.get(axis)
        if value is None or np.isnan(value):
            continue
        if value < min_r2:
            shown = f"{value:.2f}" if np.isfinite(value) else "diverged"
            out.append(f"{axis}: the model explains {100 * max(value, 0.0):.0f} % of the rate variance ({r2_label} "
                       f"R² {shown}), below {100 * min_r2:.0f} %: it says little about this axis; check "
                       + ("the input source (heli import --inputs), " if imported else "") + "the segment and the "
                       "logging rate" + (_FASTER_LOOP_R2.format(ticks=ticks) if ticks > 1 else ""))
    return out


_FASTER_LOOP_R2 = ("; the inputs are a flight controller's commands from a loop {ticks}x faster than the log, whose "
                   "corrections inside each sample the logged commands do not hold, so that even the true model predicts "
                   "little far from the samples (the bench's autopilot 8x faster than a 25 Hz log: 0.5 s-ahead R² 0.42 / "
                   "0.26 / -0.24 at the true gains and dampings)")
"""The low-R² warning's clause for a log of a flight controller's commands slower than its loop."""


def _log_ticks(flights) -> int:
    """:func:`log_ticks` of ``flights`` at the first flight's sample interval (the ticks the closed-loop check flies);
    1 for a flight of fewer than two samples."""
    if not flights or len(flights[0].time) < 2:
        return 1
    return log_ticks(flights, float(np.median(np.diff(flights[0].time))))


__getattr__ = module_getattr(__name__)


HOLD_NAMES = {"zoh": "held over each sample", "linear": "interpolated between samples"}


def hold_warning(ident) -> list[str]:
    """One line where the log leaves its input hold in doubt (``ident.hold_alternative_``, see
    :func:`identification.likelihood.input_hold.hold_alternative`) and the values move with it: those that move by
    more than their standard error at the other hold, the likelihood ratio against the decision's threshold, and
    what would decide it (the gains and dampings; the offsets' relative moves mean little). None where nothing
    moves that far (the doubt is then in model.json alone)."""
    alternative = getattr(ident, "hold_alternative_", None)
    if not alternative:
        return []
    moved = []
    for axis, fit in ident.axes_.items():
        other = alternative["axes"].get(axis, {}).get("params", {})
        for name, value in fit.params.items():
            se = fit.std_errors.get(name, 0.0)
            if name in other and not name.startswith("kd") and value != 0 and abs(other[name] - value) > se:
                moved.append(f"{name} {100 * (other[name] - value) / abs(value):+.0f} %")
    if not moved:  # the doubt moves nothing past its error (the T-REX hover, filtered at 2.4 Hz): no concern
        return []
    other = alternative["hold"]
    taken = other_hold(other)
    lr = alternative["lr"]
    preferred = (f"which the data prefer to {HOLD_NAMES[other]}" if lr >= 0
                 else f"though the data prefer {HOLD_NAMES[other]}")
    return [f"the log does not decide how its sticks reach the aircraft: read as {HOLD_NAMES[taken]}, {preferred} "
            f"by a factor of only exp({abs(lr):.1f}) (a clear decision needs exp({alternative['threshold']:.1f}))"
            + f"; read as {'held' if other == 'zoh' else 'interpolated'}: {', '.join(moved)}"
            + ". The standard errors reported include this doubt. If you know, give --input-hold zoh (a flight "
            "controller or a digital radio link) or --input-hold linear (a pilot's hand sampled); a longer flight "
            "decides it"]


def folded_lines_warning(ident) -> list[str]:
    """One line where the gyro carried lines a slow log folded into the aircraft's band
    (:func:`identification.vibration.remove_folded_lines`, ``ident.vibration_lines_``): which, at what rate, and
    what avoids them. They are removed before the fit; left in, the bench's dampings came out 450-600 % off."""
    found = [ln for per_flight in getattr(ident, "vibration_lines_", None) or [] for ln in per_flight
             if ln.get("folded")]
    lines = [ln for ln in found if ln.get("signal") != "command"]
    if not lines:
        return []
    where = sorted({round(ln["frequency_hz"], 2) for ln in lines})
    axes = [axis for axis in AXES if any(ln["axis"] == axis for ln in lines)]
    fed = [axis for axis in AXES if any(ln["axis"] == axis and ln.get("signal") == "command" for ln in found)]
    commands = (f"; the flight controller flew on that gyro and its {', '.join(fed)} command{'s' if len(fed) > 1 else ''} "
                "carr" + ("y" if len(fed) > 1 else "ies") + " them too, folded alike: the aircraft answered them at "
                "their own frequency, not at the folded one, so they were removed from those commands and the gyro "
                "together (the same prefilter on both)") if fed else ""
    return [f"the gyro ({', '.join(axes)}) carries narrow lines at {', '.join(f'{hz:g}' for hz in where)} Hz that the "
            "attitude does not show: vibration faster than half the log's rate, folded into the aircraft's band by "
            f"sampling. Their sensor share was removed before the fit{commands}; log the gyro at more than twice the "
            "rotor's frequency, or low-passed below half the log's rate, to be rid of them"]


def stick_noise_warning(check) -> list[str]:
    """One line where the sticks carry noise the aircraft did not feel
    (:func:`identification.likelihood.stick_noise.check_stick_noise`, a :class:`StickNoiseCheck` or None): which
    axes, by what likelihood ratio, which way their values lie, and what avoids it. The fit is left as it is: no
    estimate from the logged samples alone recovers what the aircraft felt between them."""
    if check is None or not check.axes:
        return []
    axes = check.axes
    ratios = ", ".join(f"{axis} exp({check.lr[axis]:.0f})" for axis in axes)
    moved = [f"{name} {pct:+.1f} %" for axis in axes for name, pct in check.moved.get(axis, {}).items()
             if abs(pct) >= 0.5]
    shrunk = f"; the gains solved on them move: {', '.join(moved)}" if moved else ""
    return [f"the {', '.join(axes)} stick{'s' if len(axes) > 1 else ''} carr{'y' if len(axes) > 1 else 'ies'} noise "
            f"the aircraft did not feel: with each sample pulled {check.shrink:g} of the way to its neighbours' mean, "
            f"the rates are explained better by a factor of {ratios} (a clear sign needs "
            f"exp({max(check.thresholds[a] for a in axes):.1f})){shrunk}. A radio link or loop that updates its "
            "commands faster than the log records them leaves sticks that moved between samples: a link's noisy "
            "commands bias the gains and dampings low (8-10 % on the bench's agile yaw, about twice what the shrunk "
            "sticks move them), and a flight controller's loop correcting the aircraft inside each sample biases "
            "the dampings high (17-45 %; docs/method.md). Log the commands at the loop's rate, or each one's mean "
            "over its sample, to identify this aircraft"]


CONTROLLER_SOURCES = ("controller", "servos", "flight controller commands")
"""The input sources that are a flight controller's commands (``heli import --inputs controller|servos`` of a
flight controller's log, the bench's autopilot), not the pilot's sticks. A CSV's own servo columns ("servos (eq.
67)", the paper's flybar helicopter: the pilot's radio drives them) are not among them."""


FASTER_LOOP = 1.25
"""A flight controller's loop faster than the fit's rate by more than this factor corrects the aircraft inside each
fitted sample (:func:`controller_loop_warning`, :func:`loop_ticks`)."""


def input_source(meta) -> tuple[str, float | None]:
    """A flight's input source and its controller's loop rate [Hz] (None where the log did not state it), from its
    own metadata or, for a CSV ``heli import`` wrote, the import's."""
    imported = meta.get("imported_from") or {}
    source = str(imported.get("input_source") or meta.get("input_source") or "")
    return source, _stated_hz(meta, "loop_rate_hz")


MAX_LOOP_TICKS = 40
"""Most ticks of a flight controller's loop flown per logged sample (:func:`loop_ticks`: a 4 kHz loop logged at
100 Hz)."""


def loop_ticks(flight, dt: float | None = None) -> int:
    """Ticks of a flight controller's loop per sample of ``flight`` (its samples ``dt`` apart, default its own): the
    loop's rate over the samples', rounded, where the inputs are a flight controller's commands and the log states a
    loop faster than them by :data:`FASTER_LOOP` (at most
    :data:`MAX_LOOP_TICKS`); else 1. Such a loop corrects the aircraft inside each logged sample, and the model,
    driven by the sampled commands, reads that as damping (docs/method.md): the check flies it at its own rate."""
    source, loop = input_source(getattr(flight, "metadata", {}) or {})
    rate = 1.0 / dt if dt else flight.sample_rate
    if source not in CONTROLLER_SOURCES or loop is None or loop <= FASTER_LOOP * rate:
        return 1
    return int(min(MAX_LOOP_TICKS, round(loop / rate)))


def log_ticks(flights, dt: float | None = None) -> int:
    """The controller ticks a sample that every one of a log's ``flights`` has (:func:`loop_ticks`, the least):
    > 1 only where each is a flight controller's commands logged slower than its stated loop. What the log as a
    whole is decided by (its hold, a delay within a sample, the gyro noise a check needs); each flight's own loop
    is still flown at its own ticks."""
    return min((loop_ticks(f, dt) for f in flights), default=1)


def _stated_hz(meta, key: str) -> float | None:
    """A frequency a flight's log states [Hz], from its own metadata or, for a CSV ``heli import`` wrote, the
    import's (which is read first); None where neither states one above 0."""
    value = (meta.get("imported_from") or {}).get(key, meta.get(key))
    return float(value) if isinstance(value, (int, float)) and value > 0 else None


def gyro_filter(meta) -> float | None:
    """The corner [Hz] of the low-pass a flight's gyro passed before its controller read it and its log wrote it (a
    2-pole one: ArduPilot's ``INS_GYRO_FILTER``, PX4's ``IMU_GYRO_CUTOFF``; ``--gyro-filter``), None where nothing
    stated it; from its own metadata or, for a CSV ``heli import`` wrote, the import's."""
    return _stated_hz(meta, "gyro_filter_hz")


def without_gyro_filter(meta) -> dict:
    """``meta`` (a flight's metadata) with no gyro filter stated (:func:`gyro_filter`), an import's included: a
    flight whose gyro is white, flown by a world that does not filter it (:mod:`identification.likelihood.loop_world`)."""
    out = {k: v for k, v in meta.items() if k != "gyro_filter_hz"}
    if isinstance(out.get("imported_from"), Mapping):
        out["imported_from"] = {k: v for k, v in out["imported_from"].items() if k != "gyro_filter_hz"}
    return out


def unstated_filter(flights) -> bool:
    """Some of ``flights`` was thinned for a filtered gyro whose corner nothing states (:func:`gyro_filter`): by the
    data's test (:func:`identification.fit_rate.at_fit_rate`) or to a model's rate (``heli refresh``); a rate the
    user asked for says nothing of the gyro. A flight controller's loop read through such a filter cannot be flown
    (:func:`identification.likelihood.loop_world.skip_reason`)."""
    return any(f.metadata.get("fit_rate_by") in ("data", "model") and gyro_filter(f.metadata) is None
               for f in flights)


def stated_controller(flight, loop_hz: float | None, gyro_filter_hz: float | None = None):
    """``flight`` with its inputs stated as a flight controller's commands from a loop at ``loop_hz`` (``heli
    identify``, ``diagnose`` and ``refresh --controller-loop``, and a model's source that recorded it) and its gyro
    low-passed at ``gyro_filter_hz`` before the loop read it and the log wrote it (``--gyro-filter``), each where
    given, over what its file or import said (:func:`input_source` and :func:`gyro_filter` read them back)."""
    items = {"input_source": "flight controller commands", "loop_rate_hz": float(loop_hz)} if loop_hz else {}
    if gyro_filter_hz:
        items["gyro_filter_hz"] = float(gyro_filter_hz)
    if not items:
        return flight
    imported = flight.metadata.get("imported_from")
    if imported:  # an import's own statement is read first (input_source): the user's replaces it
        items["imported_from"] = {**imported, **items}
    return flight.with_metadata(**items)


def controller_loop_warning(flights, advice: bool = True, check=None) -> list[str]:
    """One line where the inputs are a flight controller's commands and its loop may run faster than the rate they
    are fitted at: the loop then corrects the aircraft inside each fitted sample, and a model driven by the sampled
    commands reads that correction as damping (the bench's autopilot 4x faster than its 100 Hz log: dampings 17-45 %
    high before the closed-loop check flew the loop at its rate; docs/method.md, "A flight controller faster than
    its log").
    Where the closed-loop ``check`` flew the loop at its stated rate (``loop_ticks`` > 1), the line says what it
    removed and which axes it could not fly; without a stated rate the check cannot fly it, and the line advises.
    Silent where the log states a loop no faster than the fit's rate (a quarter more), and for a pilot's sticks.
    Without ``advice`` the cause alone (beside a refusal whose own advice stands: on the ArduCopter fixture the
    pilot's sticks end in a refusal too)."""
    slower = []
    for flight in flights:
        source, loop = input_source(getattr(flight, "metadata", {}) or {})
        if source in CONTROLLER_SOURCES and (loop is None or loop > FASTER_LOOP * flight.sample_rate):
            slower.append((source, loop, flight.sample_rate))
    if not slower:
        return []
    source, loop, rate = slower[0]
    stated = (f"its loop runs at {loop:g} Hz" if loop is not None else
              "its loop's rate is not in the log (flight controllers run theirs at 400 Hz to 8 kHz)")
    label = f" (heli import --inputs {source})" if source in ("controller", "servos") else ""
    cause = (f"the inputs are a flight controller's commands{label} fitted at {rate:g} Hz, and {stated}: the loop "
             "corrects the aircraft inside each fitted sample, and a model driven by the sampled commands reads that "
             "as damping")
    flown = _flown_at_loop_rate(check)
    if flown:
        return [cause + f"; the closed-loop check flew the loop at its rate and {flown} (docs/method.md)"]
    cause += " (the bench's autopilot with a loop 4x faster than its log: dampings 17-45 % high; docs/method.md)"
    state = (". State the gyro filter's corner (--gyro-filter HZ; ArduPilot's INS_GYRO_FILTER, 20 Hz by default): the "
             "check then flies the loop through it" if unstated_filter(flights) else "")
    return [cause + (f"{state}. Identify from the pilot's sticks (heli import --inputs sticks: the stabilised "
                     "aircraft), or from commands and gyro logged at the loop's rate" if advice else "")]


def _flown_at_loop_rate(check) -> str:
    """What the closed-loop ``check`` did with a flight controller's loop flown at its own rate, empty where it flew
    none: the dampings' biases it removed (or measured and left) per axis, and the axes it could not fly."""
    axes = getattr(check, "axes", {}) or {}
    flown = {a: c for a, c in axes.items() if c.checked and c.loop_ticks > 1}
    if not flown:
        return ""
    parts = []
    for axis, c in flown.items():
        damping = list(c.bias)[1]  # the gain, the damping (closed_loop._biases)
        verdict = "removed" if damping in c.removed else "left"
        parts.append(f"{axis} {damping} {100 * c.bias[damping]:+.0f} % ({verdict})")
    filtered = any(getattr(c, "gyro_filter", False) for c in flown.values())
    through = " (its law reading the gyro through the filter the log states)" if filtered else ""
    said = f"measured the dampings' bias{through}: " + ", ".join(parts)
    left = [a for a, c in axes.items() if not c.checked]
    return said + (f"; not flown, so still biased: {', '.join(left)}" if left else "")
