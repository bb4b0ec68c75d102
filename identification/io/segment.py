"""Airborne-segment detection: which part of a log is flight, and which is the ground.

Identification needs the aircraft in the air: on the ground the skids or legs
hold the attitude and the rate response to the inputs means nothing. The
detector works on the uniform grid of :func:`identification.io.raw_log.to_flight`
and combines three pieces of evidence, each computed over a sliding window of
:data:`WINDOW_S` seconds (moving averages, vectorised):

* **Power** -- the throttle / thrust demand (multirotor) or the collective with
  the rotor spooled (helicopter), normalised to 0..1 by the importer. Airborne
  needs ``power >= POWER_MIN``.
* **Vibration** -- RMS of the high-passed (> ~4 Hz) accelerometer magnitude
  (the gyro's when no accelerometer is logged). Spinning rotors shake the
  frame; airborne needs vibration at least ``VIBRATION_FACTOR`` times its
  level with the motors off (5th percentile of the samples with power below
  ``POWER_OFF``). Logs that start already armed (Betaflight logs only while
  armed) have no motors-off stretch of ``QUIET_MIN_S``; there the test is not
  applied and the summary says so. Vibration alone cannot tell a spooled-up
  helicopter on its skids from one in the air.
* **Attitude activity** -- the windowed standard deviation of roll and pitch
  (their larger one). A hovering aircraft wanders by degrees; one standing on
  the ground, even with the rotor spinning and the sticks stirred, by a fraction
  of a degree. Airborne needs ``activity >= ACTIVITY_MIN_RAD``, or, when the log
  holds an altitude estimate, a height of at least ``ALTITUDE_MIN_M`` above the
  ground level of the log.

The three are combined with AND, together with **upright**: roll and pitch
within ``UPRIGHT_MAX_RAD`` of level, with ``UPRIGHT_MARGIN_S`` either side of
any excursion removed too (a crashed aircraft lying on its side or back with
its motors still running must not count, nor the tumble before it). Holes shorter than ``HOLE_S`` are filled,
runs shorter than ``MIN_AIRBORNE_S`` discarded, and the longest remaining run,
trimmed by ``TRIM_S`` at both ends (take-off and touch-down transients), is the
segment (``segment="each"``: every remaining run, trimmed alike, a flight each).
Finding none raises :class:`~identification.io.errors.NotAirborneError`
with the figures that decided it, whether the vehicle was ever armed (when the log
says), and what to try next (``--segment all`` or ``T0:T1``).

Without an attitude stream (older Betaflight), the activity is the windowed
standard deviation of the roll and pitch angles integrated from the high-passed
rates (the gyro bias drops out), and upright comes from the accelerometer: the
low-passed specific force must point within ``UPRIGHT_MAX_RAD`` of the body's -z
axis (thrust keeps it there in flight; a craft lying on its side or back with the
motors running fails). Without an accelerometer either, upright is not checked and
the figures say so.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import uniform_filter1d

from .errors import NotAirborneError
from .resample import Stream, resample_stream, valid_on_grid, valid_runs

WINDOW_S = 2.0
"""s: window of the moving statistics."""
POWER_MIN = 0.15
"""Least power (throttle/thrust or spooled collective, 0..1) of an airborne sample."""
VIBRATION_FACTOR = 2.0
"""Airborne vibration is at least this multiple of the motors-off level."""
POWER_OFF = 0.02
"""Power below which the motors count as off (or idling) for the vibration reference."""
QUIET_MIN_S = 1.0
"""s: least motors-off time that makes a vibration reference."""
ACTIVITY_MIN_RAD = np.radians(0.5)
"""rad: least windowed standard deviation of roll or pitch of an airborne sample."""
ALTITUDE_MIN_M = 0.5
"""m: height above the log's ground level that counts as airborne on its own."""
UPRIGHT_MAX_RAD = np.radians(60.0)
"""rad: an aircraft rolled or pitched beyond this is not in the near-hover flight the models describe."""
UPRIGHT_MARGIN_S = 1.0
"""s: removed either side of a non-upright excursion (the tumble of a crash)."""
HOLE_S = 2.0
MIN_AIRBORNE_S = 3.0
TRIM_S = 0.5


