"""A gyro filtered before it is logged, moved to the input side: the stick enters the rate through the filter the log
states (identification.likelihood.gyro_path), so that its lag is not read as the aircraft's."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from identification.likelihood.gyro_path import matched, path_increments
from identification.likelihood.state_space import servo_increments


def _sticks(n=600, seed=0):
    return np.cumsum(np.random.default_rng(seed).normal(size=n)) * 0.01


@pytest.mark.parametrize("hold", [0.0, 0.4, 1.0])
def test_without_a_filter_the_path_is_the_servo_of_eq_31(hold):
    u = _sticks()
    assert np.allclose(path_increments(u, 4.0, 0.03, 0.02, hold, 0.01), servo_increments(u, 4.0, 0.03, 0.02, hold, 0.01),
                       rtol=0, atol=1e-15)


def test_the_filter_passes_a_steady_stick_and_delays_a_slow_one_by_its_lag():
    """At rest the path gives the rate's forced increment ((1 - exp(-d dt)) / d per unit stick); at 1 Hz the 2-pole
    20 Hz filter is a lag of sqrt(2) / (2 pi 20) = 11.25 ms, as a first-order servo lag of that size is."""
    damping, dt = 4.0, 0.01
    steady = path_increments(np.ones(50), damping, 0.0, dt, 0.0, 0.0, 20.0)
    assert np.allclose(steady, (1.0 - np.exp(-damping * dt)) / damping, rtol=1e-12)
    slow = np.sin(2 * np.pi * np.arange(0, 10, dt))
    through_filter = path_increments(slow, damping, 0.0, dt, 1.0, 0.0, 20.0)
    through_lag = path_increments(slow, damping, 0.0, dt, 1.0, np.sqrt(2) / (2 * np.pi * 20.0))
    assert np.max(np.abs(through_filter - through_lag)) < 0.02 * np.max(np.abs(through_filter))
    assert np.max(np.abs(through_filter - path_increments(slow, damping, 0.0, dt, 1.0))) > 0.05 * np.max(
        np.abs(through_filter))


def test_other_commands_are_matched_to_the_filter_and_left_alone_without_one():
    from scipy.signal import hilbert

    t = np.arange(0, 20, 0.02)
    x = np.sin(2 * np.pi * t)
    y = matched(x, 20.0, 50.0)
    lag = -np.angle(np.mean(hilbert(y[100:]) * np.conj(hilbert(x[100:])))) / (2 * np.pi)
    assert lag == pytest.approx(np.sqrt(2) / (2 * np.pi * 20.0), rel=0.01)
    assert matched(x, None, 50.0) is not None and np.array_equal(matched(x, None, 50.0), x)
    assert matched(np.full(10, 0.3), 20.0, 50.0) == pytest.approx(np.full(10, 0.3))  # settled on the first sample


def test_a_stated_filter_is_not_read_as_the_aircrafts_lag_or_its_damping():
    """A pilot's interpolated sticks, the gyro low-passed at 20 Hz at 400 Hz and logged at 100 Hz, fitted at 50 Hz
    (as the stated corner thins it): with the corner the roll damping and gain come out within 4 % and the sticks
    interpolated (hold 0.98-1.00 on the bench's aircraft); read without it, the filter's 11 ms is half a 50 Hz sample
    and the fit takes the sticks for held (hold 0) with the damping further off."""
    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.fit_rate import at_fit_rate
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier

    config = replace(BENCH_CELLS["independent"], duration=150.0, log_every=4, gyro_filter_hz=20.0)
    sim = simulate_flight(150.0, seed=1501, config=config)
    (flight,), chosen = at_fit_rate([sim.flight], "auto")
    assert chosen.hz == 50.0
    stated = MaximumLikelihoodIdentifier(axes=("roll",), closed_loop=None).fit(flight)
    unstated = MaximumLikelihoodIdentifier(axes=("roll",), closed_loop=None).fit(
        flight.with_metadata(gyro_filter_hz=None))
    k3, k2 = sim.truth.k3, sim.truth.k2
    assert abs(stated.params_.k3 / k3 - 1) < 0.04 and abs(stated.params_.k2 / k2 - 1) < 0.04
    assert stated.axes_["roll"].input_hold > 0.8 > unstated.axes_["roll"].input_hold
    assert abs(unstated.params_.k3 / k3 - 1) > abs(stated.params_.k3 / k3 - 1)


def test_a_world_that_flies_a_white_gyro_states_no_filter_for_its_fits():
    """A pilot's world in the closed-loop check flies a white gyro at the log's rate: its flights keep the log's
    metadata but no corner (neither the log's own nor an import's), so its fits put no filter on the input side."""
    from identification.validation.fit_warnings import gyro_filter, without_gyro_filter

    meta = {"gyro_filter_hz": 20.0, "input_source": "pilot", "imported_from": {"gyro_filter_hz": 20.0, "format": "x"}}
    assert gyro_filter(meta) == 20.0
    white = without_gyro_filter(meta)
    assert gyro_filter(white) is None
    assert white["input_source"] == "pilot" and white["imported_from"] == {"format": "x"}
    assert meta["gyro_filter_hz"] == 20.0  # the log's own metadata is left as it was


def test_the_fit_says_the_sticks_pass_the_stated_filter():
    from identification.bench.synthetic import simulate_flight
    from identification.validation.fit_warnings import fit_warnings

    flight = simulate_flight(20.0, seed=3).flight
    said = [w for w in fit_warnings(flight.with_metadata(gyro_filter_hz=20.0)) if "low-passed at" in w]
    assert said and "20 Hz (11.3 ms of lag)" in said[0] and "passes the sticks through that filter" in said[0]
    assert not [w for w in fit_warnings(flight) if "low-passed at" in w]


def test_flights_pooled_with_and_without_a_stated_filter_fit_together():
    """``heli refresh`` pools an old CSV (no corner stated) with a new ArduPilot log (its INS_GYRO_FILTER): the stick of
    the first enters its rate directly, the second's through the filter, in one likelihood."""
    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.fit_rate import thinned
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier

    plain = simulate_flight(90.0, seed=5).flight
    config = replace(BENCH_CELLS["independent"], duration=90.0, log_every=4, gyro_filter_hz=20.0)
    filtered = simulate_flight(90.0, seed=6, config=config)
    pooled = [thinned(plain, 2), thinned(filtered.flight, 2)]
    ml = MaximumLikelihoodIdentifier(axes=("roll",), closed_loop=None).fit(pooled)
    assert abs(ml.params_.k3 / filtered.truth.k3 - 1) < 0.1 and abs(ml.params_.k2 / filtered.truth.k2 - 1) < 0.05
