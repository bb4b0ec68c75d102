"""Tests of :mod:`identification.bench.synthetic`: the truth-model flights the other tests identify.

Session fixtures fly one 90 s flight twice with the same seed (under a second each,
the model's step compiled); everything else uses flights of a few seconds or no simulation at all.
"""

from __future__ import annotations

import json
import re
from dataclasses import fields, replace

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from identification.bench.flight_config import EFFECT_ALIASES, EFFECTS, PAPER_PARAMS, FlightConfig, truth_params
from identification.bench.synthetic import load_truth, simulate_flight, truth_paths
from identification.io import read_csv_flight

SEED = 7
DURATION = 90.0
ARRAYS = ("time", "rates", "attitude", "sticks")


@pytest.fixture(scope="session")
def flight():
    """The paper's truth, default wind and sensors, 90 s."""
    return simulate_flight(DURATION, seed=SEED)


@pytest.fixture(scope="session")
def flight_again():
    """The same flight flown a second time from the same seed."""
    return simulate_flight(DURATION, seed=SEED)


def _changed(params, base=PAPER_PARAMS) -> dict:
    """Parameters (base, delays, extra terms) whose value differs from ``base``."""
    names = [f.name for f in fields(params) if f.name != "extra"]
    out = {k: getattr(params, k) for k in names if getattr(params, k) != getattr(base, k)}
    base_extra = dict(base.extra)
    out.update({k: v for k, v in params.extra if base_extra.get(k) != v})
    return out


# ---------------------------------------------------------------------------------------- determinism


def test_same_seed_gives_a_bit_identical_flight_and_wind(flight, flight_again):
    for name in ARRAYS:
        assert_array_equal(getattr(flight.flight, name), getattr(flight_again.flight, name), err_msg=name)
    assert_array_equal(flight.wind, flight_again.wind)
    assert_array_equal(flight.wind_torque, flight_again.wind_torque)
    assert_array_equal(flight.true_rates, flight_again.true_rates)
    assert flight.truth == flight_again.truth


def test_different_seeds_give_different_flights_and_wind():
    a, b = simulate_flight(10, seed=1), simulate_flight(10, seed=2)
    assert not np.allclose(a.wind, b.wind)
    for name in ("rates", "attitude", "sticks"):
        assert not np.allclose(getattr(a.flight, name), getattr(b.flight, name)), name
    assert a.truth == b.truth  # the seed draws noise, never parameters


# ---------------------------------------------------------------------------------------- effects


@pytest.mark.parametrize("effect", list(EFFECTS))
def test_each_effect_switches_exactly_its_parameters(effect):
    assert _changed(truth_params([effect])) == EFFECTS[effect]


@pytest.mark.parametrize("alias", list(EFFECT_ALIASES))
def test_effect_aliases_switch_the_same_parameters(alias):
    assert truth_params([alias]) == truth_params([EFFECT_ALIASES[alias]])


def test_no_effect_is_the_paper_model_and_effects_combine():
    assert truth_params() == PAPER_PARAMS
    both = truth_params(["flybar", "servo_delay"])
    assert _changed(both) == EFFECTS["cross_coupling"] | EFFECTS["servo_delay"]


def test_an_effect_reaches_the_simulated_aircraft():
    """Same seed, same wind and noise draws; the flybar terms change the motion."""
    plain, flybar = simulate_flight(8, seed=3), simulate_flight(8, seed=3, effects=("flybar",))
    assert flybar.truth == truth_params(["cross_coupling"])
    assert flybar.effects == ("flybar",)
    assert_array_equal(plain.wind, flybar.wind)
    assert not np.allclose(plain.true_rates, flybar.true_rates)


def test_unknown_effect_is_rejected_naming_the_known_ones():
    known = ", ".join(list(EFFECTS) + list(EFFECT_ALIASES))
    with pytest.raises(ValueError, match=re.escape(f"unknown effect 'bogus'; known: {known}")):
        truth_params(["flybar", "bogus"])
    with pytest.raises(ValueError, match="unknown effect 'bogus'"):
        simulate_flight(1, effects=("bogus",))


# ---------------------------------------------------------------------------------------- config


@pytest.mark.parametrize(
    "field_name, value",
    [
        ("duration", 0.0), ("duration", -5.0), ("duration", float("nan")), ("duration", float("inf")),
        ("sample_rate", 0.0), ("sample_rate", float("inf")),
        ("wind_level", -0.01), ("wind_level", (0.09, -0.09, 0.03)), ("wind_level", (0.09, 0.09)),
        ("wind_level", float("nan")),
        ("wind_corner_hz", 0.0), ("pilot_bandwidth", -1.0), ("reaction_delay", -0.1),
        ("substeps", 0), ("substeps", 2.5), ("log_every", 0), ("log_every", 2.0),
        ("gyro_noise", -0.01), ("attitude_noise", -0.01), ("vibration", -0.01), ("stick_noise", -0.01),
        ("gyro_filter_hz", -20.0), ("gyro_filter_hz", 50.0),
    ],
)
def test_flight_config_rejects_bad_values(field_name, value):
    with pytest.raises(ValueError, match=rf"FlightConfig\.{field_name} out of range"):
        FlightConfig(**{field_name: value})