@dataclass
class SegmentSignals:
    """Streams the airborne detector may use (any may be None).

    Attributes
    ----------
    power : Stream or None
        (1, n) throttle/thrust demand or spooled collective, 0..1.
    accel : Stream or None
        (3, n) specific force [m/s^2].
    altitude : Stream or None
        (1, n) height [m], up positive, any datum.
    armed : Stream or None
        (1, n) 1 while the vehicle is armed, 0 otherwise (for messages only: a log never armed says so).
    power_name : str
        What ``power`` is, for messages (name the topic/message and instance it came from).
    """

    power: Stream | None = None
    accel: Stream | None = None
    altitude: Stream | None = None
    armed: Stream | None = None
    power_name: str = "throttle"


@dataclass
class Detection:
    """Result of :func:`detect_airborne`: grid indices [start, stop) and the figures behind them."""

    start: int
    stop: int
    t_start: float
    t_stop: float
    airborne_s: float
    runs: list
    figures: dict
    run_rows: list = field(default_factory=list)
    """Grid indices [start, stop) of every airborne run, each trimmed as the longest is, in time order
    (``heli import --segment each`` writes each as a flight)."""

    def summary(self) -> dict:
        return {"segment": [self.t_start, self.t_stop], "airborne_runs_s": self.runs,
                "airborne_total_s": self.airborne_s, **self.figures}


def _moving(x: np.ndarray, n: int) -> np.ndarray:
    return uniform_filter1d(x, size=max(int(n), 1), axis=-1, mode="nearest")


def _moving_std(x: np.ndarray, n: int) -> np.ndarray:
    m = _moving(x, n)
    return np.sqrt(np.maximum(_moving(x * x, n) - m * m, 0.0))


def _close_holes(mask: np.ndarray, n_hole: int) -> np.ndarray:
    """Fill runs of False shorter than ``n_hole`` that lie between two runs of True."""
    out = mask.copy()
    runs = valid_runs(~mask)
    for a, b in runs:  # a few runs per log, not a loop per sample
        if a > 0 and b < mask.size and b - a < n_hole:
            out[a:b] = True
    return out


def _activity_from_rates(rates: np.ndarray, valid: np.ndarray, fs: float, w: int) -> np.ndarray:
    """Windowed std of roll/pitch angles integrated from high-passed rates (no attitude stream)."""
    pq = np.where(valid, rates[:2], 0.0)
    pq = pq - _moving(pq, w)  # the slowly varying gyro bias drops out
    angle = np.cumsum(pq, axis=1) / fs
    return _moving_std(angle, w).max(axis=0)


def airborne_features(grid: np.ndarray, signals: SegmentSignals, rates: np.ndarray, attitude: np.ndarray | None,
                      valid: np.ndarray) -> dict:
    """The per-sample evidence on the grid: power, vibration (and its motors-off level), activity, height.

    ``attitude`` may be None (no attitude stream): the activity then comes from the integrated rates.

    Returns
    -------
    dict of str to ndarray (m,); ``vibration_quiet`` is a float, or None without a motors-off stretch.
    """
    fs = 1.0 / float(grid[1] - grid[0])
    w = int(round(WINDOW_S * fs))
    feats: dict = {}
    if signals.power is not None:
        feats["power"] = np.where(valid_on_grid(grid, signals.power), resample_stream(signals.power, grid)[0], 0.0)
    if signals.accel is not None:
        acc = resample_stream(signals.accel, grid)
        mag = np.sqrt((acc * acc).sum(axis=0))
        src = "accelerometer"
    else:
        mag = np.sqrt((rates * rates).sum(axis=0))
        src = "gyro"
    hf = mag - _moving(mag, max(int(round(0.25 * fs)), 1))
    vib = np.sqrt(_moving(hf * hf, w))
    feats["vibration"] = vib
    feats["vibration_source"] = src
    off = valid & (feats["power"] < POWER_OFF) if "power" in feats else valid
    feats["vibration_quiet"] = float(np.percentile(vib[off], 5)) if off.sum() >= QUIET_MIN_S * fs else None
    if attitude is not None:
        feats["activity"] = _moving_std(np.unwrap(attitude[:2], axis=1), w).max(axis=0)
    else:
        feats["activity"] = _activity_from_rates(rates, valid, fs, w)
    if signals.accel is not None:
        feats["specific_force"] = acc
    if signals.altitude is not None:
        alt = resample_stream(signals.altitude, grid)[0]
        ok = valid_on_grid(grid, signals.altitude)
        ground = float(np.percentile(alt[ok], 5)) if ok.any() else 0.0
        feats["height"] = np.where(ok, alt - ground, 0.0)
    return feats


