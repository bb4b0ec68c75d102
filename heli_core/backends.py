"""Where independent tasks run: this process, a pool of local processes, or a Ray cluster.

A :class:`Backend` maps a function over items, ``fn(item, shared)`` for each
item, and returns the results **in item order**, whatever order the tasks
finished in. ``shared`` is the data every task reads (a sweep's gust windows, a
model, the flights of a fleet); it moves to each worker *once*, not once per
task:

* :class:`LocalBackend` — ``workers`` processes of this machine
  (:class:`concurrent.futures.ProcessPoolExecutor`, fresh interpreters by
  ``spawn``); ``shared`` is handed to each process once by the pool's
  initializer. ``workers=1`` runs in this process, with no pickling at all.
* :class:`RayBackend` — tasks of a Ray cluster (the ``cluster`` extra):
  ``shared`` and ``fn`` are put in the object store once (:func:`ray.put`) and
  every task receives a reference, which Ray resolves from the node's shared
  memory (numpy arrays without a copy).

Failures. Tasks must be pure (same item and shared data, same result), so a task
whose worker died can simply run again. Results are stored by item index, so a
retried task replaces its slot and never adds a second result. A worker that is
killed (out of memory, a node lost, ``kill -9``) costs the tasks it was running
and nothing else: Ray resubmits them itself (``max_retries``); the local pool,
which breaks as a whole when a process dies, is rebuilt and only the unfinished
items are resubmitted (up to ``max_retries`` times). An exception *raised* by
``fn`` (a ``FlightLogError``, a ``SweepError``) is
the caller's to see: it is re-raised as itself, with no retry, unless a
:class:`RayBackend` is told otherwise with ``retry_exceptions``. When retries run
out :class:`~heli_core.errors.TaskFailed` names the item. After a task
raises, no further task is submitted; tasks already running are left to finish
and their results are dropped (a :class:`RayBackend` keeps a bounded window of
tasks in flight and never calls :func:`ray.cancel`, whose race with a task's
reply aborts the driver process in Ray 2.x). Local workers end with the process that started them: a
parent killed mid-run (SIGKILL, out of memory) leaves no worker, forkserver or resource tracker behind.

The module sits in :mod:`heli_core`, the base layer, because identification of
many flights, the gain sweeps and RL training all use it, and
``identification`` must not import ``controllers`` (data flows identification →
heli_env → controllers). ``identification.backends`` and ``controllers.backends``
re-exported it (deprecated: :mod:`heli_core.deprecation`).

Ray is imported only when a :class:`RayBackend` is made; without it the error
names the extra to install (:class:`~heli_core.errors.MissingDependency`).
"""

from __future__ import annotations

import os
import sys

from .errors import BackendError, TaskFailed, require

BACKENDS = ("local", "ray")
"""Names :func:`make_backend` (and the ``--backend`` options) accept."""


def available_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


def _check_count(value, name, minimum):
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise BackendError(f"{name} must be a whole number >= {minimum}, got {value!r}")
    return value


class _Grown:
    """A caller's bar that one map adds its tasks to, left open for the next (see :meth:`Backend.map`)."""

    def __init__(self, bar, total):
        bar.total = (bar.total or 0) + total
        bar.refresh()
        self.bar = bar

    def __enter__(self):
        return self.bar

    def __exit__(self, *exc):
        return False


def _progress(total, show, desc):
    if hasattr(show, "update"):  # a bar the caller owns over several maps (a sweep's rounds)
        return _Grown(show, total)
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="task", leave=False, file=sys.stderr,
                disable=not show or not sys.stderr.isatty())


class Backend:
    """Runs ``fn(item, shared)`` for every item; results in item order.

    Subclasses implement :meth:`map`. A backend is a context manager; :meth:`close`
    releases what it started (a Ray instance it launched) and is safe to call twice.

    Attributes
    ----------
    name : str
        ``"local"`` or ``"ray"``.
    """

    name = "backend"

    def map(self, fn, items, shared=None, *, progress: bool = False, desc: str = "tasks") -> list:
        """``[fn(item, shared) for item in items]``, the calls spread over the backend's workers.

        Parameters
        ----------
        fn : callable (item, shared) -> result
            A module-level function (it is pickled by reference for local processes),
            pure: the same item and shared data give the same result.
        items : sequence
            One task per item; each is pickled with its task, so keep them small.
        shared : object, optional
            Read-only data every task needs; moved to each worker once.
        progress : bool or tqdm bar
            tqdm bar of finished tasks on stderr (when it is a terminal); or a bar the caller owns, which
            this map's tasks are added to and which is left open (one bar over several maps).
        desc : str
            Label of the bar.

        Returns
        -------
        list
            ``fn``'s results, in the order of ``items``.
        """
        raise NotImplementedError

    def describe(self) -> str:
        """One line for reports and settings, e.g. ``"local, 2 workers"``."""
        return self.name

    def close(self) -> None:
        """Release the backend's resources."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


# ------------------------------------------------------------------ local
_SHARED = None  # the shared data of the current pool, set once per worker process


def _set_shared(shared):
    global _SHARED
    _SHARED = shared


def _init_worker(shared, parent_pid):
    """The pool's initializer: the shared data, a watch that ends this worker with its parent, and interrupts
    left to the parent (a terminal's Ctrl-C reaches the whole process group; the parent, interrupted, kills its
    workers, and a worker interrupted too would only print its own traceback)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _set_shared(shared)
    _exit_with_parent(parent_pid)