def test_a_config_names_the_settings_it_does_not_read():
    """What a study's --set would change for nothing: the gusts' corner under Gauss-Markov gusts, their time
    constant under the others, the slow gusts' time constant without slow gusts, the autopilot's D filter
    under another pilot; a setting the flight reads is not named."""
    fields = ["wind_corner_hz", "wind_fast_tau", "wind_slow_tau", "autopilot_dterm_hz", "reaction_delay"]
    assert set(FlightConfig(wind_model="gauss_markov", wind_slow_fraction=0.5).inert(fields)) == {
        "wind_corner_hz", "autopilot_dterm_hz"}
    assert set(FlightConfig(wind_model="dryden", pilot="autopilot").inert(fields)) == {"wind_fast_tau",
                                                                                       "wind_slow_tau"}


def test_config_duration_is_used_when_no_duration_is_given():
    assert simulate_flight(config=FlightConfig(duration=2.0)).flight.duration == pytest.approx(2.0)
    assert simulate_flight(3.0, config=FlightConfig(duration=2.0)).flight.duration == pytest.approx(3.0)


# ---------------------------------------------------------------------------------------- the flight


def test_sample_rate_is_100_hz(flight):
    f = flight.flight
    assert f.sample_rate == pytest.approx(100.0, rel=1e-9)
    assert_allclose(np.diff(f.time), 0.01, rtol=1e-9)
    assert f.n == int(DURATION * 100) + 1
    assert f.time[0] == 0.0


def test_a_log_of_a_faster_world_keeps_every_nth_sample_of_it():
    """``log_every``: the world (pilot, gusts, sensors) steps that many times faster and the log samples it, as a
    25 Hz logger samples a pilot and a flight that do not wait for it."""
    cfg = FlightConfig(duration=4.0, sample_rate=25.0, log_every=4)
    logged = simulate_flight(seed=5, config=cfg)
    fast = simulate_flight(seed=5, config=replace(cfg, sample_rate=100.0, log_every=1))
    assert logged.flight.n == 101 and logged.flight.sample_rate == pytest.approx(25.0, rel=1e-9)
    for name in ("rates", "attitude", "sticks"):
        assert np.array_equal(getattr(logged.flight, name), getattr(fast.flight, name)[:, ::4]), name
    for name in ("wind", "wind_torque", "true_rates"):
        assert np.array_equal(getattr(logged, name), getattr(fast, name)[:, ::4]), name
    assert logged.config == cfg and logged.flight.metadata["log_every"] == 4
    held = simulate_flight(seed=5, config=replace(cfg, held_sticks=True)).flight.metadata["input_hold"]
    assert held == "zoh at 100 Hz, one sample in 4 logged"  # held by the link, not at the log's rate


def test_a_filtered_gyro_is_the_same_flight_logged_through_the_filter_and_flown_on_by_the_autopilot():
    """``gyro_filter_hz``: a human pilot's flight is the same flight (no draw added), its logged rates the gyro's
    through a 2-pole Butterworth (about 10 ms late at 20 Hz on 100 Hz); the autopilot flies on that filtered
    gyro, so its flight changes."""
    from scipy.signal import butter, lfilter, lfilter_zi

    from identification.bench.synthetic import GyroFilter

    plain = simulate_flight(seed=3, config=FlightConfig(duration=6.0))
    filtered = simulate_flight(seed=3, config=FlightConfig(duration=6.0, gyro_filter_hz=20.0))
    for name in ("sticks", "attitude"):
        assert np.array_equal(getattr(filtered.flight, name), getattr(plain.flight, name)), name
    assert np.array_equal(filtered.true_rates, plain.true_rates)
    b, a = butter(2, 20.0, fs=100.0)
    zi = lfilter_zi(b, a)
    expected = np.array([lfilter(b, a, row, zi=zi * row[0])[0] for row in plain.flight.rates])
    assert_allclose(filtered.flight.rates, expected, rtol=0, atol=1e-12)
    lag = np.argmax(np.correlate(filtered.flight.rates[0] - filtered.flight.rates[0].mean(),
                                 plain.flight.rates[0] - plain.flight.rates[0].mean(), "full")) - (plain.flight.n - 1)
    assert lag == 1  # 10 ms, one sample
    one_by_one = GyroFilter(20.0, 100.0)
    stepped = np.array([one_by_one.step(list(col)) for col in plain.flight.rates.T]).T
    assert_allclose(stepped, expected, rtol=0, atol=1e-12)
    autopilot = FlightConfig(duration=6.0, pilot="autopilot")
    assert not np.array_equal(simulate_flight(seed=3, config=replace(autopilot, gyro_filter_hz=20.0)).flight.sticks,
                              simulate_flight(seed=3, config=autopilot).flight.sticks)


