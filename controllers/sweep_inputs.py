"""What a gain sweep replays: gains and ranges checked, library windows chosen and gathered once.

A sweep (:mod:`controllers.sweep`) flies every gain pair against the same
windows ``(trace, offset)`` of the model's disturbance library. This module turns
the user's settings into those windows — explicit, each trace whole, tiling every
trace end to end (the default: the whole library flown once, :func:`tile_windows`),
or a number of them drawn with ``numpy.random.default_rng(seed)``
(:func:`heli_env.tasks.draw_offsets`, the package's one window sampler) — and gathers what the replay holds over each
control period (:class:`controllers.replay.LoopInputs`): the trim for the
recorded collective, the collective, and the gust torque ``k·u_d`` each trace was
identified with. Every bad setting is a :class:`~controllers.errors.SweepError`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from heli_core.control_period import default_dt
from heli_core.physics import trim_sticks
from heli_env.tasks import draw_offsets, window_count

from .closed_loop import axis_index
from .errors import SweepError
from .replay import LoopInputs
from .sweep_interval import trace_blocks


def check_gains(values, name: str) -> np.ndarray:
    """Gain values as a 1-D float array; :class:`SweepError` if empty, non-finite or negative."""
    try:
        arr = np.atleast_1d(np.asarray(values, dtype=float))
    except (TypeError, ValueError) as e:
        raise SweepError(f"{name} must be numbers, got {values!r}") from e
    if arr.ndim != 1 or arr.size == 0:
        raise SweepError(f"{name} must be a non-empty 1-D sequence of gains, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise SweepError(f"{name} must be finite, got {arr.tolist()}")
    if np.any(arr < 0):
        raise SweepError(f"{name} must be >= 0 (the sign of the control gain is applied by the law), "
                         f"got {arr[arr < 0].tolist()}")
    return arr


def check_pairs(pairs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(pairs as an (n, 2) array, kp, kd)``; :class:`SweepError` unless a non-empty list of valid (kp, kd)."""
    arr = np.asarray(pairs, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
        raise SweepError(f"pairs must be a non-empty list of (kp, kd), got shape {arr.shape}")
    return arr, check_gains(arr[:, 0], "kp of pairs"), check_gains(arr[:, 1], "kd of pairs")


def parse_range(text: str, name: str = "range") -> np.ndarray:
    """Parse ``"A:B:N"`` (N evenly spaced values from A to B inclusive) or a single value ``"A"``.

    Raises :class:`SweepError` for an empty (N < 1), non-integer N, non-finite,
    reversed (A > B) or negative range, and for N = 1 with A ≠ B.
    """
    parts = str(text).split(":")
    try:
        if len(parts) == 1:
            a = b = float(parts[0])
            n = 1
        elif len(parts) == 3:
            a, b = float(parts[0]), float(parts[1])
            nf = float(parts[2])
            if not math.isfinite(nf) or nf != int(nf):
                raise SweepError(f"{name} {text!r}: N must be a whole number of values, got {parts[2]!r}")
            n = int(nf)
        else:
            raise SweepError(f"{name} {text!r}: expected A:B:N (N values from A to B) or a single value")
    except ValueError as e:
        if isinstance(e, SweepError):
            raise
        raise SweepError(f"{name} {text!r}: A, B and N must be numbers") from e
    if not (math.isfinite(a) and math.isfinite(b)):
        raise SweepError(f"{name} {text!r}: bounds must be finite")
    if n < 1:
        raise SweepError(f"{name} {text!r}: empty range, N must be >= 1")
    if a > b:
        raise SweepError(f"{name} {text!r}: reversed range, A = {a:g} > B = {b:g}")
    if a < 0:
        raise SweepError(f"{name} {text!r}: gains must be >= 0, got A = {a:g}")
    if n == 1 and a != b:
        raise SweepError(f"{name} {text!r}: N = 1 needs A = B (or give a single value)")
    return np.linspace(a, b, n)


def load_model(model):
    """An :class:`heli_env.env_model.EnvModel` from a directory, None (the shipped model) or itself.

    A missing or corrupt model directory is a :class:`SweepError`.
    """
    from heli_env.env_model import as_env_model

    try:
        return as_env_model(model)
    except ValueError as e:  # EnvModelError: missing or corrupt model directory
        raise SweepError(str(e)) from e


@dataclass(frozen=True, eq=False)
class LibraryReplay:
    """What the sweep's replay needs, checked and gathered once.

    Attributes
    ----------
    env_model : EnvModel or None
        The library (None in the copy shipped to a backend's workers: the replay needs only params).
    params : ModelParams
    axis : int
        Swept axis.
    dt : float
        Control period [s].
    ratio : int
        Library samples per control period.
    steps : int
        Control periods per window.
    windows : tuple of (trace, offset)
    inputs : LoopInputs
        Trim, collective and gust torque per period, shape (..., steps, windows).
    blocks : tuple (ndarray (steps, windows), ndarray (n, 2)) or None
        The block of trace time of every period of every window and the pairs of adjacent blocks
        (:func:`controllers.sweep_interval.trace_blocks`), for the p90s' intervals; None: no intervals.
    """

    env_model: object
    params: object
    axis: int
    dt: float
    ratio: int
    steps: int
    windows: tuple
    inputs: LoopInputs
    blocks: tuple | None = None


def _explicit(traces) -> bool:
    """Whether ``traces`` lists explicit (trace, offset) windows rather than trace indices."""
    return traces is not None and len(traces) > 0 and np.ndim(traces[0]) == 1


def _explicit_windows(env_model, traces, needed) -> tuple:
    """Explicit (trace, offset) windows as ints, each checked to hold ``needed`` samples from its offset."""
    n_tr = env_model.n_traces
    lengths = env_model.lengths
    out = []
    for t, off in traces:
        t, off = int(t), int(off)
        if not 0 <= t < n_tr:
            raise SweepError(f"trace index {t} out of range: the library holds {n_tr} traces")
        if not 0 <= off <= lengths[t] - needed:
            raise SweepError(f"window ({t}, {off}) does not fit: trace {t} has {int(lengths[t])} samples, "
                             f"a window needs {needed} from its offset")
        out.append((t, off))
    return tuple(out)


def _trace_list(env_model, traces) -> list:
    """Selected trace indices as ints (default all), each checked to be in the library."""
    n_tr = env_model.n_traces
    sel = list(range(n_tr)) if traces is None else [int(t) for t in traces]
    if not sel:
        raise SweepError("traces must name at least one library trace")
    for t in sel:
        if not 0 <= t < n_tr:
            raise SweepError(f"trace index {t} out of range: the library holds {n_tr} traces")
    return sel


def _longest_window(env_model, sel) -> str:
    """The advice of a window too long for a trace: the longest duration that fits every selected trace."""
    longest = math.floor(100.0 * (min(int(env_model.lengths[t]) for t in sel) - 1) / env_model.sample_rate) / 100.0
    return f"; the longest that fits every trace is {longest:g} s: pass duration={longest:g} or less"


def tile_windows(env_model, sel, steps: int, ratio: int, seed) -> tuple:
    """Windows that tile each selected trace end to end: every stretch of the library flown once.

    A trace of ``L`` samples holds ``m = max(1, (L - 1) // (steps * ratio))`` windows; they follow each other
    (one shares its first sample with the last of the one before) from an offset drawn with
    ``Generator(seed)`` in the ``L - 1 - m * steps * ratio`` samples left over, so the same seed gives the
    same windows. A trace shorter than one window is a :class:`SweepError`.
    """
    rng = np.random.default_rng(seed)
    span = steps * ratio
    out = []
    for t in sel:
        length = int(env_model.lengths[t])
        if length - 1 < span:
            raise SweepError(
                f"trace {t} ({env_model.trace_ids[t]}) is {(length - 1) / env_model.sample_rate:g} s long; a "
                f"{span / env_model.sample_rate:g} s window does not fit{_longest_window(env_model, sel)}")
        m = (length - 1) // span
        start = int(rng.integers(length - 1 - m * span + 1))
        out += [(t, start + j * span) for j in range(m)]
    return tuple(out)


def draw_library_windows(env_model, traces, windows, steps, ratio, seed) -> tuple:
    """(trace, offset) windows: explicit, tiling every selected trace, or drawn with ``Generator(seed)``.

    By default (``windows`` None) the windows tile each selected trace (:func:`tile_windows`): the whole
    library flown once, which is all the information it holds (two windows over one stretch of a trace fly
    the same gusts). ``windows`` windows go round robin over the traces instead; each trace's offsets are
    distinct, drawn in the order the traces are first used.
    """
    needed = steps * ratio + 1
    if _explicit(traces):
        return _explicit_windows(env_model, traces, needed)
    sel = _trace_list(env_model, traces)
    if windows is None:
        return tile_windows(env_model, sel, steps, ratio, seed)
    n_win = int(windows)
    if n_win < 1:
        raise SweepError(f"windows must be >= 1, got {windows!r}")
    assign = [sel[i % len(sel)] for i in range(n_win)]
    rng = np.random.default_rng(seed)
    offsets = {}
    for t in dict.fromkeys(assign):  # traces in order of first use
        m = assign.count(t)
        count = window_count(env_model.lengths[t], needed)
        if count < 1:
            raise SweepError(
                f"trace {t} ({env_model.trace_ids[t]}) is {(env_model.lengths[t] - 1) / env_model.sample_rate:g} s "
                f"long; a {steps * ratio / env_model.sample_rate:g} s window does not fit"
                f"{_longest_window(env_model, dict.fromkeys(assign))}")
        if m > count:
            raise SweepError(f"trace {t} has room for {count} distinct windows, {m} were asked")
        offsets[t] = draw_offsets(rng, count, m)
    used = {t: 0 for t in offsets}
    out = []
    for t in assign:
        out.append((t, offsets[t][used[t]]))
        used[t] += 1
    return tuple(out)


def _control_ratio(env_model, dt) -> int:
    """Library samples per control period; :class:`SweepError` unless ``dt`` is a whole number of them."""
    if not (isinstance(dt, (int, float)) and dt > 0 and math.isfinite(dt)):
        raise SweepError(f"dt must be a positive control period in seconds, got {dt!r}")
    ratio_f = dt * env_model.sample_rate
    ratio = int(round(ratio_f))
    if ratio < 1 or abs(ratio_f - ratio) > 1e-6:
        raise SweepError(f"dt={dt} s must be a whole number of the traces' sample periods "
                         f"({1.0 / env_model.sample_rate:g} s; left unset, dt is {default_dt(env_model.sample_rate):g} s)")
    return ratio


def _window_steps(env_model, duration, dt, ratio, traces, windows):
    """Control periods per window, and the windows when ``duration`` (None) fixes them."""
    if duration is None and _explicit(traces):  # each window from its offset, for the shortest remainder
        wins = _explicit_windows(env_model, traces, ratio + 1)
        steps = min((int(env_model.lengths[t]) - off - 1) // ratio for t, off in wins)
    elif duration is None:  # each trace from its start, for the length of the shortest
        sel = _trace_list(env_model, traces)
        steps = int((min(int(env_model.lengths[t]) for t in sel) - 1) // ratio)
        wins = tuple((t, 0) for t in sel) if windows is None else None
    else:
        if not (isinstance(duration, (int, float)) and duration > 0 and math.isfinite(duration)):
            raise SweepError(f"duration must be a positive number of seconds, got {duration!r}")
        steps = int(round(duration / dt))
        wins = None
    if steps < 1:
        raise SweepError(f"duration {duration!r} s is shorter than one control period")
    return steps, wins


def sensor_inputs(sensors, steps: int, W: int, dt: float, seed: int) -> tuple:
    """The attitude and rate errors (3, steps, W) the autopilot reads through the model's sensors, or (None, None).

    White noise per axis and each vibration line at a random phase per window, drawn from their own
    generator (``seed`` and a tag: the windows drawn with ``seed`` stay as they were); every gain pair
    flies the same noise (common random numbers: the pairs differ by their gains only).
    """
    if sensors is None or sensors.silent:
        return None, None
    rng = np.random.default_rng([int(seed), 0x5E45])
    att = np.asarray(sensors.attitude_noise)[:, None, None] * rng.standard_normal((3, steps, W))
    rate = np.asarray(sensors.gyro_noise)[:, None, None] * rng.standard_normal((3, steps, W))
    t = np.arange(steps) * dt
    for a, w, amp in zip(*sensors.line_arrays()):
        phase = rng.uniform(0.0, 2.0 * np.pi, W)
        rate[a] += amp * np.sin(w * t[:, None] + phase[None, :])
    return att, rate


def prepare(model, axis, duration, dt, seed, traces, windows, sensors: bool = True) -> LibraryReplay:
    """Check the settings, choose the windows and gather their inputs (see :func:`controllers.sweep.sweep_gains`);
    with ``sensors`` the autopilot reads the state through the model's identified sensors."""
    env_model = load_model(model)
    ax = axis_index(axis)
    if dt is None:
        dt = default_dt(env_model.sample_rate)
    ratio = _control_ratio(env_model, dt)
    steps, wins = _window_steps(env_model, duration, dt, ratio, traces, windows)
    if wins is None:
        wins = draw_library_windows(env_model, traces, windows, steps, ratio, seed)
    params = env_model.params
    base = np.array([int(env_model.starts[t]) + off for t, off in wins])
    idx = base[None, :] + ratio * np.arange(steps)[:, None]  # (steps, W)
    col = env_model.collective[idx]
    trim = np.array(trim_sticks(params, col))
    if not np.all(np.isfinite(trim)):
        raise SweepError("the model cannot be trimmed (zero control gain on some axis)")
    torque = env_model.torque[:, idx]  # each trace's u_d with the gains it was identified with
    att_noise, rate_noise = sensor_inputs(env_model.sensors if sensors else None, steps, len(wins), float(dt), seed)
    blocks = trace_blocks(wins, steps, ratio, env_model.sample_rate)
    return LibraryReplay(env_model, params, ax, float(dt), ratio, steps, wins,
                         LoopInputs(trim, col, torque, att_noise=att_noise, rate_noise=rate_noise), blocks)
