"""The hold decided in the closed loop's world (identification.likelihood.hold_check): where a pilot who sees the
aircraft biases the fit, his interpolated sticks look held; the flight's hold evidence, read against the two
worlds the check can fly, tells which they were."""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import pytest

from heli_core.files import jsonable
from identification.bench.aircraft import AIRCRAFT
from identification.bench.cells import BENCH_CELLS
from identification.bench.synthetic import simulate_flight
from identification.likelihood.closed_loop import AxisCheck, ClosedLoopCheck
from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier
from identification.likelihood.hold_check import (HoldCheck, axis_votes, choose_hold, decide_hold_in_loop,
                                                  decided_label, majority_hold, needs_hold_check)
from identification.reports.identify import method_sentence

SLUGGISH = AIRCRAFT["sluggish"]
"""The bench's large, slow helicopter (:mod:`identification.bench.aircraft`): the aircraft the hold's bias was found
on."""

# the LRs (held - interpolated, summed over roll, pitch and yaw) of the eight flights of each world that an early
# run of the comparison gave on the sluggish aircraft's noisy-gyro flight of seed 301 (a pilot's hand; its own
# LR -12.4)
LINEAR_WORLD = [-7.5, -12.0, -0.9, -9.3, -0.9, -14.4, -4.9, -7.1]
HELD_WORLD = [-25.6, -31.8, -19.1, -28.1, -20.2, -33.6, -23.7, -26.1]


def test_the_flights_lr_chooses_the_world_that_reproduces_it():
    # a pilot's hand behind the noisy gyro: held sticks preferred by 12.4, as the interpolated world prefers them
    chosen, worlds, reason = choose_hold(-12.4, {"linear": LINEAR_WORLD, "zoh": HELD_WORLD}, decided="zoh")
    assert chosen == "linear" and not reason
    assert worlds["linear"]["z"] == pytest.approx((-12.4 - worlds["linear"]["mean"]) / worlds["linear"]["sd"])
    # held sticks: the held world's figure
    assert choose_hold(-30.0, {"linear": LINEAR_WORLD, "zoh": HELD_WORLD}, decided="zoh")[0] == "zoh"
    assert choose_hold(-30.0, {"linear": LINEAR_WORLD, "zoh": HELD_WORLD}, decided="linear")[0] == "zoh"


def test_a_flight_neither_world_reproduces_keeps_the_decided_hold_and_says_so():
    chosen, _, reason = choose_hold(-80.0, {"linear": LINEAR_WORLD, "zoh": HELD_WORLD}, decided="linear")
    assert chosen == "linear" and "no world reproduces" in reason


def _per_axis(means: dict, spread: float = 2.0) -> list:
    """Eight simulated flights' per-axis LRs about ``means`` (axis -> mean), the same deviations on each axis."""
    offsets = [-2.5, -1.5, -0.8, -0.2, 0.2, 0.8, 1.5, 2.5]
    return [{a: m + spread * d for a, m in means.items()} for d in offsets]


