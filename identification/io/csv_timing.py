"""A CSV flight's sample times, made uniform before anything is fitted to them.

Every estimator here (and the disturbance library each fit writes) takes a flight's samples as a uniform
time grid. A CSV written by someone else's tool rarely is one to the microsecond: its clock may be rounded
to a millisecond (400 Hz stamped 0, 2, 5, 7, 10 ms ...), its samples taken with jitter, a sample dropped now
and then, or the logging paused. Before, such a file was fitted as its rows came and then refused when its
wind was written to the library, minutes later (jitter), or refused at once with advice no command followed
(a dropped sample). :func:`regular_columns` settles the clock when the CSV is read:

* **uniform** (:func:`heli_core.sampling.is_uniform`, the test the disturbance library applies): kept as it is;
* **on a clock** (every stamp within half an interval of a uniform clock, :func:`clock_of`): each row is the
  sample of its slot of the clock, its values kept and its stamp replaced by the slot's time; a slot with no
  row (a missing sample: an interval of two slots or more, within :func:`gap_limit`, the rule of
  :func:`identification.io.resample.gap_threshold`) is filled by linear interpolation between its
  neighbours, angles unwrapped. Stamps rounded to a clock quantum (a millisecond down to a microsecond) are
  said in the metadata only; missing samples, and jitter the rounding does not explain beyond
  :data:`JITTER_WARNING` of an interval, in a warning;
* **off any clock** (stamps further than half an interval from it: a logger whose rate wanders): resampled
  onto a uniform grid at the stamps' mean rate by linear interpolation, the method of
  :mod:`identification.io.resample`, which the flight-controller logs go through, with a warning;
* **gaps** (longer intervals: the logging stopped): refused, naming the stretches between them, unless a
  segment inside one stretch is asked for (``T0:T1``) or ``"all"``, which takes the longest stretch, as it
  does for a flight-controller log.

Why a row goes to its slot rather than being interpolated between its neighbours at the slot's time:
measured (``python scripts/csv_clock_study.py``: 2 kHz flights logged at 100 Hz with samples taken up to 1 or 2 ms
off the clock; docs/method.md), the interpolation's change of the identified dampings against the flight logged
on time was larger in 5 of 6 cells than that of the rows at their slots: a sample taken late by a random amount
errs by the rate's change over it, a white error the estimator's gyro noise takes in, while interpolation low-passes
the signal and colours the noise, which its model does not expect.

The rate is the clock's own: the least-squares slope of the stamps against their slot numbers, not the median
interval (a 400 Hz clock rounded to milliseconds has intervals of 2 and 3 ms and no 2.5), rounded to a whole
microsecond where that moves the last slot by under 5 % of an interval. The slots are counted from the intervals,
which is exact while every stamp lies within a quarter of an interval of its slot (an interval then never reads
as none or two); further off, where a count slipped and the fitted clock misses the stamps by more than half an
interval, they are counted by phase (:func:`phase_slots`, exact to about 45 %), and where that too puts two rows
in a slot the rows are interpolated from their stamps instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from heli_core.sampling import is_uniform

from .errors import SegmentError
from .resample import GAP_FACTOR, MIN_GAP_S

QUANTA_S = (1e-3, 1e-4, 1e-5, 1e-6)
"""s: the clock quanta a CSV's stamps are tested for, coarsest first."""
JITTER_WARNING = 0.1
"""Stamps further off their clock than this share of an interval, and not by its rounding, are warned of."""
ON_CLOCK = 0.5
"""Stamps at most this share of an interval off the clock are read at their slots; further, interpolated."""


