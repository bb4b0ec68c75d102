"""Gain sweeps → error distributions: the paper's Section 4 proposal.

    "use the disturbance profile identified from experiments to simulate the
    response of a proportional-derivative controller for a number of gains. The
    distribution of the error ... could then be predicted and compared with
    flight tests."

:func:`sweep_gains` flies every PD gain pair of a Kp × Kd grid against windows
of the model's disturbance library (the identified ``u_d`` of eqs. 41-47) and
reports the error distribution each pair gives, two ways:

* **time domain** — the gusts replayed through the physics core
  (:func:`identification.model.discrete_step`) in closed loop, all gain pairs ×
  windows stepped as one numpy batch; percentiles, RMS, control effort,
  saturation and a histogram per pair;
* **frequency domain** — the Welch spectrum of ``u_d`` through the linearised
  closed loop (:mod:`controllers.closed_loop`), Gaussian percentiles.

Where the two disagree (saturation, non-Gaussian gusts, model non-linearity)
the result flags it. :mod:`controllers.flight_test` checks the prediction
against flights of the truth model in fresh wind.

The replay
----------
The state starts level at rest, servos settled on the trim. At every control
period ``dt`` the PD law (:func:`controllers.closed_loop.pd_command`) computes
a stick offset per axis from the true attitude and rates (reference 0:
attitude hold), clipped to [-1, 1]; the applied stick is ``clip(trim + offset,
-1, 1)`` with the trim for the recorded collective, exactly as the
environments apply an action. The gust torque ``k·u_d`` of the window's sample
and the recorded collective are held over the period. All three axes fly:
the swept axis with the pair under test, the other two with nominal PD gains
(:func:`controllers.closed_loop.nominal_gains`, 4 rad/s, ζ = 0.7) so the
aircraft stays near hover in its own gusts. Errors are recorded on the swept
axis at the start of each period (the state the controller acts on), so the
first sample of every window is the level start.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field, replace

import numpy as np

from identification.model import _discrete_kernel, euler_from_quaternion, trim_sticks

from .closed_loop import (
    AXES,
    GAUSS_ABS_FACTOR,
    axis_index,
    closed_loop_poles,
    disturbance_spectrum,
    hover_plant,
    nominal_gains,
    pd_command,
    predict_std,
)
from .errors import SweepError
from .metrics import histogram_edges

_DEG = 180.0 / math.pi
MAX_ANGLE_DEG = 60.0
"""A replay whose roll or pitch leaves ±60° (the environments' termination) counts as diverged."""

TD_COLUMNS = ("att_rms_deg", "att_p50_deg", "att_p90_deg", "att_p99_deg", "rate_rms_dps", "rate_p50_dps",
              "rate_p90_dps", "rate_p99_dps", "stick_rms", "stick_p99", "saturation", "other_axes_max_deg")
FD_COLUMNS = ("pred_att_rms_deg", "pred_att_p50_deg", "pred_att_p90_deg", "pred_att_p99_deg", "pred_rate_rms_dps",
              "pred_rate_p50_dps", "pred_rate_p90_dps", "pred_rate_p99_dps", "pred_stick_rms")
COLUMNS = ("kp", "kd", "status", "max_pole", "settle_s") + TD_COLUMNS + FD_COLUMNS + (
    "att_p90_rel_diff", "rate_p90_rel_diff", "disagree")
"""Columns of the result table, one row per gain pair (Kp-major order).

``att_*`` |attitude error| [deg], ``rate_*`` |rate error| [deg/s], ``stick_*`` the
applied stick offset from trim [stick units], ``saturation`` the fraction of control
periods where the swept axis' stick was clipped, ``other_axes_max_deg`` the largest
|angle| of the two nominally held axes; ``pred_*`` the frequency-domain
prediction (Gaussian percentiles of |e|); ``*_rel_diff`` (time − frequency)/frequency
of the p90s; ``status`` "stable", "unstable" (closed-loop poles; not simulated) or
"diverged" (left ±60°); ``max_pole`` the spectral radius of the discrete closed loop and
``settle_s`` the 2 % settling time of its slowest mode, ``-4 dt / ln(max_pole)`` [s] (a loop
slower than the windows never reaches the stationary distribution the frequency domain
predicts)."""


# ------------------------------------------------------------------- inputs
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


def _load(model):
    from heli_env.model_dir import EnvModel, load_env_model

    return model if isinstance(model, EnvModel) else load_env_model(model)


@dataclass(frozen=True, eq=False)
class _Replay:
    """What the replay needs, checked and gathered once."""

    env_model: object  # None in the copy shipped to workers (the replay needs only params)
    params: object
    axis: int
    dt: float
    ratio: int
    steps: int
    windows: tuple  # ((trace, offset), ...)
    torque: np.ndarray  # (3, steps, W) k*u_d held over each period
    trim: np.ndarray  # (3, steps, W)
    col: np.ndarray  # (steps, W)


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


def _windows(env_model, traces, windows, steps, ratio, seed):
    """(trace, offset) windows: explicit, or drawn with ``Generator(seed)`` over the selected traces."""
    lengths = env_model.lengths
    needed = steps * ratio + 1
    if _explicit(traces):
        return _explicit_windows(env_model, traces, needed)
    sel = _trace_list(env_model, traces)
    n_win = len(sel) if windows is None else int(windows)
    if n_win < 1:
        raise SweepError(f"windows must be >= 1, got {windows!r}")
    assign = [sel[i % len(sel)] for i in range(n_win)]
    rng = np.random.default_rng(seed)
    offsets = {}
    for t in dict.fromkeys(assign):  # traces in order of first use
        m = assign.count(t)
        room = int(lengths[t]) - needed
        if room < 0:
            raise SweepError(
                f"trace {t} ({env_model.trace_ids[t]}) is {(lengths[t] - 1) / env_model.sample_rate:g} s long; "
                f"a {steps * ratio / env_model.sample_rate:g} s window does not fit (shorten duration)")
        if m > room + 1:
            raise SweepError(f"trace {t} has room for {room + 1} distinct windows, {m} were asked")
        offsets[t] = sorted(int(v) for v in rng.choice(room + 1, size=m, replace=False))
    used = {t: 0 for t in offsets}
    out = []
    for t in assign:
        out.append((t, offsets[t][used[t]]))
        used[t] += 1
    return tuple(out)


def _prepare(model, axis, duration, dt, seed, traces, windows) -> _Replay:
    try:
        env_model = _load(model)
    except ValueError as e:  # EnvModelError: missing or corrupt model directory
        raise SweepError(str(e)) from e
    ax = axis_index(axis)
    if not (isinstance(dt, (int, float)) and dt > 0 and math.isfinite(dt)):
        raise SweepError(f"dt must be a positive control period in seconds, got {dt!r}")
    ratio_f = dt * env_model.sample_rate
    ratio = int(round(ratio_f))
    if ratio < 1 or abs(ratio_f - ratio) > 1e-6:
        raise SweepError(f"dt={dt} s must be a whole number of the traces' sample periods "
                         f"({1.0 / env_model.sample_rate:g} s)")
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
    if wins is None:
        wins = _windows(env_model, traces, windows, steps, ratio, seed)
    params = env_model.params
    base = np.array([int(env_model.starts[t]) + off for t, off in wins])
    idx = base[None, :] + ratio * np.arange(steps)[:, None]  # (steps, W)
    col = env_model.collective[idx]
    trim = np.array(trim_sticks(params, col))
    if not np.all(np.isfinite(trim)):
        raise SweepError("the model cannot be trimmed (zero control gain on some axis)")
    torque = env_model.torque[:, idx]  # each trace's u_d with the gains it was identified with
    return _Replay(env_model, params, ax, float(dt), ratio, steps, wins, torque, trim, col)


# ------------------------------------------------------------------- replay
def _progress(total, show, desc):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="step", unit_scale=True, leave=False, file=sys.stderr,
                disable=not show or not sys.stderr.isatty())


