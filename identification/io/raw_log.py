"""A decoded flight-controller log before resampling, and its conversion to a :class:`Flight`.

Each format reader (:mod:`.px4`, :mod:`.ardupilot`, :mod:`.blackbox`) decodes
its file into a :class:`RawLog`: the body-rate, attitude and input streams on
their own clocks, already in canonical units and signs (rad/s, rad, inputs in
[-1, 1] with a positive input driving a positive rate), plus the signals the
airborne detector uses. :func:`to_flight` then does what is common to every
format: choose the input source, resample onto one uniform grid
(:mod:`.resample`), choose the segment (:mod:`.segment`), clip the inputs to
[-1, 1] *counting* what was clipped, and build the validated :class:`Flight`
with its provenance in ``metadata``.

Input sources
-------------
``sticks``
    The pilot's sticks as the flight controller received them.
``controller``
    The rate controller's outputs (torque demands on roll, pitch, yaw, plus the
    thrust/collective demand): for a stabilised aircraft this is what the bare
    airframe actually receives from the autopilot, so it is the default.
``servos``
    Swash-plate servo positions converted back to cyclic/collective/pedal with
    the inverse mixing of eqs. (65)-(67); helicopters only.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from heli_core.files import sha256_of
from heli_core.quaternion import euler_rates

from ..flight import STICK_COLUMNS, Flight, make_flight
from .csv_log import sticks_from_servos
from .errors import DamagedLogError, InputSourceError, MissingStreamError, SegmentError
from .resample import DEFAULT_MAX_RATE, Stream, resample_stream, uniform_grid, valid_on_grid, valid_runs
from .segment import SegmentSignals, detect_airborne

INPUT_SOURCES = ("sticks", "controller", "servos")
CLIP_TOLERANCE = 1e-3
"""Inputs beyond [-1, 1] by less than this are clipped without being counted (filter ringing)."""

H3_120_SERVO_AZIMUTH_DEG = {"u_aile": -60.0, "u_aux": 60.0, "u_elev": 180.0}
"""Default 120-degree CCPM (H3-120) layout: azimuth of each swash servo [deg], 0 = nose, positive to the right."""
H3_120_THROW_US = 500.0
"""Default servo throw [us] for a full stick (|delta| = 1) in the default H3-120 mixing."""
H3_120_TRIM_US = 1500.0
"""Default servo centre [us]."""


def h3_120_calibration(throw_us: float = H3_120_THROW_US, trim_us: float = H3_120_TRIM_US) -> dict:
    """Default mixing of eq. (66) for a 120-degree CCPM swash plate (H3-120) and a tail servo.

    A swash servo at azimuth ``a`` (0 = nose, 90 = right side) moves by
    ``throw * (col + lon * cos(a) - lat * sin(a))``: collective lifts all three;
    positive ``lon`` (nose-up pitch rate) raises the front of the plate, positive
    ``lat`` (roll right) lowers its right side. The tail servo (``u_rudd``) moves by
    ``throw * ped``. Servos are assumed un-reversed with a larger pulse lifting the
    plate; a real helicopter's reversals, throws and phase angle belong in a
    calibration file (``{"G": 4x4, "U_trim": 4}``, as :func:`read_servo_csv`).

    Returns
    -------
    dict
        ``{"G": 4x4 list (rows u_aile, u_aux, u_elev, u_rudd; columns lon, lat, col, ped) [us],
        "U_trim": 4 list [us], "name": "H3-120 default"}``.
    """
    rows = []
    for name in ("u_aile", "u_aux", "u_elev"):
        a = np.radians(H3_120_SERVO_AZIMUTH_DEG[name])
        rows.append([throw_us * np.cos(a), -throw_us * np.sin(a), throw_us, 0.0])
    rows.append([0.0, 0.0, 0.0, throw_us])
    G = np.round(np.array(rows), 9)
    return {"G": G.tolist(), "U_trim": [trim_us] * 4, "name": "H3-120 default"}


@dataclass
class RawLog:
    """A decoded log: streams on their own clocks, in canonical units and signs.

    Attributes
    ----------
    path : Path
    format : str
        ``"px4-ulog"``, ``"ardupilot-dataflash"``, ``"betaflight-blackbox"``, ``"rotorflight-blackbox"``.
    vehicle : str
        ``"multirotor"``, ``"helicopter"`` or another short description.
    rates : Stream
        p, q, r [rad/s], shape (3, n).
    attitude : Stream or None
        phi, theta, psi [rad], shape (3, n).
    inputs : dict of str to Stream
        Input source -> (4, n) stream in the canonical order lat, lon, col, ped.
    input_notes : dict of str to str
        Input source -> the streams, scaling and signs used (recorded in the metadata).
    unavailable : dict of str to str
        Input source -> why this log cannot provide it.
    default_input : str
    servos : Stream or None
        Servo pulse widths u_aile, u_aux, u_elev, u_rudd [us] (helicopters), converted with eq. (67).
    segment_signals : SegmentSignals
        Streams the airborne detector uses.
    metadata : dict
    damage : list of str
        What was found corrupt inside the log (empty for a sound log); refused unless ``allow_damaged``.
    notes : list of str
        What a real logger writes and the import tolerated, one line each: a cut last message that
        was dropped, padding, a clock restart, frames of unknown type skipped. Kept in
        ``metadata["import_warnings"]`` and printed by ``heli import``.
    """

    path: Path
    format: str
    vehicle: str
    rates: Stream
    attitude: Stream | None
    inputs: dict
    input_notes: dict
    unavailable: dict
    default_input: str
    segment_signals: SegmentSignals
    servos: Stream | None = None
    metadata: dict = field(default_factory=dict)
    damage: list = field(default_factory=list)
    notes: list = field(default_factory=list)


@contextlib.contextmanager
def captured_output():
    """Capture what a parser prints to stdout/stderr, at the file-descriptor level.

    Some parsers print from C extensions (pymavlink's indexer prints one line per
    skipped byte). Yields a list that receives the captured lines on exit.
    """
    lines: list[str] = []
    saved = []
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        try:
            for fd in (1, 2):
                try:
                    os.fsync(fd)
                except OSError:
                    pass
                saved.append((fd, os.dup(fd)))
                os.dup2(tmp.fileno(), fd)
            with contextlib.redirect_stdout(_FdText(1)), contextlib.redirect_stderr(_FdText(2)):
                yield lines
        finally:
            for fd, copy in saved:
                os.dup2(copy, fd)
                os.close(copy)
            tmp.seek(0)
            lines.extend(tmp.read().decode("utf-8", "replace").splitlines())


class _FdText:
    """A text stream writing straight to a file descriptor (so Python prints land in the capture too)."""

    def __init__(self, fd):
        self.fd = fd

    def write(self, s):
        os.write(self.fd, s.encode("utf-8", "replace"))
        return len(s)

    def flush(self):
        pass


def check_damage(raw_damage: list, path, allow_damaged: bool, fmt: str) -> None:
    """Raise :class:`DamagedLogError` for a log damaged in the middle unless the caller accepts it."""
    if raw_damage and not allow_damaged:
        raise DamagedLogError(
            f"{path}: the {fmt} log is damaged in the middle: {'; '.join(raw_damage)}. Expected a log that decodes "
            "throughout; pass allow_damaged=True (heli import --allow-damaged) to import what decodes"
        )


def _parse_segment(segment):
    """None/"auto"/"all"/"each"/(t0, t1)/"T0:T1" -> ("auto"|"all"|"each"|"range", (t0, t1) or None)."""
    if segment is None or segment == "auto":
        return "auto", None
    if segment in ("all", "each"):
        return segment, None
    if isinstance(segment, str):
        try:
            a, b = segment.split(":")
            t0, t1 = float(a), float(b)
        except ValueError:
            raise SegmentError(f"segment must be 'auto', 'all' or 'T0:T1' in seconds, got {segment!r}") from None
    else:
        try:
            t0, t1 = (float(v) for v in segment)
        except (TypeError, ValueError):
            raise SegmentError(f"segment must be 'auto', 'all' or (t0, t1) in seconds, got {segment!r}") from None
    if not (np.isfinite(t0) and np.isfinite(t1) and t1 > t0):
        raise SegmentError(f"segment needs finite t0 < t1, got {t0}:{t1}")
    return "range", (t0, t1)


def _choose_input(raw: RawLog, inputs: str | None, calibration) -> tuple[str, Stream, dict]:
    source = raw.default_input if inputs is None else inputs
    if source not in INPUT_SOURCES:
        raise InputSourceError(f"input source must be one of {', '.join(INPUT_SOURCES)}, got {source!r}")
    offered = sorted(set(raw.inputs) | ({"servos"} if raw.servos is not None else set()))
    hint = f"; this log offers --inputs {'|'.join(offered)}" if offered else ""
    meta: dict = {}
    if source == "servos":
        if raw.servos is None:
            reason = raw.unavailable.get("servos", "the log holds no servo outputs")
            raise InputSourceError(f"{raw.path}: input source 'servos' does not apply: {reason}{hint}")
        cal = _load_calibration(calibration) if calibration is not None else h3_120_calibration()
        sticks = sticks_from_servos(raw.servos.values, cal["G"], cal["U_trim"])
        stream = Stream(raw.servos.time, sticks, raw.servos.name + " via eq. (67)", dropped=raw.servos.dropped)
        meta["servo_calibration"] = cal
        return source, stream, meta
    if calibration is not None:
        raise InputSourceError(f"a servo calibration applies to inputs='servos' only, not {source!r}")
    if source not in raw.inputs:
        reason = raw.unavailable.get(source, "the log lacks its streams")
        raise InputSourceError(f"{raw.path}: input source {source!r} is not available: {reason}{hint}")
    return source, raw.inputs[source], meta


def _load_calibration(calibration) -> dict:
    import json

    from ..errors import FlightLogError

    if isinstance(calibration, dict):
        cal = dict(calibration)
    else:
        try:
            cal = json.loads(Path(calibration).read_text())
        except (OSError, ValueError) as e:
            raise FlightLogError(f"servo calibration {str(calibration)!r} is not a readable JSON file: {e}") from e
    for key in ("G", "U_trim"):
        if key not in cal:
            raise FlightLogError(f"servo calibration lacks {key!r}; expected keys 'G' (4x4) and 'U_trim' (4)")
    return cal


MAX_SPAN_FACTOR = 20.0
"""A log whose streams span more than this many times the time its gyro stream covers (plus an hour) has a
corrupt clock: building a grid over it would only fill memory with gaps."""


def _covered_s(stream: Stream) -> float:
    """Time [s] a stream covers without gaps."""
    from .resample import gap_threshold

    dt = np.diff(stream.time)
    return float(dt[dt <= gap_threshold(stream)].sum())


def to_flight(raw: RawLog, inputs: str | None = None, segment=None, rate: float | None = None,
              calibration=None) -> Flight:
    """Resample a decoded log onto a uniform grid, pick the segment and build the :class:`Flight`.

    Parameters
    ----------
    raw : RawLog
    inputs : {"sticks", "controller", "servos"} or None
        Input source; None takes the format's default (the one closest to the bare airframe).
    segment : "auto", "all", (t0, t1), "T0:T1" or None
        "auto" (the default): the longest airborne run found by
        :func:`~identification.io.segment.detect_airborne`; "all": the longest
        stretch without a gap; (t0, t1): that span of the log's clock [s]. Every airborne run, each a
        flight: :func:`to_flights`.
    rate : float, optional
        Grid rate [Hz]; default the gyro stream's rate, at most 200 Hz.
    calibration : dict or path, optional
        Servo mixing ``{"G": 4x4, "U_trim": 4}`` for ``inputs="servos"`` (default: H3-120).

    Without an attitude stream the flight's attitude is reconstructed from the rates
    (eqs. 25-29, :func:`~identification.flight.make_flight`) and a warning says so.

    Raises
    ------
    InputSourceError, MissingStreamError, NotAirborneError, SegmentError, DamagedLogError
    """
    mode, span = _parse_segment(segment)
    if mode == "each":
        raise SegmentError("segment 'each' makes a flight of every airborne run: read it with "
                           "identification.io.read_log_runs (heli import --segment each)")
    on = _on_grid(raw, inputs, span, rate, calibration)
    detection = None
    if mode == "auto":
        detection = detect_airborne(on.grid, raw.segment_signals, on.rates, on.att, on.valid, source=str(raw.path))
        i0, i1 = detection.start, detection.stop
        on = on._replace(warnings=on.warnings + _runs_left_out(detection, on.grid_rate))
    else:
        i0, i1 = _chosen_rows(raw, mode, span, on.grid, on.grid_rate, on.valid)
    if i1 - i0 < 2:
        if mode == "all":
            raise SegmentError(f"{raw.path}: the longest stretch of the log without a gap holds {i1 - i0} sample(s) "
                               f"at {on.grid_rate:g} Hz; there is no flight to import")
        raise SegmentError(f"{raw.path}: the chosen segment holds {i1 - i0} samples; pass --segment all or a "
                           "longer T0:T1")
    return _cut(raw, on, int(i0), int(i1), mode, detection)


def to_flights(raw: RawLog, inputs: str | None = None, rate: float | None = None, calibration=None) -> list:
    """Every airborne run of the log (:func:`~identification.io.segment.detect_airborne`: at least
    ``MIN_AIRBORNE_S`` long, each trimmed as the longest is) as a :class:`Flight` of its own, in time order:
    a log of several take-offs, or of a flight the detector cut where the aircraft sat for a moment, gives
    all its airborne data, where :func:`to_flight` gives the longest run. Each flight's metadata has
    ``segment_mode`` "each" and ``airborne_run`` ``{"index": k, "of": n}`` (from 1). Arguments and errors
    as :func:`to_flight`'s."""
    on = _on_grid(raw, inputs, None, rate, calibration)
    detection = detect_airborne(on.grid, raw.segment_signals, on.rates, on.att, on.valid, source=str(raw.path))
    n = len(detection.run_rows)
    return [_cut(raw, on, a, b, "each", detection, {"index": k + 1, "of": n})
            for k, (a, b) in enumerate(detection.run_rows)]