@dataclass(frozen=True, eq=False)
class Clock:
    """How a CSV's stamps relate to a uniform clock (:func:`clock_of`).

    Attributes
    ----------
    interval : float
        The clock's sample interval [s] (least squares of the stamps on their slots).
    start : float
        The clock's time of slot 0 [s] (the same fit).
    slots : ndarray of int, shape (n,)
        Each row's slot on the clock (0 for the first row, increasing; a step of two or more where samples are
        missing).
    jitter : float
        The largest distance of a stamp from its slot's time, as a share of the interval.
    quantum : float or None
        The stamps' quantum [s] when every stamp is a multiple of it and lies within it of its slot (a clock
        rounded to it), else None.
    longest_missing_s : float
        The longest interval between rows that lacks samples [s] (0 when none does).
    on_clock : bool
        Whether each row is read at its slot: every stamp within :data:`ON_CLOCK` of an interval of its slot,
        one row a slot. Otherwise the stamps are taken as the sample times and the rows interpolated onto a
        grid at their mean rate (``interval`` and ``start`` that grid's, ``slots`` the rows' numbers).
    """

    interval: float
    start: float
    slots: np.ndarray
    jitter: float
    quantum: float | None
    longest_missing_s: float
    on_clock: bool = True

    @property
    def missing(self) -> int:
        """Slots between the first and last row that no row holds."""
        return int(self.slots[-1] + 1 - self.slots.size)

    @property
    def rate(self) -> float:
        return 1.0 / self.interval

    def warning(self, path) -> str | None:
        """The line a user is shown, or None where only the stamps' rounding was undone."""
        what = []
        if self.missing:
            what.append(f"{self.missing} sample(s) missing (the longest interval {_duration(self.longest_missing_s)})")
        if self.quantum is None and self.jitter > JITTER_WARNING:
            what.append(f"stamps up to {self.jitter:.0%} of the {_duration(self.interval)} interval off a uniform "
                        f"{self.rate:.6g} Hz clock" + ("" if self.on_clock else " (their mean rate)"))
        if self.on_clock and not what:
            return None
        how = (("each row read at its slot of the clock" + (", the missing ones interpolated between their "
                                                             "neighbours" if self.missing else ""))
               if self.on_clock else "no clock places every row, so the stamps were taken as the sample times and "
               "resampled onto a uniform grid at their mean rate by linear interpolation")
        return (f"the time column is not uniform: {' and '.join(what)}; {how} (`heli import {path} --out "
                "flight.csv` writes the flight as read)")

    def to_dict(self) -> dict:
        """``metadata["resampling"]`` of a CSV flight whose clock was settled."""
        method = ("each row at its slot of the clock, its values kept; missing slots interpolated linearly "
                  "(angles unwrapped)" if self.on_clock else
                  "linear interpolation onto a uniform grid (angles unwrapped)")
        return {"rate_hz": self.rate, "method": method, "missing_samples": self.missing,
                "longest_missing_s": self.longest_missing_s, "jitter_fraction": self.jitter,
                "quantum_s": self.quantum}


def interpolated(at: np.ndarray, where: np.ndarray, values: np.ndarray, angle: bool = False) -> np.ndarray:
    """``values`` known at ``where`` (increasing), linearly interpolated at ``at``; an ``angle`` [rad] on its
    unwrapped phase, wrapped back to (-pi, pi] (as :func:`identification.io.resample.resample_stream`)."""
    if not angle:
        return np.interp(at, where, values)
    return np.angle(np.exp(1j * np.interp(at, where, np.unwrap(values))))


def _duration(seconds: float) -> str:
    return f"{seconds * 1e3:.3g} ms" if seconds >= 1e-3 else f"{seconds * 1e6:.3g} us"


def nominal_interval(dt: np.ndarray) -> float:
    """A first estimate of the sample interval from intervals ``dt``: the mean of those between their 10th and
    90th percentiles (a clock rounded to 1 ms at 400 Hz: 2 and 3 ms, mean 2.5; a dropped sample or a
    gap is an outlier)."""
    lo, hi = np.percentile(dt, [10.0, 90.0])
    return float(np.mean(dt[(dt >= lo) & (dt <= hi)]))


def gap_limit(interval: float) -> float:
    """s: a longer interval is a gap (logging paused), not missing samples: the rule of
    :func:`identification.io.resample.gap_threshold`."""
    return max(GAP_FACTOR * interval, MIN_GAP_S)


def stretches(time: np.ndarray) -> np.ndarray:
    """The gap-free stretches of ``time`` as index pairs (m, 2) of [first, last] samples."""
    dt = np.diff(time)
    cut = np.flatnonzero(dt > gap_limit(nominal_interval(dt)))
    starts = np.concatenate(([0], cut + 1))
    ends = np.concatenate((cut, [time.size - 1]))
    return np.column_stack([starts, ends])