def test_sticks_stay_in_range(flight):
    assert np.all(np.abs(flight.flight.sticks) <= 1.0)
    # Sweeps far beyond full stick must be clipped, not passed on.
    wild = simulate_flight(12, seed=1, config=FlightConfig(sweep_amplitude=(3.0, 3.0, 3.0), collective_wander=2.0))
    s = wild.flight.sticks
    assert np.all(np.abs(s) <= 1.0)
    assert np.abs(s[0]).max() == 1.0  # the roll sweep (from t = 5 s) hit the stop


def test_wind_has_the_stated_90_percent_interval(flight):
    """Half-width of the 5-95 % interval of u_d per axis vs ``wind_level`` (0.09, 0.09, 0.03).

    Over 90 s of wind with a 0.5 Hz corner the half-width of a seed scatters by
    about 2.5 % (1 sigma over 200 seeds); 10 % is four sigma.
    """
    q05, q95 = np.quantile(flight.wind, [0.05, 0.95], axis=1)
    assert_allclose((q95 - q05) / 2, [0.09, 0.09, 0.03], rtol=0.10)
    assert_allclose(flight.wind.mean(axis=1), 0.0, atol=1e-12)  # zero-mean part: offsets are kd
    assert_allclose(flight.wind_torque, flight.truth.control_gains[:, None] * flight.wind, rtol=1e-12)


# ---------------------------------------------------------------------------------------- files


def test_save_writes_flight_truth_and_wind(flight, tmp_path):
    paths = flight.save(tmp_path / "hover.csv")
    assert paths == {"flight": tmp_path / "hover.csv", "truth": tmp_path / "hover.truth.json",
                     "wind": tmp_path / "hover.wind.csv"}
    assert truth_paths(tmp_path / "hover.csv") == {"truth": paths["truth"], "wind": paths["wind"]}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hover.csv", "hover.truth.json", "hover.wind.csv"]
    doc = json.loads(paths["truth"].read_text())
    assert doc["schema"] == "heli-env/synthetic-truth/1"
    assert doc["seed"] == SEED
    assert doc["config"]["duration"] == DURATION
    assert doc["wind_file"] == "hover.wind.csv"


def test_load_truth_returns_the_saved_parameters_and_wind(tmp_path):
    s = simulate_flight(5, seed=4, effects=tuple(EFFECTS))  # every base, delay and extra term non-zero
    s.save(tmp_path / "f.csv")
    params, wind = load_truth(tmp_path / "f.csv")
    assert params == s.truth
    assert wind.shape == s.wind.shape
    assert_allclose(wind, s.wind, rtol=1e-8, atol=1e-12)  # the wind file keeps 9 significant digits


def test_saved_flight_reads_back_equal(flight, tmp_path):
    path = flight.save(tmp_path / "f.csv")["flight"]
    back = read_csv_flight(path)
    for name in ARRAYS:
        assert_allclose(getattr(back, name), getattr(flight.flight, name), rtol=0, atol=1e-9, err_msg=name)


@pytest.mark.parametrize("case", ["paper, servo delay and lag, held sticks", "agile, quadratic damping, autopilot"])
def test_the_compiled_step_flies_the_same_flight_bit_for_bit(case, monkeypatch):
    """Long flights step the model compiled (heli_core.physics.compiled_rk4): every logged and true value is the
    Python step's, bit for bit, so a flight does not depend on its length's side of COMPILED_STEPS."""
    import identification.bench.synthetic as synthetic

    if case.startswith("paper"):
        kw = dict(effects=("servo_delay", "servo_lag"), config=FlightConfig(duration=15.0, held_sticks=True))
    else:
        from identification.bench.aircraft import AIRCRAFT

        kw = dict(truth=AIRCRAFT["agile"], effects=("nonlinear_damping",), effect_scale=5.0,
                  config=FlightConfig(duration=15.0, pilot="autopilot", sample_rate=200.0))
    flights = []
    for steps in (10**12, 0):  # Python, compiled
        monkeypatch.setattr(synthetic, "COMPILED_STEPS", steps)
        flights.append(simulate_flight(seed=SEED, **kw))
    python, compiled = flights
    for name in ARRAYS:
        assert_array_equal(getattr(compiled.flight, name), getattr(python.flight, name))
    assert_array_equal(compiled.true_rates, python.true_rates)