def _replay(rp: _Replay, kp, kd, nominal, keep_samples=False, progress=True, max_batch=4096,
            hist_edges=None):
    """Fly gain pairs ``(kp[g], kd[g])`` against every window; statistics per pair.

    The state is a tuple of arrays of shape (pairs in chunk, windows); per-period
    inputs of shape (windows,) broadcast over the pairs.
    """
    params = rp.params
    dstep = _discrete_kernel(params, rp.dt)[0]
    ax = rp.axis
    signs = np.sign(params.control_gains)
    G, W, n = kp.size, len(rp.windows), rp.steps
    cp = max(1, max_batch // W)
    nb = len(hist_edges) - 1
    stats = {c: np.full(G, np.nan) for c in TD_COLUMNS}
    hist = np.zeros((G, nb), dtype=np.int64)
    overflow = np.zeros(G, dtype=np.int64)
    diverged = np.zeros(G, dtype=bool)
    samples = {}
    torque = [np.ascontiguousarray(rp.torque[i]) for i in range(3)]
    trim = [np.ascontiguousarray(rp.trim[i]) for i in range(3)]
    col = rp.col
    clip = np.clip
    with _progress(G * W * n, progress, f"sweep {AXES[ax]}") as bar, \
            np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        for c0 in range(0, G, cp):
            sl = slice(c0, min(G, c0 + cp))
            g = sl.stop - sl.start
            gains = [(nominal[i][0], nominal[i][1]) for i in range(3)]
            gains[ax] = (kp[sl][:, None], kd[sl][:, None])
            z = np.zeros((g, W))
            x = (z, z, z, z + trim[0][0], z + trim[1][0], z + trim[2][0], z + 1.0, z, z, z)
            # records laid out (pair, period, window): each pair's samples are contiguous
            att = np.empty((g, n, W), dtype=np.float32)
            rate = np.empty((g, n, W), dtype=np.float32)
            act = np.empty((g, n, W), dtype=np.float32)
            sat = np.zeros((g, W))
            omax = np.zeros((g, W))
            others = [i for i in range(3) if i != ax]
            for k in range(n):
                ang = euler_from_quaternion(x[6:10])
                sticks = []
                for i in range(3):
                    u = pd_command(gains[i][0], gains[i][1], signs[i], -ang[i], -x[i])
                    a = clip(u, -1.0, 1.0)
                    t_i = trim[i][k]
                    s = clip(t_i + a, -1.0, 1.0)
                    sticks.append(s)
                    if i == ax:
                        att[:, k] = -ang[i]
                        rate[:, k] = -x[i]
                        act[:, k] = s - t_i
                        sat += (a != u) | (s != t_i + a)
                omax = np.maximum(omax, np.maximum(np.abs(ang[others[0]]), np.abs(ang[others[1]])))
                x = dstep(x, (sticks[0], sticks[1], col[k], sticks[2]), (torque[0][k], torque[1][k], torque[2][k]))
                if k % 200 == 199:
                    bar.update(200 * g * W)
            bar.update((n % 200) * g * W)
            if keep_samples:  # before the statistics, which work in place
                for j in range(g):
                    samples[sl.start + j] = (att[j].T.ravel() * _DEG, rate[j].T.ravel() * _DEG, act[j].T.ravel())
            _chunk_stats(att, rate, act, sat, omax, n, sl, stats, hist, overflow, diverged, hist_edges)
    for c in TD_COLUMNS:
        stats[c][diverged] = np.nan
    return stats, hist, overflow, diverged, samples


TASK_STATES = 1024
"""Pair × window states per task when a sweep runs on a backend: a task gets
``max(1, TASK_STATES // n_windows)`` consecutive stable pairs. The split depends on
the grid and the windows only, never on the number of workers; chunks of 512 to
4096 states replay at the same cost per state on one core, so 1024 leaves room
for 4 tasks in a 20 × 20 grid × 10 windows and thousands in a cluster-sized one."""


def _check_chunk_pairs(chunk_pairs) -> None:
    """:class:`SweepError` unless ``chunk_pairs`` is None or a whole number >= 1."""
    if chunk_pairs is not None and not (isinstance(chunk_pairs, (int, np.integer))
                                        and not isinstance(chunk_pairs, bool) and chunk_pairs >= 1):
        raise SweepError(f"chunk_pairs must be a whole number >= 1, got {chunk_pairs!r}")


def _chunks(n_pairs: int, n_windows: int, chunk_pairs) -> list:
    """``[(start, stop), ...]`` of the task split of ``n_pairs`` pairs (see :data:`TASK_STATES`)."""
    _check_chunk_pairs(chunk_pairs)
    size = max(1, TASK_STATES // n_windows) if chunk_pairs is None else int(chunk_pairs)
    return [(a, min(n_pairs, a + size)) for a in range(0, n_pairs, size)]


def _replay_task(item, shared):
    """One backend task: :func:`_replay` of a chunk of pairs (module level, so workers import it)."""
    kp, kd = item
    rp, nominal, keep_samples, max_batch, edges = shared
    return _replay(rp, kp, kd, nominal, keep_samples, False, max_batch, edges)


def _replay_on(backend, rp: _Replay, kp, kd, nominal, keep_samples, progress, max_batch, edges, chunk_pairs):
    """:func:`_replay` split into chunks of pairs run as tasks of ``backend``, joined in pair order.

    Every pair's replay is independent of the others in its batch (element-wise
    numpy over the (pairs, windows) states, per-row statistics), so the joined
    result equals the single-process one bit for bit (tests check it). The
    windows' inputs go to the workers once as the backend's shared data, without
    the library (``env_model``); a task carries only its gains.
    """
    bounds = _chunks(kp.size, len(rp.windows), chunk_pairs)
    shared = (replace(rp, env_model=None), np.asarray(nominal, dtype=float), keep_samples, max_batch, edges)
    parts = backend.map(_replay_task, [(kp[a:b], kd[a:b]) for a, b in bounds], shared, progress=progress,
                        desc=f"sweep {AXES[rp.axis]}")
    stats = {c: np.concatenate([p[0][c] for p in parts]) for c in TD_COLUMNS}
    hist = np.concatenate([p[1] for p in parts])
    overflow = np.concatenate([p[2] for p in parts])
    diverged = np.concatenate([p[3] for p in parts])
    samples = {a + j: v for (a, _), p in zip(bounds, parts) for j, v in p[4].items()}
    return stats, hist, overflow, diverged, samples, len(bounds)


def _percentiles(data: np.ndarray, qs) -> list:
    """Percentiles along axis 1 (numpy's default "linear" method), partitioning ``data`` in place."""
    m = data.shape[1]
    pos = [q / 100.0 * (m - 1) for q in qs]
    kth = sorted({int(math.floor(v)) for v in pos} | {min(int(math.floor(v)) + 1, m - 1) for v in pos})
    data.partition(kth, axis=1)
    out = []
    for v in pos:
        lo = int(math.floor(v))
        hi = min(lo + 1, m - 1)
        out.append(data[:, lo].astype(np.float64) + (v - lo) * (data[:, hi].astype(np.float64) - data[:, lo]))
    return out


def _chunk_stats(att, rate, act, sat, omax, n, sl, stats, hist, overflow, diverged, edges):
    """Per-pair statistics of one chunk's records (g, n, W), written into the result arrays at ``sl``.

    The definitions of :func:`controllers.metrics.error_metrics` (the agents' evaluator; a test
    checks the two agree), computed in float32 and in place on the records (absolute values,
    degrees, partitioning) to spare copies of a few hundred MB per chunk. Saturation counts the
    periods where the PD command or the stick (trim + offset) was clipped.
    """
    g = att.shape[0]

    def per_pair(a, scale=1.0):  # (g, n, W) -> (g, n*W) view of |a|*scale, float32
        out = np.abs(a, out=a).reshape(g, -1)
        if scale != 1.0:
            out *= np.float32(scale)
        return out

    A = per_pair(att, _DEG)
    R = per_pair(rate, _DEG)
    U = per_pair(act)
    peak = np.max(A, axis=1)  # NaN propagates
    bad = ~np.isfinite(peak) | (peak > MAX_ANGLE_DEG) | ~np.isfinite(omax.max(axis=1))
    bad |= omax.max(axis=1) * _DEG > MAX_ANGLE_DEG
    diverged[sl] = bad
    if np.any(bad):  # keep the statistics finite; they are discarded for diverged pairs
        for arr in (A, R, U):
            arr[bad] = 0.0
    nb = edges.size - 1
    lo = np.float32(edges[1])
    inv_step = np.float32(1.0 / math.log(edges[2] / edges[1]))
    for j in range(g):  # bin 0 is [0, edges[1]); then geometric bins by index; slot nb counts the overflow
        with np.errstate(divide="ignore"):
            b = np.floor(np.log(A[j] / lo) * inv_step) + np.float32(1.0)
        counts = np.bincount(np.clip(b, 0, nb).astype(np.intp), minlength=nb + 1)
        hist[sl.start + j] = counts[:nb]
        overflow[sl.start + j] = counts[nb]
    for name, unit, data in (("att", "deg", A), ("rate", "dps", R)):
        stats[f"{name}_rms_{unit}"][sl] = np.sqrt(np.mean(data * data, axis=1, dtype=np.float64))
        for q, row in zip((50, 90, 99), _percentiles(data, (50, 90, 99))):
            stats[f"{name}_p{q}_{unit}"][sl] = row
    stats["stick_rms"][sl] = np.sqrt(np.mean(U * U, axis=1, dtype=np.float64))
    stats["stick_p99"][sl] = _percentiles(U, (99,))[0]
    stats["saturation"][sl] = sat.mean(axis=1) / n
    stats["other_axes_max_deg"][sl] = omax.max(axis=1) * _DEG


# ------------------------------------------------------------------- result
@dataclass(eq=False)
class SweepResult:
    """Error distributions of a PD gain sweep, per gain pair (Kp-major order).

    Attributes
    ----------
    axis : str
    kp_values, kd_values : ndarray
        The grid [stick/rad], [stick/(rad/s)].
    table : dict of str -> ndarray (n_pairs,)
        :data:`COLUMNS`.
    hist_edges : ndarray (n_bins + 1,)
        Bin edges of |attitude error| [deg], shared by all pairs and by agent evaluation
        (:func:`controllers.metrics.histogram_edges`): 0, then geometric from
        :data:`~controllers.metrics.HIST_MIN_DEG` to ``hist_max_deg`` (about 7 % wide by default).
    hist_counts : ndarray (n_pairs, n_bins)
        Samples per bin; ``hist_overflow`` (n_pairs,) counts those above the last edge.
    windows : tuple of (trace, offset)
        Library windows replayed (trace index, start sample).
    psd_freq, psd : ndarray
        The Welch spectrum of u_d used by the prediction [Hz], (3, nf) [stick²/Hz].
    settings : dict
        Model, dt, duration, seed, nominal gains, tolerance, timing.
    samples : dict of int -> (att_err_deg, rate_err_deg_s, stick)
        Signed per-sample errors of each pair, only with ``keep_samples=True``.
    """

    axis: str
    kp_values: np.ndarray
    kd_values: np.ndarray
    table: dict
    hist_edges: np.ndarray
    hist_counts: np.ndarray
    hist_overflow: np.ndarray
    windows: tuple
    psd_freq: np.ndarray
    psd: np.ndarray
    settings: dict
    samples: dict = field(default_factory=dict)

    @property
    def n_pairs(self) -> int:
        return int(self.table["kp"].size)

    @property
    def stable(self) -> np.ndarray:
        return self.table["status"] == "stable"

    @property
    def is_grid(self) -> bool:
        return self.settings.get("layout", "grid") == "grid"

    def grid(self, column: str) -> np.ndarray:
        """A column as a (n_kp, n_kd) array (rows Kp, columns Kd); grids only."""
        if not self.is_grid:
            raise SweepError("this sweep ran a list of pairs, not a grid")
        return np.asarray(self.table[column]).reshape(self.kp_values.size, self.kd_values.size)

    def index(self, kp: float, kd: float) -> int:
        """Row of the pair nearest to ``(kp, kd)`` (relative distance in each gain)."""
        k_p, k_d = np.asarray(self.table["kp"], float), np.asarray(self.table["kd"], float)
        sp, sd = max(np.ptp(k_p), 1e-12), max(np.ptp(k_d), 1e-12)
        return int(np.argmin(((k_p - kp) / sp) ** 2 + ((k_d - kd) / sd) ** 2))

    def row(self, i: int) -> dict:
        """One pair's row as a dict of Python scalars."""
        return {c: _scalar(self.table[c][i]) for c in COLUMNS}

    def rows(self) -> list:
        return [self.row(i) for i in range(self.n_pairs)]

    def best(self, by: str = "att_p90_deg") -> dict | None:
        """The stable, simulated pair with the smallest ``by`` (default p90 |attitude error|), or None."""
        v = np.where(self.stable, np.asarray(self.table[by], dtype=float), np.nan)
        if not np.any(np.isfinite(v)):
            return None
        return self.row(int(np.nanargmin(v)))

    def to_csv(self, path):
        """Write the table as CSV (one row per pair; NaN for what was not simulated), atomically."""
        from .sweep_report import write_csv

        return write_csv(self, path)

    def to_json(self, path):
        """Write settings, table, histograms, windows and spectrum as JSON (NaN as null), atomically."""
        from .sweep_report import write_json

        return write_json(self, path)

    def to_markdown(self) -> str:
        """The report: settings, summary and the side-by-side time/frequency table."""
        from .sweep_report import markdown

        return markdown(self)

    def plot_heatmap(self, path):
        """PNG heat maps of p90 |attitude error| over Kp × Kd (time and frequency domain), unstable region
        hatched, stability boundary drawn, best pair starred."""
        from .sweep_report import plot_heatmap

        return plot_heatmap(self, path)

    def plot_histograms(self, path, pairs=None):
        """Overlaid |attitude error| histograms of ``pairs`` ((kp, kd) list; default best and three others),
        each with its frequency-domain half-normal prediction dashed."""
        from .sweep_report import plot_histograms

        return plot_histograms(self, path, pairs)


def _scalar(v):
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.floating, float)):
        return float(v)
    if isinstance(v, (np.integer, int)):
        return int(v)
    return str(v)