def _start_forkserver() -> None:
    """Start the forkserver (and its resource tracker) with SIGINT ignored, which they and the workers forked
    from the server inherit: a Ctrl-C while the server imports its preload printed the server's traceback under
    the command's "interrupted". The window in which this process ignores SIGINT is the spawn of the server
    (milliseconds; its imports run after it); a server already running is left alone."""
    import signal
    import threading
    from multiprocessing import forkserver

    if threading.current_thread() is not threading.main_thread():  # only the main thread may set handlers
        forkserver.ensure_running()
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        forkserver.ensure_running()
    finally:
        signal.signal(signal.SIGINT, previous)


def _exit_with_parent(parent_pid: int) -> None:
    """End this process (``os._exit``) as soon as process ``parent_pid`` has ended, whatever ends it.

    A pool's workers block on queues whose pipes every sibling also holds, so a parent killed by SIGKILL (or
    out of memory) never closes them: without this watch the workers, and with them the forkserver and the
    resource tracker (which live while a worker holds their pipes), outlive it for ever (issue 15: about
    265 MiB after each killed run). The parent is named by pid, not by ``os.getppid()``: a worker started by
    the forkserver is the server's child. A daemon thread waits on a pidfd of the parent (Linux >= 5.3:
    readable when it exits; no polling, no race with a recycled pid), else polls every 0.5 s.
    """
    import threading

    try:
        fd = os.pidfd_open(parent_pid)
    except ProcessLookupError:  # already gone
        os._exit(1)
    except (AttributeError, OSError):  # not Linux, or an old kernel: poll
        fd = None

    def watch():
        if fd is not None:
            import select

            select.select([fd], [], [])
        else:  # pragma: no cover - without pidfd
            import time

            while True:
                try:
                    os.kill(parent_pid, 0)
                except ProcessLookupError:
                    break
                except OSError:  # alive, someone else's
                    pass
                time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="heli-exit-with-parent", daemon=True).start()


def _call_with_shared(fn, item):
    return fn(item, _SHARED)