def _runs_left_out(detection, grid_rate: float) -> list:
    """A warning naming the airborne runs besides the longest, which a flight of the longest leaves out ([] when
    there is one run)."""
    runs = detection.runs
    if len(runs) < 2:
        return []
    spans = [b - a for a, b in runs]
    listed = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in runs)
    kept = (detection.stop - detection.start) / grid_rate
    return [f"the log holds {len(runs)} airborne runs ({listed}): this flight is the longest ({kept:.1f} s "
            f"trimmed), the other {len(runs) - 1}'s {sum(spans) - max(spans):.1f} s are left out; heli import "
            "--segment each writes every run as a CSV of its own, which heli identify takes together (Python: "
            "identification.io.read_log_runs)"]


class _OnGrid(NamedTuple):
    """A decoded log's streams on its uniform grid (:func:`_on_grid`), before a segment is cut."""

    grid: np.ndarray
    valid: np.ndarray
    rates: np.ndarray
    att: np.ndarray | None
    sticks: np.ndarray
    source: str
    extra_meta: dict
    warnings: list
    used: list
    grid_rate: float


def _on_grid(raw: RawLog, inputs, span, rate, calibration) -> _OnGrid:
    """The input source chosen and the rates, attitude and inputs resampled onto the grid (``span`` limits
    it when given)."""
    source, input_stream, extra_meta = _choose_input(raw, inputs, calibration)
    used = [raw.rates, input_stream] + ([raw.attitude] if raw.attitude is not None else [])
    what = f"rates, {'attitude and ' if raw.attitude is not None else ''}{source}"
    grid_rate = float(rate) if rate is not None else min(raw.rates.rate, DEFAULT_MAX_RATE)
    if not (np.isfinite(grid_rate) and grid_rate > 0):
        raise SegmentError(f"grid rate must be a positive number of Hz, got {rate!r}")
    grid = _grid(raw, used, what, source, span, grid_rate)
    valid = np.ones(grid.size, dtype=bool)
    for s in used:
        valid &= valid_on_grid(grid, s)
    if not valid.any():
        raise SegmentError(f"{raw.path}: no stretch of the log holds all of {what} without a gap")
    return _OnGrid(grid, valid, resample_stream(raw.rates, grid),
                   resample_stream(raw.attitude, grid) if raw.attitude is not None else None,
                   resample_stream(input_stream, grid), source, extra_meta, list(raw.notes), used, grid_rate)