def _upright(attitude: np.ndarray | None, feats: dict, fs: float) -> tuple[np.ndarray | None, str]:
    """Per-sample "not tilted beyond UPRIGHT_MAX_RAD", from the attitude or else the accelerometer."""
    if attitude is not None:
        return (np.abs(attitude[0]) <= UPRIGHT_MAX_RAD) & (np.abs(attitude[1]) <= UPRIGHT_MAX_RAD), "attitude"
    if "specific_force" in feats:
        f = _moving(feats["specific_force"], max(int(round(0.5 * fs)), 1))
        norm = np.sqrt((f * f).sum(axis=0))
        return -f[2] >= np.cos(UPRIGHT_MAX_RAD) * np.maximum(norm, 1e-9), "accelerometer"
    return None, "not checked (no attitude, no accelerometer)"


def detect_airborne(grid: np.ndarray, signals: SegmentSignals, rates: np.ndarray, attitude: np.ndarray | None,
                    valid: np.ndarray, source: str = "log") -> Detection:
    """Find the longest airborne run of a log on its uniform grid (method in the module docstring).

    Parameters
    ----------
    grid : ndarray, shape (m,)
        Uniform times [s].
    signals : SegmentSignals
    rates : ndarray, shape (3, m)
        p, q, r on the grid [rad/s].
    attitude : ndarray, shape (3, m), or None
        phi, theta, psi on the grid [rad]; None when the log has no attitude stream.
    valid : ndarray of bool, shape (m,)
        Grid points where every stream of the flight has data (runs never cross a False).
    source : str
        Name of the log, for messages.

    Raises
    ------
    NotAirborneError
        No run of at least ``MIN_AIRBORNE_S`` seconds meets every criterion.
    """
    fs = 1.0 / float(grid[1] - grid[0])
    f = airborne_features(grid, signals, rates, attitude, valid)
    crit = {}
    if "power" in f:
        crit["power"] = f["power"] >= POWER_MIN
    quiet = f["vibration_quiet"]
    if quiet is not None:
        crit["vibration"] = f["vibration"] >= VIBRATION_FACTOR * quiet
    moving = f["activity"] >= ACTIVITY_MIN_RAD
    if "height" in f:
        moving = moving | (f["height"] >= ALTITUDE_MIN_M)
    crit["attitude_or_height"] = moving
    upright, upright_source = _upright(attitude, f, fs)
    if upright is not None:
        margin = int(round(UPRIGHT_MARGIN_S * fs))
        crit["upright"] = ~(_moving((~upright).astype(float), 2 * margin + 1) > 1e-9)
    air = valid.copy()
    for c in crit.values():
        air &= c
    air = _close_holes(air, int(round(HOLE_S * fs))) & valid
    runs = valid_runs(air)
    long = runs[(runs[:, 1] - runs[:, 0]) >= MIN_AIRBORNE_S * fs] if runs.size else runs
    figures = {
        "power_max": round(float(f["power"][valid].max()), 4) if "power" in f else None,
        "power_name": signals.power_name if "power" in f else None,
        "vibration_source": f["vibration_source"],
        "vibration_max_over_quiet": round(float(f["vibration"][valid].max() / quiet), 2) if quiet else None,
        "activity_max_deg": round(float(np.degrees(f["activity"][valid].max())), 3),
        "height_max_m": round(float(f["height"][valid].max()), 2) if "height" in f else None,
        "activity_source": "attitude" if attitude is not None else "rates integrated (no attitude stream)",
        "upright_source": upright_source,
        "criteria_share": {k: round(float(v.mean()), 4) for k, v in crit.items()},
    }
    if not len(long):
        raise NotAirborneError(_not_airborne_message(source, grid, valid, runs, f, figures, signals, crit))
    lengths = long[:, 1] - long[:, 0]
    trim = int(round(TRIM_S * fs))
    rows = [(int(i + trim), int(j - trim)) for i, j in long]
    a, b = rows[int(np.argmax(lengths))]
    return Detection(
        start=a, stop=b, t_start=float(grid[a]), t_stop=float(grid[b - 1]),
        airborne_s=round(float(lengths.sum() / fs), 3),
        runs=[[round(float(grid[i]), 3), round(float(grid[j - 1]), 3)] for i, j in long],
        figures=figures, run_rows=rows,
    )


def _armed_note(signals: SegmentSignals, grid: np.ndarray) -> str:
    """What the log says about arming, for the not-airborne message ('' if it says nothing)."""
    armed = signals.armed
    if armed is None:
        return ""
    on = armed.values[0] > 0.5
    if not on.any():
        return f"; the vehicle was never armed ({armed.name} is 0 throughout)"
    dt = np.diff(armed.time, append=armed.time[-1])
    return f"; armed for {float(dt[on].sum()):.1f} s ({armed.name})"