def clock_of(time: np.ndarray) -> Clock:
    """How the stamps ``time`` (strictly increasing, one gap-free stretch) sit on a uniform clock.

    Each row's slot is first counted from the intervals (each rounded to whole nominal intervals:
    :func:`nominal_interval`), the clock fitted to the slots by least squares, the slots taken again as the
    nearest of that clock's and the clock fitted again, until the slots stay (a count that slipped on one
    long interval is mended by the fit of the rest)."""
    dt = np.diff(time)
    slots = np.concatenate(([0], np.cumsum(np.maximum(np.rint(dt / nominal_interval(dt)), 1.0)))).astype(np.int64)
    for _ in range(4):
        slope, offset = _fitted_clock(time, slots)
        again = np.rint((time - offset) / slope).astype(np.int64)
        again -= again[0]
        if np.array_equal(again, slots) or np.any(np.diff(again) < 1):
            break
        slots = again
    off_clock = _off_clock(time, slots, slope, offset)
    if off_clock > ON_CLOCK:  # a count slipped (stamps over a quarter of an interval off): count by phase
        phased = phase_slots(time)
        if phased is not None:
            slots = phased
            slope, offset = _fitted_clock(time, slots)
            off_clock = _off_clock(time, slots, slope, offset)
    steps = np.diff(slots)
    longest = float(dt[steps > 1].max()) if np.any(steps > 1) else 0.0
    if off_clock > ON_CLOCK:  # no clock places the rows: the stamps are the sample times
        mean = float((time[-1] - time[0]) / (time.size - 1))
        number = np.arange(time.size)
        off_mean = float(np.max(np.abs(time - time[0] - mean * number))) / mean  # off the mean rate's grid
        return Clock(mean, float(time[0]), number, off_mean, None, longest, on_clock=False)
    quantum = next((q for q in QUANTA_S if _on_quantum(time, q)), None)
    if quantum is not None and off_clock * slope > quantum * (1.0 + 1e-6):
        quantum = None  # stamps on a quantum, but further off the clock than rounding puts them: jitter
    start = round(float(offset), 6)  # (to a microsecond: a stamp a reader can compare with the file's)
    return Clock(float(slope), start, slots, off_clock, quantum, longest)


def phase_slots(time: np.ndarray, search: float = 0.05) -> np.ndarray | None:
    """Each row's slot where the stamps lie up to half an interval off their clock, counted by phase, or None
    where the count puts two rows in one slot (no clock places them).

    The clock's interval is the one on which the stamps' phases ``2 pi t / T`` gather most (the length of
    their mean resultant: the circular statistics of a periodic point process), searched within ``search`` of
    :func:`nominal_interval` on the first 1000 rows, then 10 000, then all, each time at a quarter of the
    peak's width (``T^2 / span``); the slots are the stamps rounded on that clock, its phase the resultant's
    angle. Unlike a count of the intervals, which slips where an interval reads as none or two, this is exact
    for stamps up to about 45 % of an interval off (measured on 30 000 rows at 100 and 400 Hz, uniform jitter
    of 10-45 %, 0-5 % of the samples missing, stamps rounded to 1 ms or not: 42 of 45 cases read right, the
    other three, at 45 % with samples missing, found to put two rows in a slot)."""
    t = time - time[0]
    interval = nominal_interval(np.diff(time))
    width = search
    for m in sorted({min(t.size, 1000), min(t.size, 10_000), t.size}):
        step = interval * interval / (4.0 * max(t[m - 1], interval))
        half = int(np.ceil(width * interval / step))
        grid = interval + step * np.arange(-half, half + 1)
        strength = [abs(np.mean(np.exp(2j * np.pi * t[:m] / g))) for g in grid]
        interval = float(grid[int(np.argmax(strength))])
        width = 4.0 * step / interval
    phase = np.angle(np.mean(np.exp(2j * np.pi * t / interval)))
    slots = np.rint(t / interval - phase / (2.0 * np.pi)).astype(np.int64)
    slots -= slots[0]
    return slots if np.all(np.diff(slots) >= 1) else None