def _cut(raw: RawLog, on: _OnGrid, i0: int, i1: int, mode: str, detection, run: dict | None = None) -> Flight:
    """The flight of grid rows [i0, i1): inputs clipped to [-1, 1] (counted), metadata written."""
    sl = slice(i0, i1)
    sticks = on.sticks[:, sl]
    # Count what is really out of range; the anti-alias filter's ringing at a step (< 0.1 %) is clipped silently.
    clipped = {name: int((np.abs(sticks[i]) > 1.0 + CLIP_TOLERANCE).sum()) for i, name in enumerate(STICK_COLUMNS)}
    sticks = np.clip(sticks, -1.0, 1.0)
    warnings = list(on.warnings)
    if on.att is None:
        warnings.append("the log has no attitude stream (older firmware): the attitude is reconstructed from the "
                        "rates (eqs. 25-29), starting level")
    meta = _provenance(raw, on.source, on.extra_meta, clipped, _resampling(on.used, on.grid_rate),
                       [float(on.grid[i0]), float(on.grid[i1 - 1])], mode)
    if detection is not None:
        meta["airborne_detection"] = detection.summary()
    if run is not None:
        meta["airborne_run"] = run
    if raw.damage:
        meta["damage"] = list(raw.damage)
    if warnings:
        meta["import_warnings"] = warnings
    return make_flight(on.grid[sl], on.rates[:, sl], sticks, attitude=None if on.att is None else on.att[:, sl],
                       metadata=meta, units_from=f"{raw.format} log")


