"""A servo delay tested in the delay-free closed loop (identification.likelihood.delay_check): a pilot who sees
the aircraft behind a noisy gyro can give the likelihood a servo delay the servo does not have; the delay-free
model flown under him makes it too, and then the delay is the loop's. A real servo delay is not made there; it
stands, and the check flies the axis through it."""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import pytest

from heli_core.params import ModelParams
from identification.bench.cells import BENCH_CELLS
from identification.bench.synthetic import simulate_flight
from identification.likelihood.delay_check import DelayCheck, delay_candidates
from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier

SLUGGISH = ModelParams(k2=0.7, k3=1.2, kd1=0.02, k6=-0.5, k7=1.1, kd2=0.01, k10=6.0, k11=1.6, k12=-0.3, kd3=0.05)
"""scripts/aircraft_generalisation.py's large, slow helicopter."""


def test_a_world_flight_reproduces_the_delay_within_one_sample_near_its_lr():
    # the sluggish pitch behind the noisy gyro, held sticks, no servo delay (seed 303): the flight's 11.7 ms at
    # LR 22.7, the delay-free world's best flights 22.6 at 12.0 ms and 20.9 at 11.2 ms
    check = DelayCheck("pitch", 0.0117, 22.7, dt=0.01)
    assert check.reproduces(0.0120, 22.6) and check.reproduces(0.0112, 20.9)
    assert not check.reproduces(0.0, 0.0)  # the world's flight kept no delay
    assert not check.reproduces(0.0350, 40.0)  # another delay
    assert not check.reproduces(0.0117, 12.0)  # too weak
    # a pilot's hand with a real 10 ms delay (seed 303): the flight's 16.6 ms at LR 45.4; the world's loop optima
    # (27.3 at 13.5 ms, 24.4 at 11.7 ms) are not it
    real = DelayCheck("pitch", 0.0166, 45.4, dt=0.01)
    assert not real.reproduces(0.0135, 27.3) and not real.reproduces(0.0117, 24.4)


def test_the_delay_check_is_reported_in_words_and_json():
    world = [(0.0, 0.0), (0.0118, 23.0), (0.0, 0.0)]
    loops = DelayCheck("pitch", 0.0117, 22.7, world, loops=True, dt=0.01, removed=True)
    assert "made by 1 of 3 flights" in loops.line() and "fitted without it" in loops.line()
    assert "reported, kept" in replace(loops, removed=False).line()  # the check's mode "report"
    assert json.loads(json.dumps(loops.describe()))["loops"] is True
    stands = DelayCheck("pitch", 0.0299, 149.0, [(0.0, 0.0)] * 3, dt=0.01)
    assert "made by 0 of 3" in stands.line() and "it stands" in stands.line()
    untested = DelayCheck("roll", 0.02, reason="its sticks follow the logged gyro (a flight controller's loop)")
    assert "not tested" in untested.line()


def test_only_delays_the_search_found_are_tested():
    fit = SimpleNamespace(delay=0.012, lag=0.0)
    found = SimpleNamespace(axes_={"pitch": fit, "roll": SimpleNamespace(delay=0.0, lag=0.0)},
                            _delays=lambda: ["detect", "detect", "detect"])
    assert delay_candidates(found) == ["pitch"]
    given = SimpleNamespace(axes_={"pitch": fit}, _delays=lambda: [0.0, 0.012, 0.0])  # the user's delay stands
    assert delay_candidates(given) == []
    lagged = SimpleNamespace(axes_={"pitch": SimpleNamespace(delay=0.012, lag=0.03)},
                             _delays=lambda: ["detect"] * 3)
    assert delay_candidates(lagged) == []


def _held_noisy_gyro(seed: int, truth):
    config = replace(BENCH_CELLS["broadband-pd-noisy-gyro"], held_sticks=True, command_noise=0.01)
    return simulate_flight(300.0, seed=seed, config=config, truth=truth)


@pytest.mark.slow
def test_a_delay_the_loop_makes_is_removed_and_the_axis_checked():
    sim = _held_noisy_gyro(303, SLUGGISH)
    ml = MaximumLikelihoodIdentifier(**CLI_TIMING).fit(sim.flight)
    assert ml.axes_["pitch"].delay > 0.005 and ml.params_.k7 > 1.3 * SLUGGISH.k7  # +48 %
    check = ml.closed_loop_check("auto")
    assert check.delays["pitch"].loops and check.delays["pitch"].removed, check.delays["pitch"].line()
    assert ml.axes_["pitch"].delay == 0.0 and ml.params_.tau_pitch == 0.0
    assert check.axes["pitch"].checked
    assert abs(ml.params_.k7 / SLUGGISH.k7 - 1.0) < 0.08  # +1.9 %


@pytest.mark.slow
def test_a_real_servo_delay_stands_and_the_check_flies_the_axis_through_it():
    sim = _held_noisy_gyro(304, replace(SLUGGISH, tau_pitch=0.02))
    ml = MaximumLikelihoodIdentifier(**CLI_TIMING).fit(sim.flight)
    fitted = ml.axes_["pitch"].delay
    assert fitted > 0.025 and ml.params_.k7 > 1.2 * SLUGGISH.k7  # 35 ms, +31 %: the loop lengthens it
    check = ml.closed_loop_check("auto")
    tested = check.delays["pitch"]
    assert not tested.loops and not tested.reason, tested.line()
    pitch = check.axes["pitch"]
    assert pitch.checked and {"k7", "tau_pitch"} <= set(pitch.removed), check.lines()
    assert 0.02 < ml.axes_["pitch"].delay < fitted and ml.params_.tau_pitch == ml.axes_["pitch"].delay  # 29 ms
    assert abs(ml.params_.k7 / SLUGGISH.k7 - 1.0) < 0.08  # +4.6 %


def test_a_profiled_fit_carries_its_undelayed_likelihood_for_the_world_flights_ratio():
    """The world's flights take the delay-free likelihood from the profile's own undelayed fit instead of a second
    fit (delay_check._lr without the fit): it is the delay-free fit's, to rounding, on an axis with a servo delay
    and on one without; a fit that did not profile has none."""
    truth = replace(SLUGGISH, tau_pitch=0.02)
    flight = simulate_flight(60, seed=5, config=replace(BENCH_CELLS["independent"], duration=60), truth=truth).flight
    settings = dict(axes=("roll", "pitch"), input_hold="zoh", wind_model="gm2", workers=1)
    profiled = MaximumLikelihoodIdentifier(delay="auto", **settings).fit(flight)
    plain = MaximumLikelihoodIdentifier(**settings).fit(flight)
    assert profiled.axes_["pitch"].delay > 0.01 and profiled.axes_["roll"].delay == 0.0
    for axis in ("roll", "pitch"):
        assert profiled.axes_[axis].undelayed_nll == pytest.approx(plain.axes_[axis].nll, rel=1e-12, abs=1e-9)
        assert plain.axes_[axis].undelayed_nll is None
