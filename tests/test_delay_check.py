"""A servo delay tested in the delay-free closed loop (identification.likelihood.delay_check): a pilot who sees
the aircraft behind a noisy gyro can give the likelihood a servo delay the servo does not have; the delay-free
model flown under him makes it too, and then the delay is the loop's. A real servo delay is not made there; it
stands, and the check flies the axis through it."""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import pytest

from identification.bench.aircraft import AIRCRAFT
from identification.bench.cells import BENCH_CELLS
from identification.bench.synthetic import simulate_flight
from identification.likelihood.delay_check import DelayCheck, delay_candidates, loop_timing
from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier

SLUGGISH = AIRCRAFT["sluggish"]
"""The bench's large, slow helicopter (:mod:`identification.bench.aircraft`)."""


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


def _controller_flight(rate: float):
    """A flight controller's commands logged at ``rate`` from its loop 4x faster (what ``loop_ticks`` reads)."""
    meta = {"imported_from": {"format": "ardupilot-dataflash", "input_source": "controller",
                              "loop_rate_hz": 4.0 * rate}}
    return SimpleNamespace(metadata=meta, sample_rate=rate, dt=1.0 / rate)


def test_a_timing_a_fast_loop_makes_is_a_candidate_delay_or_lag_and_a_long_one_is_not():
    # the sluggish autopilot's 200 Hz logs, its loop at 800 Hz: a 7.3 ms lag (yaw, seed 1501) and a 5.4 ms delay
    # (seed 1505) on effect-free flights; the catalogue's servo lag of 30 ms is not the loop's
    modes = lambda: ["detect"] * 3  # noqa: E731
    fast = SimpleNamespace(flights_=[_controller_flight(200.0)], _delays=modes, axes_={
        "roll": SimpleNamespace(delay=0.0, lag=0.0073), "pitch": SimpleNamespace(delay=-5e-5, lag=0.030),
        "yaw": SimpleNamespace(delay=0.0054, lag=0.0)})
    assert delay_candidates(fast) == ["roll", "yaw"]
    behind = SimpleNamespace(flights_=[_controller_flight(200.0)], _delays=modes,
                             axes_={"yaw": SimpleNamespace(delay=0.004, lag=0.0073)})  # 11.3 ms in all: too long
    assert delay_candidates(behind) == []
    pilot = SimpleNamespace(flights_=[SimpleNamespace(metadata={}, sample_rate=200.0, dt=0.005)], _delays=modes,
                            axes_={"yaw": SimpleNamespace(delay=0.0, lag=0.0073)})  # no loop: a lag is not tested
    assert delay_candidates(pilot) == []
    assert loop_timing(0.005) == 0.010 and loop_timing(0.01) == 0.010 and loop_timing(0.02) == 0.02


def test_a_lag_taken_for_the_loops_says_so():
    check = DelayCheck("yaw", 0.0, 53.5, loops=True, dt=0.005, removed=True, inside_sample=4, lag=0.0073)
    line = check.line()
    assert line.startswith("yaw: servo lag 7.3 ms (LR 53.5)") and "within 10 ms (2 logged samples)" in line
    assert "4x faster than the log" in line and "fitted without it" in line
    assert "if one is known, --delay SECONDS fits it" in line  # a real servo this fast: the user's recourse
    assert json.loads(json.dumps(check.describe()))["lag_s"] == 0.0073
    at_50 = replace(check, dt=0.02, lag=0.0, delay=0.005)
    assert "servo delay 5.0 ms" in at_50.line() and "within 20 ms (1 logged sample)" in at_50.line()


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


def test_a_delay_whose_world_makes_more_than_all_of_it_is_corrected_to_none_not_below():
    from identification.likelihood.closed_loop import less_bias

    # seed 1501's yaw behind the autopilot 4x faster than its 200 Hz log, a real 10 ms servo delay: fitted 6.8 ms,
    # its world's bias +107 % (a negative tau_yaw ended heli identify)
    assert less_bias("tau_yaw", 0.0068, 1.07) == 0.0
    assert less_bias("tau_yaw", 0.0068, 0.5) == 0.0068 * 0.5
    assert less_bias("k11", 2.0, 0.2) == 2.0 * 0.8 and less_bias("k10", 6.0, -0.05) == 6.0 * 1.05