# -------------------------------------------------------------------- sweep
def sweep_gains(model, kp_values, kd_values, axis="roll", duration: float | None = 60.0, dt: float = 0.01,
                seed: int = 0, traces=None, windows: int | None = None, progress: bool = True, nominal=None,
                agree_tol: float = 0.2, keep_samples: bool = False, hist_max_deg: float = 30.0,
                hist_bins: int = 120, max_batch: int = 4096, backend=None, chunk_pairs: int | None = None
                ) -> SweepResult:
    """Predict the error distribution of every PD gain pair of a Kp × Kd grid (paper Section 4).

    Parameters
    ----------
    model : str, Path, EnvModel or None
        Model directory written by ``heli identify`` (``model.json`` + ``disturbances/``),
        a loaded :class:`heli_env.model_dir.EnvModel`, or None for the shipped model.
    kp_values : sequence of float, shape (n_kp,)
        Proportional gains [stick/rad], >= 0.
    kd_values : sequence of float, shape (n_kd,)
        Derivative gains [stick/(rad/s)], >= 0.
    axis : {"roll", "pitch", "yaw"}
        Axis swept; the other two are held by ``nominal`` gains.
    duration : float or None
        Length of each replayed window [s]; None replays each selected trace whole
        (from its start, for the length of the shortest), or each explicit window
        from its offset to the end of its trace (for the length of the shortest).
    dt : float
        Control period [s], a whole number of the traces' sample periods.
    seed : int
        Seeds the window offsets (``numpy.random.Generator``); same seed, same result.
    traces : sequence of int, or of (trace, offset), optional
        Library traces to draw windows from (default all), or explicit windows.
    windows : int, optional
        Number of (trace, offset) windows, spread round robin over ``traces`` with
        distinct offsets per trace (default one per trace). Windows of one trace may
        overlap when the trace is shorter than their total length.
    progress : bool
        tqdm bar on stderr (when it is a terminal).
    nominal : array (3, 2), optional
        (kp, kd) per axis for the held axes; default :func:`~controllers.closed_loop.nominal_gains`.
    agree_tol : float
        Relative difference of the p90s above which time and frequency domain are flagged.
    keep_samples : bool
        Keep every pair's signed error samples in ``result.samples``.
    hist_max_deg, hist_bins : float, int
        Histogram: top edge [deg] and number of bins (the first bin is [0, 0.01°), the
        others geometric up to ``hist_max_deg``).
    max_batch : int
        Pair × window states stepped at once (memory: ~12 bytes × steps each).
    backend : None, {"local", "ray"} or identification.backends.Backend
        Where the time-domain replay runs. None (default): in this process, as one
        batch. Otherwise the stable pairs are split into chunks (``chunk_pairs``) run as
        tasks of the backend (``"local"``: every core of this machine; ``"ray"``:
        ``RAY_ADDRESS`` or a Ray instance started here, closed after the sweep). The
        result is the same, bit for bit, on every backend and worker count.
    chunk_pairs : int, optional
        Pairs per task with a backend (default :data:`TASK_STATES` // windows).

    Returns
    -------
    SweepResult

    Raises
    ------
    SweepError
        Bad gains, axis, dt or duration, windows that do not fit, a missing or corrupt model directory,
        or nominal gains that do not stabilise the held axes.
    identification.errors.MissingDependency
        ``backend="ray"`` without the ``cluster`` extra.
    identification.errors.TaskFailed
        A backend's worker died more often than its retries allow.
    """
    kp_values = check_gains(kp_values, "kp_values")
    kd_values = check_gains(kd_values, "kd_values")
    KP, KD = np.meshgrid(kp_values, kd_values, indexing="ij")
    return _sweep(model, KP.ravel(), KD.ravel(), kp_values, kd_values, "grid", axis, duration, dt, seed, traces,
                  windows, progress, nominal, agree_tol, keep_samples, hist_max_deg, hist_bins, max_batch, backend,
                  chunk_pairs)


