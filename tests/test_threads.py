"""Tests of the vector env's thread choice (:mod:`heli_env.threads`), on a fake clock."""

from __future__ import annotations

import numba
import pytest

from heli_env import threads as threads_mod
from heli_env.threads import (FIRST_RETRIAL, LAST_RETRIAL, THREADED_FROM, TRIAL_STEPS, ThreadChoice,
                              requested_threads)


class _Clock:
    """A perf_counter whose loops take the times we say: one thread ``one`` s, the pool ``pool`` s."""

    def __init__(self, monkeypatch, one, pool):
        self.now, self.one, self.pool, self.calls = 0.0, one, pool, []
        monkeypatch.setattr(threads_mod.time, "perf_counter", lambda: self.now)
        monkeypatch.setattr(threads_mod, "pool_size", lambda: 2)
        monkeypatch.setattr(threads_mod.numba, "set_num_threads", lambda k: None)
        monkeypatch.setattr(threads_mod, "prefer_workqueue", lambda: None)
        monkeypatch.setattr(threads_mod, "usable_cores", lambda: 2)
        self.others = 0  # threads the operating system runs besides ours
        monkeypatch.setattr(threads_mod, "cores_taken", lambda: self.others)

    def serial(self):
        self.now += self.one
        self.calls.append("one")

    def parallel(self):
        self.now += self.pool
        self.calls.append("pool")

    def steps(self, choice, k):
        for _ in range(k):
            choice.run(self.serial, self.parallel)
        return self.calls[-k:]


@pytest.fixture(autouse=True)
def _no_variable(monkeypatch):
    monkeypatch.delenv("HELI_NUM_THREADS", raising=False)


def test_small_batches_and_a_pool_of_one_never_use_threads(monkeypatch):
    clock = _Clock(monkeypatch, one=1.0, pool=0.1)
    choice = ThreadChoice(THREADED_FROM - 1)
    assert not choice.measured and not choice.compiled_parallel
    assert clock.steps(choice, 500) == ["one"] * 500
    monkeypatch.setattr(threads_mod, "pool_size", lambda: 1)
    assert not ThreadChoice(10 * THREADED_FROM).compiled_parallel


def test_the_pool_is_kept_while_it_measures_faster(monkeypatch):
    clock = _Clock(monkeypatch, one=1.0, pool=0.5)
    choice = ThreadChoice(THREADED_FROM)
    assert choice.measured and choice.compiled_parallel
    clock.steps(choice, 4 * TRIAL_STEPS)
    assert clock.steps(choice, 1000) == ["pool"] * 1000


def test_a_slower_pool_is_left_and_retried_ever_later(monkeypatch):
    clock = _Clock(monkeypatch, one=1.0, pool=3.0)
    choice = ThreadChoice(THREADED_FROM)
    clock.steps(choice, 40_000)
    pooled = [k for k, c in enumerate(clock.calls) if c == "pool"]
    trials = [k for k in pooled if k - 1 not in pooled]
    gaps = [b - a for a, b in zip(trials, trials[1:])]
    assert gaps[0] > FIRST_RETRIAL and all(b >= a for a, b in zip(gaps, gaps[1:]))
    assert max(gaps) <= LAST_RETRIAL + 3 * TRIAL_STEPS
    assert all(pooled.count(k) for k in trials)
    assert len(pooled) / len(clock.calls) < 0.002  # each trial stops at its first slow counted step: 2 steps


def test_no_trial_while_every_other_core_runs_something(monkeypatch):
    clock = _Clock(monkeypatch, one=1.0, pool=0.5)
    clock.others = 1
    choice = ThreadChoice(THREADED_FROM)
    assert clock.steps(choice, 5000).count("pool") == 0
    clock.others = 0  # the neighbour left: a later trial finds the pool faster
    assert clock.steps(choice, 5000)[-1] == "pool"


def test_a_neighbour_sends_the_env_back_to_one_thread_at_once(monkeypatch):
    clock = _Clock(monkeypatch, one=1.0, pool=0.5)
    choice = ThreadChoice(THREADED_FROM)
    clock.steps(choice, 100)
    assert clock.calls[-1] == "pool"
    clock.pool = 20.0  # another process takes a core: each parallel region waits for a descheduled thread
    after = clock.steps(choice, 50)
    assert after.count("pool") == 1 and after[-1] == "one"


def test_a_pool_that_stops_paying_is_left_within_a_few_steps(monkeypatch):
    clock = _Clock(monkeypatch, one=1.0, pool=0.5)
    choice = ThreadChoice(THREADED_FROM)
    clock.steps(choice, 100)
    clock.pool = 0.95  # slower than KEEP_BELOW of one thread, not GIVE_UP times: the median of a few steps says so
    after = clock.steps(choice, 50)
    assert 1 < after.count("pool") <= TRIAL_STEPS and after[-1] == "one"


def test_a_fixed_count_is_kept(monkeypatch):
    clock = _Clock(monkeypatch, one=1.0, pool=30.0)
    choice = ThreadChoice(THREADED_FROM, threads=2)
    assert not choice.measured
    assert clock.steps(choice, 50) == ["pool"] * 50
    monkeypatch.setenv("HELI_NUM_THREADS", "1")
    one = ThreadChoice(100 * THREADED_FROM)
    assert not one.measured and not one.compiled_parallel


def test_the_variable_and_the_argument(monkeypatch):
    monkeypatch.setenv("HELI_NUM_THREADS", "64")
    assert requested_threads() == numba.config.NUMBA_NUM_THREADS  # capped at numba's pool
    assert requested_threads(1) == 1  # the argument wins
    monkeypatch.setenv("HELI_NUM_THREADS", " ")
    assert requested_threads() is None


@pytest.mark.parametrize("text", ["0", "two", "-1", "1.5"])
def test_a_bad_variable_says_what_it_wants(monkeypatch, text):
    monkeypatch.setenv("HELI_NUM_THREADS", text)
    with pytest.raises(ValueError, match="HELI_NUM_THREADS must be a whole number >= 1"):
        requested_threads()


@pytest.mark.parametrize("threads", [0, 1.5, True, 10_000])
def test_a_bad_argument_says_what_it_wants(threads):
    with pytest.raises(ValueError, match="threads must be a whole number from 1 to"):
        requested_threads(threads)