def _fitted_clock(time: np.ndarray, slots: np.ndarray) -> tuple[float, float]:
    """(interval, start) [s] of the clock fitted to the rows' ``slots`` by least squares, the interval rounded
    to a whole microsecond where that moves the last slot by under 5 % of an interval."""
    slope, offset = np.polyfit(slots, time, 1)
    whole = round(float(slope), 6)
    if whole > 0 and abs(whole - slope) * slots[-1] <= 0.05 * slope:
        return whole, float(np.mean(time - whole * slots))
    return float(slope), float(offset)


def _off_clock(time: np.ndarray, slots: np.ndarray, interval: float, start: float) -> float:
    """The largest distance of a stamp from its slot's time on the clock (``interval``, ``start``), in intervals."""
    return float(np.max(np.abs(time - (start + interval * slots)))) / interval


def _on_quantum(time: np.ndarray, quantum: float) -> bool:
    """Whether every stamp is a whole number of ``quantum`` s (counted from a first stamp on it too)."""
    counts = (time - time[0]) / quantum
    start = time[0] / quantum
    return bool(np.max(np.abs(counts - np.rint(counts))) < 1e-6 and abs(start - np.rint(start)) < 1e-3)


def _choose_stretch(path, time: np.ndarray, segment) -> tuple[int, int]:
    """Indices [first, last] of the stretch to read: the whole flight, or the part ``segment`` asks for
    ((t0, t1) inside one gap-free stretch, or ``"all"``: the longest)."""
    runs = stretches(time)
    if len(runs) == 1 and segment != "all":
        return 0, time.size - 1
    spans = [(float(time[a]), float(time[b])) for a, b in runs]
    longest = int(np.argmax([b - a for a, b in spans]))
    if segment == "all":
        return tuple(int(i) for i in runs[longest])
    if segment is not None:
        t0, t1 = segment
        inside = [j for j, (a, b) in enumerate(spans) if a <= t1 and b >= t0]
        if len(inside) != 1:
            raise SegmentError(f"{path}: segment {t0:g}:{t1:g} s spans a gap in the logged data; choose a segment "
                               f"inside one continuous stretch ({_listed(spans)}; --segment all takes the longest)")
        a, b = runs[inside[0]]
        keep = np.flatnonzero((time >= t0) & (time <= t1))
        return int(max(a, keep[0])), int(min(b, keep[-1]))
    limit = gap_limit(nominal_interval(np.diff(time)))
    a, b = spans[longest]
    raise SegmentError(
        f"{path}: the logging stopped {'once' if len(runs) == 2 else f'{len(runs) - 1} times'} (for over "
        f"{_duration(limit)}); the flight is "
        f"{len(runs)} stretches ({_listed(spans)}). Read one: --segment all (the longest, {a:.2f}-{b:.2f} s) or "
        f"--segment T0:T1; `heli import {path} --segment all --out flight.csv` writes the longest as a flight")


def _listed(spans, most: int = 4) -> str:
    shown = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in spans[:most])
    return shown + (f" and {len(spans) - most} more" if len(spans) > most else "")


