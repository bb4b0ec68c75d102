"""Tests of :func:`identification.validation.fit_warnings.fit_warnings`: one line per concern, none for good data."""

from __future__ import annotations

import numpy as np
import pytest

from identification.flight import make_flight
from identification.validation.fit_warnings import MIN_DURATION_S, MIN_R2, fit_warnings


def _flight(duration=120.0, rate=50.0, source="f.csv", ped=0.3, r_scale=1.0, col=0.05, noise=0.005):
    t = np.arange(0.0, duration, 1.0 / rate)
    w = 2 * np.pi * 0.4
    sticks = np.array([0.3 * np.sin(w * t), 0.3 * np.cos(w * t), 0.1 + col * np.sin(0.1 * w * t),
                       ped * np.sin(1.3 * w * t)])
    rates = np.array([0.2 * np.sin(w * t), 0.2 * np.cos(w * t), r_scale * 0.3 * np.sin(1.3 * w * t)])
    rates = rates + noise * np.random.default_rng(0).standard_normal(rates.shape)  # a gyro's noise floor
    return make_flight(t, rates, sticks, metadata={"source": source})


GOOD = {"roll": 0.8, "pitch": 0.75, "yaw": 0.9}


def test_a_long_well_excited_well_fitted_flight_gets_no_warning():
    assert fit_warnings([_flight()], GOOD) == []
    assert fit_warnings(_flight(), GOOD) == []  # one flight needs no list


def test_a_constant_collective_and_a_log_filtered_before_it_was_written_are_said():
    (line,) = fit_warnings([_flight(col=0.0)], GOOD)
    assert line.startswith("the collective does not vary (std 0 within each flight)")
    (line,) = fit_warnings([_flight(noise=0.0)], GOOD)  # pure tones: no noise floor at all
    assert "the rates carry nothing above about" in line and "low-pass filtered before it was written" in line


def test_a_short_flight_is_named_with_its_length():
    (line,) = fit_warnings([_flight(duration=5.0, source="hop.csv")], GOOD)
    assert line.startswith(f"flight 'hop.csv' lasts 5.0 s, shorter than {MIN_DURATION_S:.0f} s")


def test_a_weak_fit_names_the_axis_and_the_share_explained():
    lines = fit_warnings([_flight()], {**GOOD, "pitch": 0.02})
    assert lines == [f"pitch: the model explains 2 % of the rate variance (fit R² 0.02), below {100 * MIN_R2:.0f} %: "
                     "it says little about this axis; check the segment and the logging rate"]
    assert len(fit_warnings([_flight()], {**GOOD, "roll": -0.5})) == 1  # a negative R² reads as 0 %


def test_a_weak_fit_of_a_loop_faster_than_the_log_says_the_true_model_predicts_little_there():
    """A 25 Hz log of a 200 Hz loop's commands: the bench's true model predicted its yaw 0.5 s ahead at R² -0.24."""
    f = _flight(rate=25.0)
    fast = make_flight(f.time, f.rates, f.sticks, metadata={"source": "ap25.csv", "loop_rate_hz": 200.0,
                                                             "input_source": "flight controller commands"})
    (line,) = fit_warnings([fast], {**GOOD, "yaw": -0.19})
    assert line.startswith("yaw: the model explains 0 % of the rate variance")
    assert "from a loop 8x faster than the log" in line and "even the true model predicts little" in line
    (plain,) = fit_warnings([f], {**GOOD, "yaw": -0.19})  # a pilot's sticks: no such clause
    assert plain.endswith("check the segment and the logging rate")
    at_rate = make_flight(f.time, f.rates, f.sticks, metadata={"loop_rate_hz": 25.0,
                                                               "input_source": "flight controller commands"})
    assert fit_warnings([at_rate], {**GOOD, "yaw": -0.19})[0].endswith("check the segment and the logging rate")


def test_another_input_source_is_advised_only_for_a_flight_from_a_log():
    """``heli import --inputs`` can change a fit only where a flight controller's log was imported: a CSV the user
    wrote, or a synthetic flight, gets no advice it cannot follow (#31.3)."""
    imported = _flight().with_metadata(imported_from={"format": "betaflight-blackbox", "input_source": "controller"})
    (line,) = fit_warnings([imported], {**GOOD, "pitch": 0.02})
    assert "check the input source (heli import --inputs), the segment and the logging rate" in line
    raw = _flight().with_metadata(format="ardupilot-dataflash")  # read from the .bin itself
    assert "heli import --inputs" in fit_warnings([raw], {**GOOD, "pitch": 0.02})[0]
    (line,) = fit_warnings([_flight(ped=0.0)], GOOD)
    assert line.endswith("(fly sweeps on ped)")