def _grid(raw: RawLog, used: list, what: str, source: str, span, grid_rate: float) -> np.ndarray:
    """The uniform grid [s] over the time all ``used`` streams cover (only ``span`` of it when one is asked for).

    Raises
    ------
    MissingStreamError
        The streams overlap for less than two grid steps.
    SegmentError
        ``span`` lies outside the log's data.
    DamagedLogError
        The streams span far more time than the gyro stream covers (a corrupt clock).
    """
    t0 = max(s.time[0] for s in used)
    t1 = min(s.time[-1] for s in used)
    if t1 - t0 < 2.0 / grid_rate:
        spans = ", ".join(f"{s.name} {s.span[0]:.3f}..{s.span[1]:.3f} s" for s in used)
        others = [k for k in raw.inputs if k != source]
        hint = f"; another input source may cover more (--inputs {'|'.join(others)})" if others else ""
        raise MissingStreamError(
            f"{raw.path}: the {what} streams overlap for {max(t1 - t0, 0.0):.3f} s only ({spans}){hint}"
        )
    if span is not None:  # only the asked-for part of the clock is gridded
        t0, t1 = max(t0, span[0] - 1.0 / grid_rate), min(t1, span[1] + 1.0 / grid_rate)
        if t1 - t0 < 2.0 / grid_rate:
            raise SegmentError(
                f"{raw.path}: segment {span[0]}:{span[1]} s lies outside the log's data, which spans "
                f"{max(s.time[0] for s in used):.3f}:{min(s.time[-1] for s in used):.3f} s (the log's own clock); "
                "pass --segment all for the whole log"
            )
    elif (t1 - t0) > MAX_SPAN_FACTOR * _covered_s(raw.rates) + 3600.0:
        raise DamagedLogError(
            f"{raw.path}: the log's time stamps span {t1 - t0:.4g} s but its gyro stream ({raw.rates.name}) covers "
            f"only {_covered_s(raw.rates):.4g} s of it: the clock is corrupt; choose a stretch with --segment T0:T1"
        )
    return uniform_grid(t0, t1, grid_rate)