def sweep_pairs(model, pairs, axis="roll", duration: float | None = 60.0, dt: float = 0.01, seed: int = 0,
                traces=None, windows: int | None = None, progress: bool = True, nominal=None,
                agree_tol: float = 0.2, keep_samples: bool = False, hist_max_deg: float = 30.0,
                hist_bins: int = 120, max_batch: int = 4096, backend=None, chunk_pairs: int | None = None
                ) -> SweepResult:
    """:func:`sweep_gains` on a list of ``(kp, kd)`` pairs instead of a grid (same arguments).

    The table rows follow ``pairs``; ``kp_values``/``kd_values`` hold each pair's
    gains and :meth:`SweepResult.grid` is not available.
    """
    arr = np.asarray(pairs, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
        raise SweepError(f"pairs must be a non-empty list of (kp, kd), got shape {arr.shape}")
    kp = check_gains(arr[:, 0], "kp of pairs")
    kd = check_gains(arr[:, 1], "kd of pairs")
    return _sweep(model, kp, kd, kp, kd, "pairs", axis, duration, dt, seed, traces, windows, progress, nominal,
                  agree_tol, keep_samples, hist_max_deg, hist_bins, max_batch, backend, chunk_pairs)


def _make_backend(backend):
    """:func:`identification.backends.make_backend`, an unknown name reported as a :class:`SweepError`.

    Making a backend starts nothing (no processes, no Ray instance) until its first ``map``;
    ``"ray"`` without the ``cluster`` extra raises :class:`~identification.errors.MissingDependency`.
    """
    from identification.backends import make_backend
    from identification.errors import BackendError

    try:
        return make_backend(backend)
    except BackendError as e:
        raise SweepError(str(e)) from e


def _sweep(model, kp, kd, kp_values, kd_values, layout, axis, duration, dt, seed, traces, windows, progress,
           nominal, agree_tol, keep_samples, hist_max_deg, hist_bins, max_batch, backend=None,
           chunk_pairs=None) -> SweepResult:
    import time

    t_start = time.perf_counter()
    be = None if backend is None else _make_backend(backend)  # check before any work
    try:
        if be is not None:
            _check_chunk_pairs(chunk_pairs)
        if not (isinstance(agree_tol, (int, float)) and agree_tol > 0 and math.isfinite(agree_tol)):
            raise SweepError(f"agree_tol must be a positive fraction, got {agree_tol!r}")
        try:
            edges = histogram_edges(float(hist_max_deg), int(hist_bins))
        except ValueError as e:
            raise SweepError(str(e)) from e
        rp = _prepare(model, axis, duration, dt, seed, traces, windows)
        env_model = rp.env_model
        plant = hover_plant(env_model.params, rp.dt, float(np.mean(env_model.collective)))
        nominal = nominal_gains(plant) if nominal is None else np.asarray(nominal, dtype=float).reshape(3, 2)
        ax = rp.axis
        _, nominal_ok = closed_loop_poles(plant, ax, [nominal[ax][0]], [nominal[ax][1]], nominal)
        if not nominal_ok[0]:
            raise SweepError(f"the nominal gains {nominal.tolist()} do not stabilise the model; pass nominal=")
        G = kp.size
        t0 = time.perf_counter()
        max_pole, stable = closed_loop_poles(plant, ax, kp, kd, nominal)
        freq, psd = disturbance_spectrum(env_model, rp.dt)
        sigma = predict_std(plant, ax, kp, kd, nominal, freq, psd)
        t_fd = time.perf_counter() - t0

        with np.errstate(divide="ignore", invalid="ignore"):
            settle = np.where(stable, -4.0 * rp.dt / np.log(np.minimum(max_pole, 1.0)), np.inf)
        table = {"kp": kp, "kd": kd, "max_pole": max_pole, "settle_s": settle}
        table.update({c: np.full(G, np.nan) for c in TD_COLUMNS})
        hist = np.zeros((G, edges.size - 1), dtype=np.int64)
        overflow = np.zeros(G, dtype=np.int64)
        status = np.where(stable, "stable", "unstable").astype(object)
        idx = np.flatnonzero(stable)
        t0 = time.perf_counter()
        samples = {}
        where, n_tasks = "in-process", 1
        if idx.size and backend is None:
            st, h, o, div, smp = _replay(rp, kp[idx], kd[idx], nominal, keep_samples, progress, max_batch, edges)
        elif idx.size:
            st, h, o, div, smp, n_tasks = _replay_on(be, rp, kp[idx], kd[idx], nominal, keep_samples, progress,
                                                     max_batch, edges, chunk_pairs)
            where = be.describe()
        if idx.size:
            for c in TD_COLUMNS:
                table[c][idx] = st[c]
            hist[idx], overflow[idx] = h, o
            status[idx[div]] = "diverged"
            samples = {int(idx[j]): v for j, v in smp.items()}
        t_td = time.perf_counter() - t0

        s_att, s_rate, s_stick = (sigma[:, 0] * _DEG, sigma[:, 1] * _DEG, sigma[:, 2])
        table["pred_att_rms_deg"], table["pred_rate_rms_dps"], table["pred_stick_rms"] = s_att, s_rate, s_stick
        for q, f in GAUSS_ABS_FACTOR.items():
            table[f"pred_att_p{q}_deg"] = f * s_att
            table[f"pred_rate_p{q}_dps"] = f * s_rate
        with np.errstate(invalid="ignore", divide="ignore"):
            table["att_p90_rel_diff"] = table["att_p90_deg"] / table["pred_att_p90_deg"] - 1.0
            table["rate_p90_rel_diff"] = table["rate_p90_dps"] / table["pred_rate_p90_dps"] - 1.0
        table["disagree"] = (np.abs(np.nan_to_num(table["att_p90_rel_diff"])) > agree_tol) | (
            np.abs(np.nan_to_num(table["rate_p90_rel_diff"])) > agree_tol)
        table["status"] = status
        df = freq[1] - freq[0]
        settings = {
            "model": str(env_model.path), "library_version": env_model.library_version,
            "trace_ids": list(env_model.trace_ids), "axis": AXES[ax], "layout": layout, "dt": rp.dt,
            "duration": rp.steps * rp.dt, "steps": rp.steps, "seed": int(seed), "n_windows": len(rp.windows),
            "nominal_gains": nominal.tolist(), "agree_tol": float(agree_tol),
            "linearised_at_collective": plant.collective,
            "ud_std": np.sqrt(np.sum(psd, axis=1) * df).tolist(),
            "seconds": {"total": time.perf_counter() - t_start, "time_domain": t_td, "frequency_domain": t_fd},
            "backend": where, "tasks": n_tasks,
        }
        return SweepResult(AXES[ax], np.asarray(kp_values), np.asarray(kd_values), table, edges, hist, overflow,
                           rp.windows, freq, psd, settings, samples)
    finally:
        if be is not backend:  # made here from a name: release it
            be.close()