def test_an_imported_csv_knows_its_log_from_the_metadata_beside_it(tmp_path):
    import json

    from identification.io import meta_path, read_flight, write_csv_flight

    csv = write_csv_flight(_flight(), tmp_path / "bf.csv")
    assert "imported_from" not in read_flight(csv).metadata
    meta_path(csv).write_text(json.dumps({"format": "betaflight-blackbox", "input_source": "controller"}))
    assert dict(read_flight(csv).metadata)["imported_from"] == {"format": "betaflight-blackbox",
                                                               "input_source": "controller"}
    meta_path(csv).write_text("{not json")  # a damaged sidecar is no import record, never an error
    assert "imported_from" not in read_flight(csv).metadata


@pytest.mark.parametrize("kwargs", [{"ped": 0.0}, {"r_scale": 0.0}], ids=["stick-still", "rate-still"])
def test_a_barely_excited_axis_is_named(kwargs):
    (line,) = fit_warnings([_flight(**kwargs)], GOOD)
    assert line.startswith("yaw is barely excited: the ped stick varies by")


def test_axes_without_a_figure_are_not_judged_and_order_is_flights_then_axes():
    flights = [_flight(duration=20.0, source="a.csv", ped=0.0), _flight(duration=25.0, source="b.csv", ped=0.0)]
    lines = fit_warnings(flights, {"roll": None, "pitch": float("nan"), "yaw": 0.1})
    assert [line.split(" ")[0] for line in lines] == ["the", "yaw", "yaw:"]
    assert lines[0].startswith("the 2 flights ('a.csv' 20.0 s, 'b.csv' 25.0 s) last 45.0 s in all")  # fitted together
    assert fit_warnings(flights, None)[:1] == lines[:1]


def test_thresholds_can_be_changed():
    assert fit_warnings([_flight(duration=30.0)], GOOD, min_duration_s=20.0) == []
    assert len(fit_warnings([_flight()], GOOD, min_r2=0.85)) == 2


# --------------------------------------------------------------- the R² that judges a maximum-likelihood model
@pytest.fixture(scope="module")
def windy_yaw():
    """The project's own 300 s flight (seed 1, `heli simulate-flight --duration 300 --seed 1`): the yaw wind
    dominates the yaw rate, so the sticks alone explain 24 % of it although the model is right."""
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier
    from identification.bench.synthetic import simulate_flight

    sim = simulate_flight(duration=300.0, seed=1)
    return sim, MaximumLikelihoodIdentifier().fit([sim.flight])


def test_a_correct_model_in_strong_wind_gets_no_weak_fit_warning(windy_yaw):
    from identification.validation.judged_fit import AHEAD_LABEL, judged_r2

    sim, ident = windy_yaw
    yaw = ident.axes_["yaw"]
    assert yaw.r2 < MIN_R2  # what the warning once judged by
    for name in ("k10", "k11"):  # the model is right (tolerance: 3 %, measured 1-2 %)
        np.testing.assert_allclose(yaw.params[name], sim.truth.get(name), rtol=0.03)
    r2, label = judged_r2(ident, [sim.flight])
    assert label == AHEAD_LABEL and r2["yaw"] > MIN_R2 + 0.2  # measured 0.66
    assert not [line for line in fit_warnings([sim.flight], r2, label) if "explains" in line]


def test_a_model_of_sticks_that_are_not_the_inputs_is_warned_about(windy_yaw):
    """The same flight with its pedal replaced by another flight's: what identify must still call weak."""
    from identification.validation.judged_fit import judged_r2
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier
    from identification.bench.synthetic import simulate_flight

    sim, _ = windy_yaw
    other = simulate_flight(duration=300.0, seed=2).flight
    sticks = sim.flight.sticks.copy()
    sticks[3] = other.sticks[3][: sticks.shape[1]]
    wrong = make_flight(sim.flight.time, sim.flight.rates, sticks,
                        metadata={"source": "wrong.log", "format": "ardupilot-dataflash"})
    ident = MaximumLikelihoodIdentifier(axes=("yaw",)).fit([wrong])
    lines = [line for line in fit_warnings([wrong], *judged_r2(ident, [wrong])) if line.startswith("yaw:")]
    assert len(lines) == 1 and "0.5 s-ahead prediction R²" in lines[0] and "heli import --inputs" in lines[0]