def _chosen_rows(raw: RawLog, mode: str, span, grid: np.ndarray, grid_rate: float, valid: np.ndarray):
    """Rows (i0, i1) of the grid of segment ``"all"`` (the longest run without a gap) or of ``span``.

    Raises
    ------
    SegmentError
        ``span`` lies outside the grid or spans a gap in the data.
    """
    if mode == "all":
        runs = valid_runs(valid)
        return runs[np.argmax(runs[:, 1] - runs[:, 0])]
    a, b = span
    if a < grid[0] - 1.5 / grid_rate or b > grid[-1] + 1.5 / grid_rate:
        raise SegmentError(
            f"{raw.path}: segment {a}:{b} s lies outside the log's data, which spans "
            f"{grid[0]:.3f}:{grid[-1]:.3f} s (the log's own clock); pass --segment all for the whole log"
        )
    i0 = int(np.searchsorted(grid, a - 1e-9))
    i1 = int(np.searchsorted(grid, b + 1e-9))
    if not valid[i0:i1].all():
        bad = i0 + int(np.argmin(valid[i0:i1]))
        raise SegmentError(
            f"{raw.path}: segment {a}:{b} s spans a gap in the logged data at t={grid[bad]:.3f} s; "
            "choose a segment inside one continuous stretch (--segment all takes the longest)"
        )
    return i0, i1


