"""Axes fitted side by side, one process each, on the cores this process may use.

Each axis' likelihood is its own: the wind-state model of an axis (eqs. 18 and 21 with its gust state) takes
the other axes' measured rates as inputs, so the search on one axis never waits for another's, and on two
cores a fit of three axes takes about two axes' time. The workers are forked children of the caller: they
inherit its state (the flight, the fitted pieces, BLAS held to one thread), only the results travel back
(pickled), and each result is the serial one bit for bit (the same code on the same data).

By default the processes are as many as the cores other work leaves idle (:func:`workers_available`, from the
one-minute load average): forked beside a busy neighbour, two processes share one core and the fork costs
(a 300 s flight's three axes took 1.93 s in two processes at load 2 against 1.51 s in one).
The axes are fitted one after another when only one core is idle, when ``HELI_WORKERS=1``, inside a
process that is itself a worker (a study's process pool: no pools within pools), or where the platform
cannot fork. A task that fails in a worker is run again in the caller, so that its exception reaches the
user exactly as a serial fit raises it.

An interrupt is the caller's alone: the workers ignore SIGINT (a terminal's Ctrl-C reaches the whole process
group, and a worker interrupted inside the pool's queues left the pool waiting on it for ever), and the caller,
interrupted or failing while it waits, kills them (:func:`heli_core.backends.kill_workers`, as the local
backend's pools) and re-raises at once instead of waiting for the running fits.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np

from heli_core.backends import kill_workers

WORKERS_ENV = "HELI_WORKERS"
"""Environment variable capping the number of processes the axes are fitted in (1: one after another)."""

_TASK = None
_IN_WORKER = False


def workers_available() -> int:
    """``HELI_WORKERS`` when it is set (at most the cores this process may run on), else the cores other work
    leaves idle: the cores less the one-minute load average beyond this process' own one, rounded, at least 1.

    Raises
    ------
    ValueError
        ``HELI_WORKERS`` set to anything but a whole number >= 1.
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    text = os.environ.get(WORKERS_ENV, "").strip()
    if not text:
        try:
            others = max(0.0, os.getloadavg()[0] - 1.0)
        except (AttributeError, OSError):  # no load average on this platform
            others = 0.0
        return max(1, min(cores, int(cores - others + 0.5)))
    if not text.isdigit() or int(text) < 1:
        raise ValueError(f"{WORKERS_ENV} must be a whole number >= 1 (1 fits the axes one after another); "
                         f"got {text!r}")
    return min(int(text), cores)


def check_workers(workers) -> None:
    """Raise ``ValueError`` unless ``workers`` is None or a whole number >= 1 (an estimator's setting)."""
    if workers is not None and not (isinstance(workers, (int, np.integer)) and not isinstance(workers, bool)
                                    and workers >= 1):
        raise ValueError(f"workers must be None (the idle cores) or a whole number >= 1, got {workers!r}")


def in_worker() -> bool:
    """True inside a worker of :func:`map_axes` (where progress is the caller's to show)."""
    return _IN_WORKER


def map_axes(fn, items, workers: int | None = None, on_done=None) -> list:
    """``[fn(item) for item in items]``, the items in separate forked processes when more than one core is
    available (module docstring); the results in the order of ``items``.

    Parameters
    ----------
    fn : callable
        Called with one item; may be a closure or a bound method (it is inherited by the fork, never pickled).
        Its result must pickle.
    items : iterable
        Typically axis names.
    workers : int or None
        Largest number of processes; None: :func:`workers_available`.
    on_done : callable or None
        Called in the caller with each item as its task ends (in the order they end), e.g. to show progress.
    """
    items = list(items)
    report = on_done or (lambda item: None)
    n = min(len(items), workers_available() if workers is None else int(workers))
    if n <= 1 or _IN_WORKER or mp.parent_process() is not None or "fork" not in mp.get_all_start_methods():
        out = []
        for item in items:
            out.append(fn(item))
            report(item)
        return out
    global _TASK
    _TASK = fn
    pool = ProcessPoolExecutor(n, mp_context=mp.get_context("fork"), initializer=_mark_worker)
    try:
        futures = {pool.submit(_run, item): i for i, item in enumerate(items)}
        done = [None] * len(items)
        for future in as_completed(futures):
            done[futures[future]] = future.result()
            report(items[futures[future]])
    except BaseException:  # Ctrl-C above all: the workers go now, not when their fits end
        kill_workers(pool)
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    finally:
        _TASK = None
    pool.shutdown(wait=True)  # every result is in: the workers are idle and leave at once
    return [result if ok else fn(item) for item, (ok, result) in zip(items, done)]


def _mark_worker() -> None:
    """A worker's start: it knows it is one, and leaves interrupts to the caller (module docstring)."""
    global _IN_WORKER
    _IN_WORKER = True
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run(item):
    """One task in a worker: ``(True, result)``, or ``(False, None)`` when it raised (run again by the caller)."""
    try:
        return True, _TASK(item)
    except Exception:  # noqa: BLE001 - re-raised by the caller's own run of the same task
        return False, None