class LocalBackend(Backend):
    """The cores of this machine.

    Parameters
    ----------
    workers : int, optional
        Processes to run tasks in (default: every core this process may use). With
        1, or a single item, tasks run in this process.
    max_retries : int
        Times the pool is rebuilt after a worker process died (the unfinished items
        are resubmitted each time) before :class:`TaskFailed` is raised.
    start_method : {"forkserver", "spawn", "fork"}, optional
        How worker processes start. Default ``forkserver`` where the OS has it, else
        ``spawn``: workers are forked from a clean single-threaded server process,
        so nothing of the caller's threads (BLAS pools, torch's OpenMP, tqdm) is
        inherited, and the modules the tasks need (numpy and the module of ``fn``)
        are imported once in the server, not once per worker (importing
        :mod:`controllers` costs 1.5-3 s on a busy 2-core machine).
    """

    name = "local"

    def __init__(self, workers: int | None = None, max_retries: int = 2, start_method: str | None = None):
        import multiprocessing

        if start_method is None:
            start_method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
        self.workers = available_cores() if workers is None else _check_count(workers, "workers", 1)
        self.max_retries = _check_count(max_retries, "max_retries", 0)
        if start_method not in multiprocessing.get_all_start_methods():
            raise BackendError(f"start_method must be one of {multiprocessing.get_all_start_methods()}, "
                               f"got {start_method!r}")
        self.start_method = start_method
        self.retries_ = 0  # pools rebuilt after a dead worker, over this backend's life

    def describe(self) -> str:
        return f"local, {self.workers} worker{'s' if self.workers != 1 else ''}"

    def map(self, fn, items, shared=None, *, progress: bool = False, desc: str = "tasks") -> list:
        items = list(items)
        if self.workers == 1 or len(items) <= 1:
            out = []
            with _progress(len(items), progress, desc) as bar:
                for item in items:
                    out.append(fn(item, shared))
                    bar.update(1)
            return out
        return self._map_pool(fn, items, shared, progress, desc)

    def _map_pool(self, fn, items, shared, progress, desc):
        import multiprocessing
        from concurrent.futures import FIRST_EXCEPTION, ProcessPoolExecutor, wait
        from concurrent.futures.process import BrokenProcessPool

        results = {}
        attempt = 0
        ctx = multiprocessing.get_context(self.start_method)
        if self.start_method == "forkserver":  # effective when the server starts (first pool of this process)
            ctx.set_forkserver_preload(["numpy", getattr(fn, "__module__", None) or "numpy", __name__])
            _start_forkserver()
        with _progress(len(items), progress, desc) as bar:
            while True:
                todo = [i for i in range(len(items)) if i not in results]
                pool = ProcessPoolExecutor(max_workers=min(self.workers, len(todo)), mp_context=ctx,
                                           initializer=_init_worker, initargs=(shared, os.getpid()))
                futures, broken, failed = {}, None, True
                try:
                    try:
                        for i in todo:
                            futures[pool.submit(_call_with_shared, fn, items[i])] = i
                    except BrokenProcessPool as e:  # a worker died while tasks were still being submitted
                        broken = e
                    pending = set(futures)
                    while pending and broken is None:
                        done, pending = wait(pending, return_when=FIRST_EXCEPTION)
                        for f in done:
                            exc = f.exception()
                            if isinstance(exc, BrokenProcessPool):
                                broken = exc
                            elif exc is not None:
                                raise exc  # the task's own error, for the caller
                    for f, i in futures.items():  # keyed by item: a rerun replaces, never duplicates
                        if i not in results and f.done() and not f.cancelled() and f.exception() is None:
                            results[i] = f.result()
                            bar.update(1)
                    failed = broken is not None
                finally:
                    if failed:
                        kill_workers(pool)
                    pool.shutdown(wait=True, cancel_futures=True)
                if broken is None:
                    return [results[i] for i in range(len(items))]
                attempt += 1
                self.retries_ += 1
                if attempt > self.max_retries:
                    lost = [i for i in range(len(items)) if i not in results]
                    raise TaskFailed(
                        f"a local worker process died {attempt} times (max_retries={self.max_retries}); "
                        f"{len(lost)} of {len(items)} tasks unfinished, first item #{lost[0]}", lost[0]) from broken


def kill_workers(pool) -> None:
    """SIGKILL the processes of a ``ProcessPoolExecutor`` that broke, whose task failed, or whose caller was
    interrupted (also :func:`identification.likelihood.axis_pool.map_axes`'s), before its ``shutdown``.

    A broken ``ProcessPoolExecutor`` terminates the workers it knows of, but a worker
    it starts for a task submitted while it was breaking (a race in CPython 3.11)
    escapes, blocks writing its result to a pipe nobody reads, and ``shutdown`` then
    waits for it for ever; after a task's error the others need not finish either.
    """
    for p in list((getattr(pool, "_processes", None) or {}).values()):
        try:
            if p.is_alive():
                p.kill()
        except (OSError, ValueError):  # already gone or closed
            pass


# -------------------------------------------------------------------- ray
def _ray_call(fn, item, shared):
    return fn(item, shared)