def _resampling(used: list, grid_rate: float) -> dict:
    """How the streams were put on the grid (``metadata["resampling"]``)."""
    return {
        "rate_hz": grid_rate,
        "method": "linear interpolation; zero-phase 4th-order Butterworth at 0.4x the grid rate on faster "
                  "streams first; angles unwrapped",
        "streams": {s.name: round(s.rate, 3) for s in used},
        "dropped_samples": {s.name: s.dropped for s in used if s.dropped},
    }


def _provenance(raw: RawLog, source: str, extra_meta: dict, clipped: dict, resampling: dict, segment: list,
                mode: str) -> dict:
    """The flight's metadata: where it came from, how its inputs were mapped and clipped, resampled, cut."""
    return {
        "source": raw.path.name,
        "sha256": sha256_of(raw.path),
        "format": raw.format,
        "vehicle": raw.vehicle,
        "input_source": source,
        "input_mapping": raw.input_notes.get(source, extra_meta.get("servo_calibration", {}).get("name", "")),
        "inputs_clipped": clipped,
        "units": {"time": "s (the log's own clock)", "rates": "rad/s", "attitude": "rad", "sticks": "[-1, 1]"},
        "resampling": resampling,
        "segment": segment,
        "segment_mode": mode,
        **{k: v for k, v in raw.metadata.items()},
        **extra_meta,
    }


def rate_attitude_agreement(flight: Flight, cutoff_hz: float = 2.0) -> dict:
    """Correlation, per axis, of the attitude's derivative with the body rates (a check of units and signs).

    The Euler-angle rates implied by p, q, r (ZYX kinematics,
    ``phi' = p + (q sin(phi) + r cos(phi)) tan(theta)``, ``theta' = q cos(phi) - r sin(phi)``,
    ``psi' = (q sin(phi) + r cos(phi)) / cos(theta)``) are compared with the numerical derivative
    of the logged (unwrapped) angles, both low-passed at ``cutoff_hz`` with a zero-phase
    Butterworth filter (attitude streams are often logged slower than the gyro).
    A correlation near +1 says the mapping is right; near -1, a sign is flipped.

    Returns
    -------
    dict
        ``{"roll": r, "pitch": r, "yaw": r}`` Pearson correlations; ``None`` for an axis that does not move.
    """
    from scipy import signal

    t, (p, q, r) = flight.time, flight.rates
    phi, theta, psi = np.unwrap(flight.attitude, axis=1)
    angle_rates = euler_rates(phi, theta, p, q, r)
    deriv = np.gradient(np.array([phi, theta, psi]), t, axis=1)
    fs = flight.sample_rate
    if cutoff_hz < 0.5 * fs and flight.n > 30:
        sos = signal.butter(2, cutoff_hz, fs=fs, output="sos")
        angle_rates = signal.sosfiltfilt(sos, angle_rates, axis=1)
        deriv = signal.sosfiltfilt(sos, deriv, axis=1)
    out = {}
    for i, axis in enumerate(("roll", "pitch", "yaw")):
        a, b = deriv[i], angle_rates[i]
        out[axis] = None if np.std(a) < 1e-9 or np.std(b) < 1e-9 else round(float(np.corrcoef(a, b)[0, 1]), 4)
    return out