def test_one_axis_whose_hold_is_confounded_does_not_carry_the_others():
    """A delay the search did not find makes its axis look held (half a sample late): summed, its LR puts a
    pilot's hand in the held world; the other two axes' own LRs point to the interpolated one, and decide."""
    worlds = {"linear": _per_axis({"roll": -2.0, "pitch": -1.0, "yaw": -2.0}),
              "zoh": _per_axis({"roll": -9.0, "pitch": -10.0, "yaw": -9.0})}
    flight = {"roll": -2.5, "pitch": -24.0, "yaw": -3.0}
    total = sum(flight.values())
    chosen, _, _ = choose_hold(total, {h: [sum(r.values()) for r in lrs] for h, lrs in worlds.items()}, "zoh")
    assert chosen == "zoh"  # the sum alone: held
    votes = axis_votes(flight, worlds, "zoh")
    assert votes == {"roll": "linear", "pitch": None, "yaw": "linear"}  # pitch: beyond both worlds' spreads
    assert majority_hold(votes) == "linear"
    # held sticks: every axis in the held world
    held = {"roll": -9.5, "pitch": -10.5, "yaw": -8.0}
    assert majority_hold(axis_votes(held, worlds, "zoh")) == "zoh"
    # fewer than three axes, or no majority: the sum decides
    assert majority_hold({"roll": "linear", "yaw": "linear"}) is None
    assert majority_hold({"roll": "linear", "pitch": "zoh", "yaw": None}) is None
    # said so: the terminal's line names the majority, not a world that reproduces the sum
    hold = HoldCheck("zoh", "linear", ("roll", "pitch", "yaw"), total, {"linear": {"mean": -5.0, "sd": 3.0},
                     "zoh": {"mean": -28.0, "sd": 4.0}}, "the axes' majority (roll, yaw) points to linear where "
                     "their sum pointed to zoh", applied=True, votes=votes, by_majority=True)
    assert hold.line().endswith("the axes' majority (roll, yaw) points to linear where their sum pointed to zoh: "
                                "hold zoh -> linear")
    assert json.loads(json.dumps(hold.describe()))["votes"]["pitch"] is None


# the LRs of the three worlds the check flew for the paper aircraft's flight of seed 1 logged at 25 Hz behind a
# 0.03 rad/s gyro (a pilot's hand; the likelihood alone read a fraction 0.72, dampings 12-18 % high; its own LR +66)
FLOWN_25HZ = {"linear": [103.8, 78.9, 74.3, 76.3, 80.9, 82.2, 109.6, 94.2],
              "zoh": [-171.3, -159.6, -171.4, -197.3, -195.6, -174.6, -206.8, -203.9],
              "fraction 0.72": [22.8, 3.0, 15.8, 49.5, 20.8, 13.9, -1.4, 21.2]}


def test_a_fraction_the_loop_drew_is_read_against_its_own_world_and_both_named_ones():
    assert decided_label({"named": None, "fraction": 0.7213}) == "fraction 0.72"
    assert decided_label({"named": "zoh", "fraction": 0.0}) == "zoh"
    chosen, worlds, reason = choose_hold(66.1, FLOWN_25HZ, decided="fraction 0.72")
    assert chosen == "linear" and not reason and set(worlds) == set(FLOWN_25HZ)
    # sticks stamped part-way through their sample: the fraction's own world reproduces its LR, and it stands
    kept = choose_hold(18.0, FLOWN_25HZ, decided="fraction 0.72")[0]
    hold = HoldCheck("fraction 0.72", kept, ("roll", "pitch", "yaw"), 18.0, {})
    assert kept == "fraction 0.72" and not hold.switched


def _check(damping_bias: float, loops_direction: bool = True) -> ClosedLoopCheck:
    axis = AxisCheck("pitch", True, bias={"k6": -0.02, "k7": damping_bias}, bias_se={"k6": 0.003, "k7": 0.015},
                     loops_direction=loops_direction)
    return ClosedLoopCheck({"pitch": axis}, 8, 0, "auto", 1.0)


def test_the_hold_is_checked_only_where_the_loops_bias_could_have_reached_it():
    decided = SimpleNamespace(input_hold="auto", hold_decision_={"named": "zoh", "fraction": 0.0})
    assert needs_hold_check(decided, _check(0.10)) == ""
    assert "no bias" in needs_hold_check(decided, _check(0.02))  # within two standard errors
    assert "no bias" in needs_hold_check(decided, _check(0.10, loops_direction=False))
    fixed = SimpleNamespace(input_hold="zoh", hold_decision_=None)  # the user's hold is not second-guessed
    assert "not decided" in needs_hold_check(fixed, _check(0.10))
    pooled = SimpleNamespace(input_hold="auto", hold_decision_={"named": None, "fraction": 0.72})  # the data's
    assert needs_hold_check(pooled, _check(0.10)) == ""  # a fraction the loop drew is read in its world as well,
    assert needs_hold_check(pooled, _check(0.02)) == ""  # even where the check at it measured no bias
    unchecked = ClosedLoopCheck({"pitch": AxisCheck("pitch", False, reason="a flight controller's loop")}, 8, 0,
                                "auto", 1.0)
    assert "no bias" in needs_hold_check(pooled, unchecked)  # but not where no axis was flown


