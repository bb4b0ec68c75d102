"""Axes fitted side by side (identification.likelihood.axis_pool): the same result as one after another."""

from __future__ import annotations

import pytest

from identification.bench.synthetic import simulate_flight
from identification.likelihood.axis_pool import map_axes, workers_available
from identification.likelihood.estimator import MaximumLikelihoodIdentifier


def test_the_axes_fitted_in_two_processes_equal_the_serial_fit_bit_for_bit():
    flight = simulate_flight(90, seed=5).flight
    serial = MaximumLikelihoodIdentifier(workers=1).fit(flight)
    pooled = MaximumLikelihoodIdentifier(workers=2).fit(flight)
    assert pooled.params_.values() == serial.params_.values()
    for axis in serial.axes_:
        assert pooled.axes_[axis].std_errors == serial.axes_[axis].std_errors


def test_results_keep_the_items_order_and_each_end_is_reported():
    ended = []
    assert map_axes(lambda axis: axis.upper(), ["roll", "pitch", "yaw"], 2, ended.append) == ["ROLL", "PITCH", "YAW"]
    assert sorted(ended) == ["pitch", "roll", "yaw"]


class _Unpicklable(Exception):
    def __init__(self, axis, why):  # two arguments: pickling it from a worker would fail
        super().__init__(f"{axis}: {why}")


def test_a_failing_axis_raises_the_callers_own_exception():
    def fit(axis):
        if axis == "pitch":
            raise _Unpicklable(axis, "diverged")
        return axis

    with pytest.raises(_Unpicklable, match="pitch: diverged"):
        map_axes(fit, ["roll", "pitch", "yaw"], 2)


def test_heli_workers_caps_the_processes_and_is_checked(monkeypatch):
    monkeypatch.setenv("HELI_WORKERS", "1")
    assert workers_available() == 1
    monkeypatch.setenv("HELI_WORKERS", "two")
    with pytest.raises(ValueError, match="HELI_WORKERS must be a whole number"):
        workers_available()
    with pytest.raises(ValueError, match="workers must be None"):
        MaximumLikelihoodIdentifier(workers=0).fit(simulate_flight(90, seed=5).flight)


def test_by_default_only_the_cores_other_work_leaves_idle(monkeypatch):
    import os

    monkeypatch.delenv("HELI_WORKERS", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    monkeypatch.setattr(os, "getloadavg", lambda: (1.0, 1.0, 1.0))  # this process alone
    assert workers_available() == 2
    monkeypatch.setattr(os, "getloadavg", lambda: (2.1, 2.0, 2.0))  # a busy neighbour: forking would cost
    assert workers_available() == 1
    monkeypatch.setenv("HELI_WORKERS", "2")  # those who know better
    assert workers_available() == 2


_INTERRUPTED_POOL = """
import os, sys, time
from identification.likelihood.axis_pool import map_axes

def fit(axis):
    open(os.path.join(sys.argv[1], axis), "w").close()  # this worker has started its fit
    time.sleep(120)
    return axis

try:
    map_axes(fit, ["roll", "pitch", "yaw"], 2)
except KeyboardInterrupt:
    print("interrupted", flush=True)
    sys.exit(130)
"""


def test_ctrl_c_during_a_pooled_fit_ends_the_caller_and_its_workers_at_once(tmp_path):
    """A terminal's Ctrl-C reaches the whole process group. A worker interrupted inside the pool's queues left
    `heli identify` waiting on it for ever; now the caller alone is interrupted and ends its workers."""
    import os
    import signal
    import subprocess
    import sys
    import time

    started = tmp_path / "started"
    started.mkdir()
    script = tmp_path / "pooled_fit.py"
    script.write_text(_INTERRUPTED_POOL)
    env = dict(os.environ, PYTHONPATH=os.getcwd())
    process = subprocess.Popen([sys.executable, str(script), str(started)], env=env, start_new_session=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while len(list(started.iterdir())) < 2 and time.monotonic() < deadline:  # both workers in a fit
            time.sleep(0.05)
        assert len(list(started.iterdir())) == 2, "the workers never started"
        os.killpg(process.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole group
        out, err = process.communicate(timeout=30)  # the fits' 120 s are not waited for
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    assert (process.returncode, out.strip()) == (130, "interrupted"), err
    time.sleep(0.5)  # the terminated workers' exit
    with pytest.raises(ProcessLookupError):  # no worker left running in the group
        os.killpg(process.pid, 0)