def regular_columns(path, columns: dict, angles: tuple = (), segment=None) -> tuple[dict, dict | None, list | None]:
    """The CSV's ``columns`` (name -> (n,) array, ``"time"`` among them, strictly increasing) on a uniform
    clock (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The file, for messages.
    columns : dict of str to ndarray, shape (n,)
    angles : tuple of str
        Columns holding angles [rad] (interpolated on their unwrapped phase).
    segment : None, "all" or (t0, t1)
        Which stretch is read when the logging stopped during the flight (ignored otherwise: the caller cuts).

    Returns
    -------
    columns : dict
        The same names, uniform in time (the input itself where it already was).
    resampling : dict or None
        What was done (:meth:`Clock.to_dict` plus ``"note"``, the line shown to the user), None when nothing was.
    stretch : list or None
        ``[t0, t1]`` [s] of the stretch read where the logging stopped during the flight, else None.

    Raises
    ------
    SegmentError
        The logging stopped during the flight and no segment, or one across a stop, was asked for.
    """
    time = columns["time"]
    a, b = _choose_stretch(path, time, segment)
    stretch = None
    if (a, b) != (0, time.size - 1):
        stretch = [float(time[a]), float(time[b])]
        columns = {name: values[a:b + 1] for name, values in columns.items()}
        time = columns["time"]
    if time.size < 3 or is_uniform(time):
        return columns, None, stretch
    clock = clock_of(time)
    out = {"time": clock.start + clock.interval * np.arange(clock.slots[-1] + 1)}
    held = clock.slots if clock.on_clock else time  # where the rows are, in the grid's own terms
    at = np.arange(out["time"].size) if clock.on_clock else out["time"]
    for name, values in columns.items():
        if name == "time":
            continue
        if clock.on_clock and not clock.missing:
            out[name] = values
            continue
        out[name] = interpolated(at, held, values, name in angles)
    resampling = clock.to_dict()
    warning = clock.warning(path)
    return out, {**resampling, **({"note": warning} if warning else {})}, stretch


def rows_of_the_rates(path, columns: dict, blank: dict, rates: tuple, required: tuple, angles: tuple = ()
                      ) -> tuple[dict, str]:
    """A CSV with empty fields (a multi-rate export, as PlotJuggler's, or a spreadsheet's: a stream logged
    slower than the gyro leaves the rows between its samples empty) as rows of the gyro's samples.

    The rows where every one of ``rates`` has a value are the samples; every other column is interpolated
    linearly onto them from the rows where it has a value (angles unwrapped), as the flight-controller logs'
    slower streams are (:mod:`identification.io.resample`); the rows before the last and after the first
    value of the ``required`` columns that are present are dropped (interpolation would hold them).

    Parameters
    ----------
    path : str or Path
        The file, for messages.
    columns : dict of str to ndarray, shape (n,)
        ``"time"`` (strictly increasing) and the other columns, NaN where empty.
    blank : dict of str to ndarray of bool, shape (n,)
        Which fields of each column were empty.
    rates, required, angles : tuple of str
        The gyro's columns, the columns the flight needs where present, the columns holding angles [rad].

    Returns
    -------
    columns : dict
        The rows of the rates.
    note : str
        What was done, one line (a warning: the user should know).

    Raises
    ------
    FlightLogError
        A column with fewer than two values, or no row with every rate.
    """
    from ..errors import FlightLogError

    time = columns["time"]
    sampled = ~np.any([blank[c] for c in rates], axis=0)
    sparse = [c for c in columns if c != "time" and c not in rates and blank[c].any()]
    few = [c for c in (*rates, *sparse) if np.count_nonzero(~blank[c]) < 2]
    if few or np.count_nonzero(sampled) < 2:
        raise FlightLogError(f"{path}: column(s) {', '.join(few) or ', '.join(rates)} hold fewer than two values; "
                             "expected a value on most rows (an empty field is a row where the column was not logged)")
    keep = sampled.copy()
    for c in (c for c in required if c in sparse):
        logged = time[~blank[c]]
        keep &= (time >= logged[0]) & (time <= logged[-1])
    if np.count_nonzero(keep) < 2:
        raise FlightLogError(f"{path}: the rates and {', '.join(c for c in required if c in sparse)} share no "
                             "stretch of the flight")
    out = {name: values[keep] for name, values in columns.items() if name not in sparse}
    for c in sparse:
        logged = ~blank[c]
        out[c] = interpolated(time[keep], time[logged], columns[c][logged], c in angles)
    shares = sorted({f"{np.count_nonzero(~blank[c]) / time.size:.0%}" for c in sparse})
    note = (f"fields left empty: {', '.join(sparse) or 'none'} hold values on {' / '.join(shares) or '-'} of the "
            f"rows and were interpolated linearly between their values onto the rows of {', '.join(rates)}")
    dropped = time.size - np.count_nonzero(keep)
    if dropped:
        note += f"; {dropped} row(s) without a rate or outside every needed column's values not read"
    return out, note
