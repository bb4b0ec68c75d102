"""The time domain of a gain sweep: the library's gusts replayed in closed loop, statistics per gain pair.

Every stable pair flies every library window through the one batched closed
loop (:func:`controllers.replay.fly`, the physics core's exact discrete step, as
the environments integrate); the swept axis' records of each pair become its
error distribution (:func:`controllers.metrics.error_metrics_inplace`). A pair
whose roll or pitch leaves ±:data:`MAX_ANGLE_DEG` counts as diverged. The replay
runs in this process, or split into chunks of pairs run as tasks of a backend
(:func:`replay_on`), with the same result bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from heli_core.terms import AXES

from .errors import SweepError
from .metrics import abs_in_place, error_metrics_inplace
from .replay import Autopilot, fly, zoh_step
from .sweep_interval import INTERVAL_COLUMNS, quantiles_at, woodruff_levels

_DEG = 180.0 / math.pi
MAX_ANGLE_DEG = 60.0
"""A replay whose roll or pitch leaves ±60° (the environments' termination) counts as diverged."""

TD_COLUMNS = ("att_rms_deg", "att_p50_deg", "att_p90_deg", "att_p99_deg", "rate_rms_dps", "rate_p50_dps",
              "rate_p90_dps", "rate_p99_dps", "stick_rms", "stick_p99", "saturation",
              "other_axes_max_deg") + INTERVAL_COLUMNS
"""Time-domain columns of a sweep's table (see :data:`controllers.sweep_result.COLUMNS`); the last four are the
90 % intervals of the two p90s (:mod:`controllers.sweep_interval`)."""

TASK_STATES = 1024
"""Pair × window states per task when a sweep runs on a backend: a task gets
``max(1, TASK_STATES // n_windows)`` consecutive stable pairs. The split depends on
the grid and the windows only, never on the number of workers; chunks of 512 to
4096 states replay at the same cost per state on one core, so 1024 leaves room
for 4 tasks in a 20 × 20 grid × 10 windows and thousands in a cluster-sized one."""


def replay(rp, kp, kd, nominal, keep_samples=False, progress=True, max_batch=4096, hist_edges=None, d_poles=None):
    """Fly gain pairs ``(kp[g], kd[g])`` against every window of ``rp``; statistics per pair.

    Parameters
    ----------
    rp : controllers.sweep_inputs.LibraryReplay
    kp, kd : ndarray (G,)
    nominal : array (3, 2)
        Gains of the held axes.
    keep_samples : bool
        Also return each pair's signed samples (att [deg], rate [deg/s], stick).
    progress : bool
    max_batch : int
        Pair × window states stepped at once.
    hist_edges : ndarray
        Histogram edges of |attitude error| [deg].
    d_poles : array (3,), optional
        Each axis' derivative-filter pole (:attr:`controllers.closed_loop.HoverPlant.d_poles`); None: no filter.

    Returns
    -------
    stats : dict of :data:`TD_COLUMNS` -> ndarray (G,)
        NaN for diverged pairs.
    hist, overflow : ndarray (G, nb), (G,)
    diverged : ndarray of bool (G,)
    samples : dict of int -> (att, rate, stick)
    """
    G, n = kp.size, rp.steps
    stats = {c: np.full(G, np.nan) for c in TD_COLUMNS}
    hist = np.zeros((G, len(hist_edges) - 1), dtype=np.int64)
    overflow = np.zeros(G, dtype=np.int64)
    diverged = np.zeros(G, dtype=bool)
    samples = {}
    autopilot = Autopilot(rp.axis, kp, kd, nominal, np.sign(rp.params.control_gains), d_poles)
    chunks = fly(zoh_step(rp.params, rp.dt), rp.inputs, autopilot, max_batch, progress, f"sweep {AXES[rp.axis]}")
    for sl, rec in chunks:
        if keep_samples:  # before the statistics, which work in place
            for j in range(sl.stop - sl.start):
                samples[sl.start + j] = (rec.att[j].T.ravel() * _DEG, rec.rate[j].T.ravel() * _DEG,
                                         rec.act[j].T.ravel())
        _chunk_stats(rec, n, sl, stats, hist, overflow, diverged, hist_edges, getattr(rp, "blocks", None))
    for c in TD_COLUMNS:
        stats[c][diverged] = np.nan
    return stats, hist, overflow, diverged, samples


def _chunk_stats(rec, n, sl, stats, hist, overflow, diverged, edges, blocks=None):
    """Per-pair statistics of one chunk's records (g, n, W), written into the result arrays at ``sl``.

    Saturation counts the periods where the PD command or the stick (trim + offset) was clipped. ``blocks``
    is ``(block of each (period, window), adjacent block pairs)`` (:func:`controllers.sweep_interval.trace_blocks`)
    for the p90s' intervals; without it they are NaN.
    """
    A = abs_in_place(rec.att, _DEG)
    R = abs_in_place(rec.rate, _DEG)
    U = abs_in_place(rec.act)
    omax = rec.omax.max(axis=1)
    peak = np.max(A, axis=1)  # NaN propagates
    bad = ~np.isfinite(peak) | (peak > MAX_ANGLE_DEG) | ~np.isfinite(omax)
    bad |= omax * _DEG > MAX_ANGLE_DEG
    diverged[sl] = bad
    if np.any(bad):  # keep the statistics finite; they are discarded for diverged pairs
        for arr in (A, R, U):
            arr[bad] = 0.0
    levels = None
    if blocks is not None:  # before the statistics partition the samples in place
        ids, adjacent = np.asarray(blocks[0]).ravel(), blocks[1]
        levels = [woodruff_levels(A, ids, adjacent), woodruff_levels(R, ids, adjacent)]
    m = error_metrics_inplace(A, R, U, rec.sat.mean(axis=1) / n, edges)
    hist[sl], overflow[sl] = m.pop("hist_counts"), m.pop("hist_overflow")
    for c, v in m.items():
        stats[c][sl] = v
    stats["other_axes_max_deg"][sl] = omax * _DEG
    if levels is not None:
        for (lo, hi), data, lv in zip((INTERVAL_COLUMNS[:2], INTERVAL_COLUMNS[2:]), (A, R), levels):
            ends = quantiles_at(data, lv)
            stats[lo][sl], stats[hi][sl] = ends[:, 0], ends[:, 1]


def check_chunk_pairs(chunk_pairs) -> None:
    """:class:`SweepError` unless ``chunk_pairs`` is None or a whole number >= 1."""
    if chunk_pairs is not None and not (isinstance(chunk_pairs, (int, np.integer))
                                        and not isinstance(chunk_pairs, bool) and chunk_pairs >= 1):
        raise SweepError(f"chunk_pairs must be a whole number >= 1, got {chunk_pairs!r}")


def chunks(n_pairs: int, n_windows: int, chunk_pairs) -> list:
    """``[(start, stop), ...]`` of the task split of ``n_pairs`` pairs (see :data:`TASK_STATES`)."""
    check_chunk_pairs(chunk_pairs)
    size = max(1, TASK_STATES // n_windows) if chunk_pairs is None else int(chunk_pairs)
    return [(a, min(n_pairs, a + size)) for a in range(0, n_pairs, size)]


def _replay_task(item, shared):
    """One backend task: :func:`replay` of a chunk of pairs (module level, so workers import it)."""
    kp, kd = item
    rp, nominal, keep_samples, max_batch, edges, d_poles = shared
    return replay(rp, kp, kd, nominal, keep_samples, False, max_batch, edges, d_poles)


def replay_on(backend, rp, kp, kd, nominal, edges, cfg, progress=None, d_poles=None):
    """:func:`replay` split into chunks of pairs run as tasks of ``backend``, joined in pair order.

    ``cfg`` is the sweep's :class:`~controllers.sweep.SweepConfig`: its ``chunk_pairs`` split the pairs into
    tasks (:func:`chunks`), its ``keep_samples`` and ``max_batch`` go to each task's :func:`replay`, and its
    ``progress`` shows a bar of finished tasks (``progress``, when given, replaces it: a bar the caller owns,
    see :meth:`heli_core.backends.Backend.map`); ``edges`` are the histogram's, ``d_poles`` :func:`replay`'s.

    Every pair's replay is independent of the others in its batch (element-wise
    numpy over the (pairs, windows) states, per-row statistics), so the joined
    result equals the single-process one bit for bit (tests check it). The
    windows' inputs go to the workers once as the backend's shared data, without
    the library (``env_model``); a task carries only its gains.

    Returns
    -------
    What :func:`replay` returns, and the number of tasks.
    """
    bounds = chunks(kp.size, len(rp.windows), cfg.chunk_pairs)
    shared = (replace(rp, env_model=None), np.asarray(nominal, dtype=float), cfg.keep_samples, cfg.max_batch, edges,
              d_poles)
    parts = backend.map(_replay_task, [(kp[a:b], kd[a:b]) for a, b in bounds], shared,
                        progress=cfg.progress if progress is None else progress,
                        desc=f"sweep {AXES[rp.axis]}")
    stats = {c: np.concatenate([p[0][c] for p in parts]) for c in TD_COLUMNS}
    hist = np.concatenate([p[1] for p in parts])
    overflow = np.concatenate([p[2] for p in parts])
    diverged = np.concatenate([p[3] for p in parts])
    samples = {a + j: v for (a, _), p in zip(bounds, parts) for j, v in p[4].items()}
    return stats, hist, overflow, diverged, samples, len(bounds)