def test_the_hold_is_read_on_axes_without_a_servo_delay():
    """A delay shapes the phase as a hold does: an axis with one does not vote on the log's hold."""
    delayed = SimpleNamespace(input_hold="auto", hold_decision_={"named": "zoh", "fraction": 0.0},
                              axes_={"pitch": SimpleNamespace(delay=0.02, lag=0.0)})
    hold = decide_hold_in_loop(delayed, _check(0.10), 8)
    assert hold.chosen == "zoh" and not hold.worlds and "servo delay or lag" in hold.reason


def test_the_hold_check_is_reported_in_words_and_json():
    _, worlds, _ = choose_hold(-12.4, {"linear": LINEAR_WORLD, "zoh": HELD_WORLD}, decided="zoh")
    hold = HoldCheck("zoh", "linear", ("roll", "pitch", "yaw"), -12.4, worlds, applied=True)
    check = replace(_check(0.10), hold=hold)
    assert hold.switched and check.lines()[-1].endswith("hold zoh -> linear")
    assert "(reported, not applied)" in replace(hold, applied=False).line()  # the check's mode "report"
    assert json.loads(json.dumps(check.describe()))["hold"]["chosen"] == "linear"
    kept = HoldCheck("zoh", "zoh", reason="no bias the loop's way: the loop does not reach the hold")
    assert "zoh kept" in kept.line() and not kept.switched


def _noisy_gyro_flight(seed: int, held: bool):
    config = replace(BENCH_CELLS["broadband-pd-noisy-gyro"], held_sticks=held, command_noise=0.01 if held else 0.0)
    return simulate_flight(300.0, seed=seed, config=config, truth=SLUGGISH)


@pytest.mark.slow
def test_a_pilots_hand_taken_for_held_sticks_is_found_and_the_dampings_mended():
    sim = _noisy_gyro_flight(301, held=False)
    ml = MaximumLikelihoodIdentifier(**CLI_TIMING).fit(sim.flight)
    assert ml.hold_decision_["named"] == "zoh"  # the loop's bias drew the hold (dampings 20-26 % high)
    assert ml.params_.k7 > 1.15 * SLUGGISH.k7
    hold = ml.closed_loop_check("auto").hold
    assert hold.decided == "zoh" and hold.chosen == "linear" and hold.applied, hold.line()
    assert ml.hold_decision_["named"] == "linear" and all(f.input_hold == 1.0 for f in ml.axes_.values())
    assert "linear hold, decided in the closed loop's world" in method_sentence(ml)  # the report says so
    for k in ("k3", "k7", "k11"):  # 4.6 / 1.5 / 3.9 % after; 23 / 26 / 21 % before
        assert abs(getattr(ml.params_, k) / getattr(SLUGGISH, k) - 1.0) < 0.08, k


@pytest.mark.slow
def test_a_servo_delay_on_one_axis_does_not_make_a_pilots_hand_look_held():
    """A real 10 ms pitch delay behind the noisy gyro: fitted delay-free, the pitch votes for held sticks (the sum
    over the three axes sat in the held world and roll and yaw were fitted held, k3 / k11 +20 %); read on roll and
    yaw the hold is the hand's."""
    config = replace(BENCH_CELLS["broadband-pd-noisy-gyro"])
    sim = simulate_flight(300.0, seed=301, config=config, truth=replace(SLUGGISH, tau_pitch=0.01))
    ml = MaximumLikelihoodIdentifier(**CLI_TIMING).fit(sim.flight)
    assert ml.axes_["pitch"].delay > 0.0
    hold = ml.closed_loop_check("auto").hold
    assert hold.axes == ("roll", "yaw") and hold.chosen == "linear", hold.line()
    for k in ("k3", "k11"):  # 4.8 / 3.9 % after; 23 / 21 % before
        assert abs(getattr(ml.params_, k) / getattr(SLUGGISH, k) - 1.0) < 0.08, k


