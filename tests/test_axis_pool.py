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
