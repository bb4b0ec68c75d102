"""A log's clock made monotonic: clock restarts, counter wrap-around and single corrupt time stamps.

Flight controllers stamp samples with the time since boot. Within one log that
clock can still misbehave:

* **Wrap-around.** Betaflight/Rotorflight stamp frames with a 32-bit microsecond
  counter, which wraps after 4294.967296 s (71.6 min after power-up).
* **Restart.** A log that spans a reboot of the flight controller (a DataFlash
  chip written on, a log continued by the logger) restarts its clock near zero.
* **Glitch.** A single corrupt time stamp far ahead of its neighbours.

:func:`continue_clock` turns such a clock into one that only increases, so the
resampling of :mod:`.resample` can use it: a glitch is dropped; a wrap-around is
undone exactly (the counter's period is added); after a restart the clock is
continued from where it stopped plus :data:`RESTART_GAP_S`, a gap the segment
choice never crosses. Each event is recorded (the flight's ``metadata["clock"]``)
so a time on the continued clock can be traced back to the log's own clock.
Backward steps smaller than :data:`RESTART_MIN_S` are jitter between message types
or decoder glitches, left to :func:`.resample.make_stream` (which drops them).
"""

from __future__ import annotations

import numpy as np

RESTART_MIN_S = 1.0
"""s: a step back in time larger than this is a clock restart (or wrap-around), not jitter."""
RESTART_GAP_S = 1.0
"""s: the continued clock resumes this long after the last sample before a restart (a gap in the data)."""
UINT32_US_PERIOD_S = 2.0**32 * 1e-6
"""s: period of a 32-bit microsecond counter (4294.967296 s)."""
WRAP_TOLERANCE_S = 5.0
"""s: a step back within this of the counter period is a wrap-around."""
MAX_EVENTS = 50
"""More restarts than this mean the time stamps are garbage, not a clock that restarted."""


def _drop_glitches(t: np.ndarray) -> np.ndarray:
    """Mask of samples to keep: a sample far ahead of both neighbours (the next continues from the previous) goes."""
    keep = np.ones(t.size, dtype=bool)
    if t.size >= 3:
        mid = t[1:-1]
        glitch = (mid > t[2:] + RESTART_MIN_S) & (t[2:] >= t[:-2])
        keep[1:-1] = ~glitch
    return keep


def continue_clock(time) -> tuple[np.ndarray, np.ndarray, list]:
    """Make a log's clock monotonic across restarts and wrap-arounds (method in the module docstring).

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times [s] in log order (file order), on the log's own clock.

    Returns
    -------
    time : ndarray, shape (m,)
        The continued clock [s] of the kept samples.
    keep : ndarray of bool, shape (n,)
        Which input samples were kept (glitches are dropped).
    events : list of dict
        One per restart or wrap-around: ``{"kind": "restart"|"wrap-around", "last_before_s", "first_after_s":
        the log's own clock at the last sample before and the first after it, "offset_s": what was added to
        the clock from that sample on (cumulative)}``.
    """
    t = np.array(time, dtype=float)
    finite = np.isfinite(t)
    keep = finite.copy()
    keep[finite] = _drop_glitches(t[finite])
    t = t[keep]
    events: list = []
    start, total = 1, 0.0
    while t.size > 1 and len(events) < MAX_EVENTS:
        run = np.maximum.accumulate(t[start - 1:])
        back = np.flatnonzero(t[start:] < run[:-1] - RESTART_MIN_S)
        if not back.size:
            break
        i = start + int(back[0])
        before = float(run[i - start])
        step = float(t[i]) - before
        if abs(step + UINT32_US_PERIOD_S) < WRAP_TOLERANCE_S:
            offset, kind = UINT32_US_PERIOD_S, "wrap-around"
        else:
            offset, kind = before + RESTART_GAP_S - float(t[i]), "restart"
        total += offset
        events.append({"kind": kind, "last_before_s": round(before - total + offset, 6),
                       "first_after_s": round(float(t[i]) - total + offset, 6), "offset_s": round(total, 6)})
        t[i:] += offset
        start = i + 1
    return t, keep, events


def describe(events: list) -> str | None:
    """One line for the terminal about the clock events, or None."""
    if not events:
        return None
    kinds = {k: sum(e["kind"] == k for e in events) for k in ("restart", "wrap-around")}
    what = ", ".join(f"{n} {k}{'s' if n > 1 else ''}" for k, n in kinds.items() if n)
    first = events[0]
    return (f"the log's clock is not monotonic ({what}; first from {first['last_before_s']:.3f} s back to "
            f"{first['first_after_s']:.3f} s): continued it (metadata 'clock' lists the offsets); "
            "no segment spans a restart")