def _longest_s(mask: np.ndarray, valid: np.ndarray, fs: float) -> float:
    """The longest run of ``mask`` within the valid data [s], holes shorter than ``HOLE_S`` filled (as the
    detector fills them)."""
    runs = valid_runs(_close_holes(mask & valid, int(round(HOLE_S * fs))) & valid)
    return float((runs[:, 1] - runs[:, 0]).max() / fs) if runs.size else 0.0


def _failed_condition(crit: dict, valid: np.ndarray, fs: float, f: dict) -> str:
    """Which condition kept every run short: those that alone never hold ``MIN_AIRBORNE_S`` (each with its
    longest run), else the two that never hold together that long (a peak above a threshold says nothing
    about how long, or when, it lasts)."""
    names = {"power": f"power >= {POWER_MIN:.2f}", "vibration": f"vibration >= {VIBRATION_FACTOR:g}x motors-off",
             "attitude_or_height": f"activity >= {np.degrees(ACTIVITY_MIN_RAD):.1f} deg"
             + (f" or height >= {ALTITUDE_MIN_M:.1f} m" if "height" in f else ""), "upright": "upright"}
    alone = {k: _longest_s(c, valid, fs) for k, c in crit.items()}
    short = [k for k, v in alone.items() if v < MIN_AIRBORNE_S]
    if short:
        return "; ".join(f"'{names[k]}' " + (f"holds at most {alone[k]:.1f} s at a time" if alone[k] > 0 else
                                              "never holds") for k in short)
    keys = list(crit)
    pairs = [(_longest_s(crit[a] & crit[b], valid, fs), a, b) for i, a in enumerate(keys) for b in keys[i + 1:]]
    together, a, b = min(pairs) if pairs else (0.0, keys[0], keys[0])
    if together >= MIN_AIRBORNE_S:
        return f"each condition holds for {MIN_AIRBORNE_S:.0f} s alone, and each two together, but never all at once"
    return (f"each condition holds for {MIN_AIRBORNE_S:.0f} s alone, but '{names[a]}' and '{names[b]}' hold together "
            f"at most {together:.1f} s at a time")


def _not_airborne_message(source, grid, valid, runs, f, figures, signals, crit=None) -> str:
    """Why no airborne run was found: too little continuous data, or the criteria none of the runs met
    (``f``: :func:`airborne_features`; ``figures``: the peaks :func:`detect_airborne` records; ``crit``: each
    condition's mask, to name the one that failed)."""
    fs = 1.0 / float(grid[1] - grid[0])
    quiet = f["vibration_quiet"]
    best = float((runs[:, 1] - runs[:, 0]).max() / fs) if runs.size else 0.0
    longest_data = float((valid_runs(valid)[:, 1] - valid_runs(valid)[:, 0]).max() / fs)
    if longest_data < MIN_AIRBORNE_S:
        return (f"{source}: found no airborne segment: the log holds {longest_data:.2f} s of continuous data "
                f"({grid[0]:.3f}..{grid[-1]:.3f} s on its clock), less than the {MIN_AIRBORNE_S:.0f} s the airborne "
                f"detector needs{_armed_note(signals, grid)}. To import it as it is, pass segment='all' "
                "(heli import --segment all)")
    return (
        f"{source}: found no airborne segment: expected at least {MIN_AIRBORNE_S:.0f} s with "
        f"{'power >= %.2f, ' % POWER_MIN if 'power' in f else ''}"
        f"{'vibration >= %gx the motors-off level, ' % VIBRATION_FACTOR if quiet else ''}upright, "
        f"and roll/pitch activity >= {np.degrees(ACTIVITY_MIN_RAD):.1f} deg"
        f"{' or height >= %.1f m' % ALTITUDE_MIN_M if 'height' in f else ''}; got a longest such run of "
        f"{best:.1f} s{' (' + _failed_condition(crit, valid, fs, f) + ')' if crit else ''}; peaks: "
        f"{figures['power_name'] or 'power'} {figures['power_max']}, vibration "
        f"{figures['vibration_max_over_quiet']}x motors-off, activity {figures['activity_max_deg']} deg"
        f"{', height %s m' % figures['height_max_m'] if 'height' in f else ''}{_armed_note(signals, grid)}. "
        "The log looks like it never left the ground. To import it anyway, pass segment='all' "
        "(heli import --segment all) or a stretch T0:T1 of the log's clock (--segment T0:T1)"
    )
