"""How many threads the native vector env's step loop uses: one, unless more measure faster now.

Handing a loop to threads pays only where the batch is large, and only while the other cores are free:
on a 2-core machine with one core taken by another process, every parallel region waits for a thread
that is not running, and a step that takes 0.4 ms on one thread took 20 ms. So the vector env's
default (``threads=None``) measures instead of assuming:

* Fewer than :data:`THREADED_FROM` copies, or a thread pool of one: always one thread. The step's
  loop is then compiled without ``prange`` and numba's pool is never started.
* Otherwise the step times its loop (the only parallel region of a step) on one thread and on the
  pool, a few steps each, and keeps the pool only while its median is at most :data:`KEEP_BELOW`
  of one thread's. Pooled steps whose median comes out slower than that, or one that takes
  :data:`GIVE_UP` times one thread's (a neighbour took a core), send the env back to one thread at
  once; a new trial of the pool follows after :data:`FIRST_RETRIAL` steps, then twice as late after
  each trial the pool loses, up to :data:`LAST_RETRIAL`. A trial is not even started while the
  operating system counts a running thread on every other core (:func:`cores_taken`:
  ``/proc/loadavg``'s running count on Linux), and it takes one thread per free core (at most the
  pool); it stops at its first slow pooled step. The decision costs two timer reads a step; a lost
  trial, two slow steps.

``threads=k`` (the env's argument) or the environment variable ``HELI_NUM_THREADS=k`` fixes the count
instead (``1``: never start the pool); ``threads`` wins over ``HELI_NUM_THREADS``, and both are capped
at numba's pool size (``NUMBA_NUM_THREADS``, all cores by default). The results never depend on the
count: copies are independent and each is computed by the same code.

Numba's threading layer is chosen on purpose: :func:`prefer_workqueue` asks for ``workqueue``, numba's
own pool, unless ``NUMBA_THREADING_LAYER`` is set or numba's pool already runs. Measured on 2 cores
(``docs/benchmarks.md``): OpenMP's threads spin after each region, so with another process on the
second core they took its time and the threaded step collapsed; ``workqueue`` threads sleep. TBB was
not installed here to compare.
"""

from __future__ import annotations

import os
import statistics
import time

import numba

THREADED_FROM = 1024
"""Copies from which the default may try threads. On 2 quiet cores two threads took 5 % off a step of 256
copies, 15 % at 1024 and 22 % at 4096 (measured with the loops of before, 2026-11-24); the pool is kept
only for a gain of 15 % (:data:`KEEP_BELOW`), so smaller batches are not worth a trial's risk."""

TRIAL_STEPS = 5
"""Steps timed on each side of a trial; the first threaded step of a trial is not counted (it wakes the pool)."""

KEEP_BELOW = 0.85
"""The pool is kept while its median step loop takes at most this share of one thread's."""

GIVE_UP = 2.0
"""A pooled step loop this many times slower than one thread's ends the pool (or its trial) at once."""

FIRST_RETRIAL = 256
LAST_RETRIAL = 16384
"""Steps between trials of the pool: the first, and the most after the pool lost again and again."""

ENV_VAR = "HELI_NUM_THREADS"


def pool_size() -> int:
    """Numba's thread pool size (``NUMBA_NUM_THREADS``, all cores by default)."""
    return int(numba.config.NUMBA_NUM_THREADS)


def requested_threads(threads=None) -> int | None:
    """The fixed thread count asked for, or None for the measured default.

    ``threads`` (the env's argument) wins over ``$HELI_NUM_THREADS``. Raises ValueError for a count that
    is not a whole number from 1 to :func:`pool_size` (the variable: for one that is not a whole number
    >= 1; a larger count is capped at the pool, since the variable is meant for every machine it meets).
    """
    most = pool_size()
    if threads is not None:
        if isinstance(threads, bool) or int(threads) != threads or not 1 <= threads <= most:
            raise ValueError(f"threads must be a whole number from 1 to {most} (numba's thread pool), got {threads!r}")
        return int(threads)
    text = os.environ.get(ENV_VAR, "").strip()
    if not text:
        return None
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise ValueError(f"{ENV_VAR} must be a whole number >= 1 (threads of the vector env's step), got {text!r}")
    return min(value, most)