@pytest.mark.slow
def test_held_sticks_behind_the_same_gyro_stay_held():
    sim = _noisy_gyro_flight(302, held=True)
    ml = MaximumLikelihoodIdentifier(**CLI_TIMING).fit(sim.flight)
    hold = ml.closed_loop_check("auto").hold
    assert hold is not None and hold.chosen == "zoh" and not hold.switched and not hold.applied, hold.line()
    assert ml.hold_decision_["named"] == "zoh"
    stored = json.loads(json.dumps(jsonable(ml.closed_loop_.describe()), allow_nan=False))  # as model.json stores it
    assert stored["hold"]["chosen"] == "zoh" and stored["hold"]["applied"] is False


@pytest.mark.slow
def test_a_fraction_the_loop_drew_from_a_pilots_hand_is_moved_to_it():
    """Logged at 25 Hz behind a 0.03 rad/s gyro, a pilot's hand on the paper aircraft read as a fraction 0.72: the
    check at the fraction measured its own world's 1-5 %, the dampings stood 12-18 % high."""
    config = replace(BENCH_CELLS["broadband-pd-noisy-gyro"], sample_rate=25.0, vibration=0.0, vibration_lines=())
    sim = simulate_flight(300.0, seed=1, config=config)
    ml = MaximumLikelihoodIdentifier(**CLI_TIMING, closed_loop="auto").fit(sim.flight)
    hold = ml.closed_loop_.hold
    assert hold.decided.startswith("fraction 0.7") and hold.chosen == "linear" and hold.applied, hold.line()
    truth = sim.truth.values()
    for k in ("k3", "k7", "k11"):  # 5.2 / 2.1 / 1.9 % after; 15.5 / 11.5 / 12.7 % before
        assert abs(ml.params_.values()[k] / truth[k] - 1.0) < 0.08, k


@pytest.mark.slow
def test_a_controller_twice_as_fast_as_its_log_keeps_its_fraction():
    """Sticks held at 200 Hz and logged at 100 Hz change half-way through every logged sample: the fraction the
    likelihood reads (0.56) is the log's, its own world reproduces the flight's LR, and it stands."""
    sim = simulate_flight(300.0, seed=1, config=replace(BENCH_CELLS["held-sticks-pd"], sample_rate=200.0))
    f = sim.flight
    logged = type(f)(f.time[::2], f.rates[:, ::2], f.attitude[:, ::2], f.sticks[:, ::2], f.metadata,
                     {k: v[..., ::2] for k, v in f.extra.items()} if f.extra else f.extra)
    ml = MaximumLikelihoodIdentifier(**CLI_TIMING, closed_loop="auto").fit(logged)
    hold = ml.closed_loop_.hold
    assert hold.decided.startswith("fraction 0.5") and not hold.switched and not hold.reason, hold.line()
    truth = sim.truth.values()
    for k in ("k3", "k7", "k11"):  # -2.2 / -1.7 / +1.7 %
        assert abs(ml.params_.values()[k] / truth[k] - 1.0) < 0.05, k


def test_an_axis_left_for_its_direction_says_what_was_found():
    down = _check(-0.05, loops_direction=False)
    assert "not the loop's direction: the damping down beyond its noise; left" in down.lines()[0]
    agile_yaw = AxisCheck("yaw", True, bias={"k10": 0.11, "k11": 0.40}, bias_se={"k10": 0.01, "k11": 0.03},
                          loops_direction=False)  # the agile yaw in 2 Hz Dryden gusts (closed_loop's docstring)
    line = ClosedLoopCheck({"yaw": agile_yaw}, 8, 0, "auto", 1.0).lines()[0]
    assert "the gain's magnitude up beyond its noise" in line