class RayBackend(Backend):
    """Tasks on a Ray cluster (the ``cluster`` extra).

    Parameters
    ----------
    address : str, optional
        Cluster to connect to, e.g. ``"ray://head:10001"`` or ``"head:6379"``. Default:
        ``RAY_ADDRESS`` when set, else a Ray instance started on this machine (and shut
        down by :meth:`close`). If Ray is already initialised in this process it is used
        as it is.
    max_retries : int
        Times Ray reruns a task whose worker process or node died (default 3).
    retry_exceptions : bool or tuple of exception types
        Also rerun tasks that *raised* these exceptions (default False: an exception
        raised by the task is deterministic and goes straight to the caller).
    num_cpus : int, optional
        CPUs of a Ray instance started here (default: all); ignored when connecting.
    cpus_per_task : float
        CPUs Ray reserves per task (default 1: one task per core, numpy single-threaded).
    init_kwargs : dict, optional
        More arguments of :func:`ray.init` when this backend initialises Ray.

    Raises
    ------
    MissingDependency
        Ray is not installed (``pip install 'heli-env[cluster]'``).
    """

    name = "ray"

    def __init__(self, address: str | None = None, max_retries: int = 3, retry_exceptions=False,
                 num_cpus: int | None = None, cpus_per_task: float = 1.0, init_kwargs: dict | None = None):
        self._ray = require("ray", "cluster")
        self.address = address
        self.max_retries = _check_count(max_retries, "max_retries", 0)
        if not (isinstance(retry_exceptions, bool) or (
                isinstance(retry_exceptions, (tuple, list))
                and all(isinstance(t, type) and issubclass(t, BaseException) for t in retry_exceptions))):
            raise BackendError(f"retry_exceptions must be a bool or exception classes, got {retry_exceptions!r}")
        self.retry_exceptions = list(retry_exceptions) if isinstance(retry_exceptions, tuple) else retry_exceptions
        self.num_cpus = None if num_cpus is None else _check_count(num_cpus, "num_cpus", 1)
        if not (isinstance(cpus_per_task, (int, float)) and cpus_per_task > 0):
            raise BackendError(f"cpus_per_task must be > 0, got {cpus_per_task!r}")
        self.cpus_per_task = float(cpus_per_task)
        self.init_kwargs = dict(init_kwargs or {})
        self._owns = False
        self._remote = None

    def _connect(self):
        ray = self._ray
        if not ray.is_initialized():
            kwargs = {"include_dashboard": False, "log_to_driver": False, **self.init_kwargs}
            address = self.address or os.environ.get("RAY_ADDRESS") or None
            if address is None and self.num_cpus is not None:
                kwargs.setdefault("num_cpus", self.num_cpus)
            ray.init(address=address, **kwargs)
            self._owns = True
        if self._remote is None:
            self._remote = ray.remote(num_cpus=self.cpus_per_task, max_retries=self.max_retries,
                                      retry_exceptions=self.retry_exceptions)(_ray_call)
        return ray

    @property
    def workers(self) -> int:
        """CPUs of the cluster (connects if needed)."""
        ray = self._connect()
        return int(ray.cluster_resources().get("CPU", 0))

    def describe(self) -> str:
        ray = self._connect()
        nodes = sum(1 for n in ray.nodes() if n.get("Alive"))
        return f"ray, {self.workers} CPUs on {nodes} node{'s' if nodes != 1 else ''}"

    def map(self, fn, items, shared=None, *, progress: bool = False, desc: str = "tasks") -> list:
        """Run ``fn(item, shared)`` on the cluster; results in item order.

        At most :attr:`in_flight` tasks are submitted at a time, and a task that
        raises stops further submission. Tasks already running are left to finish
        (their results are dropped): :func:`ray.cancel` of a task whose reply is
        arriving aborts the driver process in Ray 2.x ("Tried to complete task
        that was not pending", ray-project/ray#54846), so it is never called.
        """
        ray = self._connect()
        items = list(items)
        if not items:
            return []
        fn_ref, shared_ref = ray.put(fn), ray.put(shared)  # into the object store once
        window = self.in_flight
        refs, results, nxt = {}, {}, 0
        with _progress(len(items), progress, desc) as bar:
            while len(results) < len(items):
                while nxt < len(items) and len(refs) < window:
                    refs[self._remote.remote(fn_ref, items[nxt], shared_ref)] = nxt
                    nxt += 1
                done, _ = ray.wait(list(refs), num_returns=1)
                for ref in done:
                    index = refs.pop(ref)
                    results[index] = self._get(ray, ref, index, items)
                    bar.update(1)
        return [results[i] for i in range(len(items))]

    @property
    def in_flight(self) -> int:
        """Tasks submitted at once: twice the cluster's task slots, so no worker waits for the next one."""
        return max(2, 2 * int(self.workers / self.cpus_per_task))

    def _get(self, ray, ref, index, items):
        try:
            return ray.get(ref)
        except ray.exceptions.RayTaskError as e:  # fn raised: give the caller its own exception
            cause = getattr(e, "cause", None)
            if isinstance(cause, BaseException):
                raise cause from e
            raise
        except ray.exceptions.RayError as e:  # the worker or its node died more than max_retries times
            raise TaskFailed(f"Ray task #{index} of {len(items)} failed after {self.max_retries} retries: "
                             f"{type(e).__name__}: {e}", index) from e

    def close(self) -> None:
        if self._owns and self._ray.is_initialized():
            self._ray.shutdown()
        self._owns = False
        self._remote = None


# ------------------------------------------------------------------ choose
def make_backend(backend=None, workers: int | None = None, **kwargs) -> Backend:
    """A backend from a name (``"local"``, ``"ray"``), a :class:`Backend` (returned as is) or None (local).

    Parameters
    ----------
    backend : {"local", "ray"}, Backend or None
    workers : int, optional
        Local processes, or the CPUs of a Ray instance started on this machine
        (ignored when connecting to a cluster). Default: all cores.
    **kwargs
        Passed to :class:`LocalBackend` or :class:`RayBackend`.

    Raises
    ------
    BackendError
        An unknown name.
    MissingDependency
        ``"ray"`` without the ``cluster`` extra.
    """
    if isinstance(backend, Backend):
        return backend
    if backend is None or backend == "local":
        return LocalBackend(workers, **kwargs)
    if backend == "ray":
        return RayBackend(num_cpus=workers, **kwargs)
    raise BackendError(f"backend must be one of {BACKENDS} or a Backend, got {backend!r}")