def usable_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def cores_taken() -> int:
    """Threads running now on the machine besides the caller's (Linux: ``/proc/loadavg``; elsewhere the
    1-minute load average, rounded). Cheap enough for a trial's start, not for every step."""
    try:
        with open("/proc/loadavg") as f:
            return max(int(f.read().split()[3].split("/")[0]) - 1, 0)
    except (OSError, IndexError, ValueError):
        try:
            return int(round(os.getloadavg()[0]))
        except OSError:
            return 0


def prefer_workqueue() -> None:
    """Ask numba for its ``workqueue`` layer before its pool starts, unless the user chose a layer."""
    from numba.np.ufunc import parallel

    if "NUMBA_THREADING_LAYER" not in os.environ and not parallel._is_initialized:
        numba.config.THREADING_LAYER = "workqueue"


class ThreadChoice:
    """Per step, whether the vector env's loop runs on one thread or on ``threads`` (see the module docstring).

    Parameters
    ----------
    n_copies : int
        Copies stepped per call.
    threads : int, optional
        A fixed count (the env's ``threads`` argument); None reads ``$HELI_NUM_THREADS``, then measures.
    """

    def __init__(self, n_copies: int, threads: int | None = None):
        fixed = requested_threads(threads)
        most = pool_size()
        self.measured = fixed is None and most > 1 and n_copies >= THREADED_FROM
        self.threads = fixed if fixed is not None else (most if self.measured else 1)
        self._most = self.threads
        self.parallel = self.threads > 1 and not self.measured  # the loop to run this step
        self._retrial = FIRST_RETRIAL
        self._countdown = TRIAL_STEPS  # the first trial soon: the pool's worth is unknown
        self._trial = None  # (one-thread times, pool times) while a trial runs
        self._one = []  # recent one-thread loop times [s]
        self._pool = []  # recent pool loop times [s]
        if self.threads > 1:
            prefer_workqueue()

    @property
    def compiled_parallel(self) -> bool:
        """A ``prange`` loop is needed at all (a fixed count above one, or the measured default)."""
        return self.threads > 1

    def run(self, serial, parallel, *args):
        """Call the one-thread loop ``serial`` or the pool's ``parallel`` on ``args``, as decided; time it."""
        if not self.measured:
            if self.parallel:
                numba.set_num_threads(self.threads)
                return parallel(*args)
            return serial(*args)
        pool = self.parallel
        if pool:
            numba.set_num_threads(self.threads)
        t0 = time.perf_counter()
        out = (parallel if pool else serial)(*args)
        self._record(pool, time.perf_counter() - t0)
        return out

    def _record(self, pool: bool, seconds: float) -> None:
        if self._trial is not None:
            self._trial_step(pool, seconds)
            return
        if pool:
            self._pool = (self._pool + [seconds])[-TRIAL_STEPS:]
            one = statistics.median(self._one) if self._one else None
            if one is not None and (seconds > one * GIVE_UP or (
                    len(self._pool) == TRIAL_STEPS and statistics.median(self._pool) > one * KEEP_BELOW)):
                self._lose()  # a neighbour took a core: back to one thread now
                return
        else:
            self._one = (self._one + [seconds])[-TRIAL_STEPS:]
        self._countdown -= 1
        if self._countdown <= 0:  # time for a trial (one-thread steps, then pool steps) if a core looks free
            free = usable_cores() - 1 - cores_taken()
            if free < 1:
                self._lose()
                return
            self.threads = min(self._most, 1 + free)
            self._trial = ([], [])
            self.parallel = False

    def _trial_step(self, pool: bool, seconds: float) -> None:
        ones, pools = self._trial
        if not pool:
            ones.append(seconds)
            if len(ones) == TRIAL_STEPS:
                self.parallel = True
            return
        pools.append(seconds)
        if len(pools) > 1 and seconds > statistics.median(ones) * GIVE_UP:
            self._trial = None
            self._lose()
            return
        if len(pools) <= TRIAL_STEPS:  # the first pool step wakes the pool's threads: not counted
            return
        self._trial = None
        self._one, self._pool = ones, pools[1:]
        if statistics.median(self._pool) <= statistics.median(self._one) * KEEP_BELOW:
            self.parallel = True
            self._retrial = FIRST_RETRIAL
            self._countdown = LAST_RETRIAL  # re-measure one thread now and then: the machine changes
        else:
            self._lose()

    def _lose(self) -> None:
        self.parallel = False
        self._pool = []
        self._countdown = self._retrial
        self._retrial = min(2 * self._retrial, LAST_RETRIAL)
