"""A flight controller's loop that reads its gyro through a low-pass (ArduPilot's INS_GYRO_FILTER): the closed-loop
check's world flies the filter the log states, removes the bias it measures whichever way it points, and does not
fly a loop whose filter it cannot know (identification.likelihood.loop_world.gyro_biquad)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from identification.bench.cells import BENCH_CELLS
from identification.bench.synthetic import simulate_flight
from identification.fit_rate import thinned
from identification.likelihood.estimator import MaximumLikelihoodIdentifier

FIXTURES = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "logs"


def _filtered_autopilot(seed: int, duration: float = 120.0):
    """The bench's autopilot at 400 Hz on a gyro low-passed at 20 Hz, logged at 100 Hz and fitted at 50 Hz (every
    second sample, as the fit-rate choice takes it); no vibration (the check's refits do not remove it)."""
    config = replace(BENCH_CELLS["broadband-autopilot"], vibration_lines=(), vibration=0.0, log_every=4,
                     duration=duration, gyro_filter_hz=20.0)
    sim = simulate_flight(duration, seed=seed, config=config)
    return sim, thinned(sim.flight, 2)


def test_the_filter_is_designed_at_the_loops_tick_as_the_firmware_designs_it():
    from scipy.signal import butter

    from identification.likelihood.loop_world import gyro_biquad

    b, a = butter(2, 20.0, fs=400.0)
    stated = SimpleNamespace(metadata={"gyro_filter_hz": 20.0})
    assert np.allclose(gyro_biquad(stated, 1 / 400.0), [b[0], b[1], b[2], a[1], a[2]])
    imported = SimpleNamespace(metadata={"imported_from": {"gyro_filter_hz": 20.0}})  # a CSV heli import wrote
    assert gyro_biquad(imported, 1 / 400.0).size == 5
    assert gyro_biquad(SimpleNamespace(metadata={}), 1 / 400.0).size == 0  # nothing stated: nothing flown
    assert gyro_biquad(SimpleNamespace(metadata={"gyro_filter_hz": 190.0}), 1 / 400.0).size == 0  # near Nyquist


def test_the_worlds_gyro_is_filtered_as_the_logs_and_its_noise_keeps_the_fitted_std():
    """The loop flown through the filter: the logged gyro's noise keeps the std the fit measured at the log's
    samples, and moves together from tick to tick as a low-passed noise does."""
    from identification.likelihood.loop_world import _filtered_noise, gyro_biquad

    biquad = gyro_biquad(SimpleNamespace(metadata={"gyro_filter_hz": 20.0}), 1 / 400.0)
    white = np.random.default_rng(3).standard_normal(80_000) * 0.02
    noise = _filtered_noise(white, biquad, 8)
    assert np.std(noise[::8]) == pytest.approx(np.std(white), rel=1e-9)
    lag1 = np.corrcoef(noise[:-1], noise[1:])[0, 1]
    assert lag1 > 0.9 and abs(np.corrcoef(white[:-1], white[1:])[0, 1]) < 0.02


@pytest.mark.parametrize("seed", [1, 2])
def test_a_loop_read_through_a_stated_filter_is_flown_through_it_and_its_bias_removed_downwards(seed):
    """Fitted at 50 Hz the filter's 11 ms lag reads as the aircraft's: the roll damping -10 to -11 % (three seeds);
    the world that flies the filter measures -12 % and removes it, ending within 2 % (-0.1, +1.4, +0.1 %). Before,
    the world flew the law on the unfiltered rate and left a bias that pointed down as not the loop's."""
    sim, flight = _filtered_autopilot(seed)
    ml = MaximumLikelihoodIdentifier(axes=("roll",), closed_loop="auto").fit(flight)
    check = ml.closed_loop_.axes["roll"]
    assert check.checked and check.gyro_filter and check.loop_ticks == 8, check.reason
    assert check.fitted["k3"] / sim.truth.k3 - 1.0 < -0.05
    assert check.bias["k3"] < -2.0 * check.bias_se["k3"] and "k3" in check.removed and check.loops_direction
    assert abs(ml.params_.k3 / sim.truth.k3 - 1.0) < 0.04
    assert "through the low-pass the log states" in ml.closed_loop_.lines()[0]


def test_a_loop_whose_gyro_filter_is_not_stated_is_not_flown_and_says_how_to_state_it():
    """The fit rate lowered for a filtered gyro, the loop faster than the log, and no corner stated: the world
    cannot fly what the law read, so the axis is not checked (the fit's own values stand) and the reason says how to
    state the filter."""
    sim, flight = _filtered_autopilot(1)
    unstated = flight.with_metadata(gyro_filter_hz=None)
    ml = MaximumLikelihoodIdentifier(axes=("roll",), closed_loop="auto").fit(unstated)
    check = ml.closed_loop_.axes["roll"]
    assert not check.checked and "--gyro-filter HZ" in check.reason and "low-passed" in check.reason
    assert ml.params_.k3 == ml.axes_["roll"].params["k3"]


def test_a_bias_either_way_is_removed_where_the_filter_was_flown():
    from identification.likelihood.closed_loop import against_the_loop, loops_direction

    se = {"k2": 0.002, "k3": 0.007}
    down = {"k2": -0.025, "k3": -0.12}
    assert "damping down" in against_the_loop(down, se, "k2", "k3", 8)
    assert loops_direction(down, se, "k2", "k3", 8, gyro_filter=True)


def test_an_ardupilot_log_states_its_gyro_filter_and_an_import_carries_it(tmp_path):
    log = FIXTURES / "ardupilot_copter_log171.bin"
    if not log.exists():
        pytest.skip(f"needs the shared fixtures ({log} is absent)")
    from identification.io.ardupilot import load_ardupilot
    from identification.io import _imported_from, meta_path

    assert load_ardupilot(log, allow_damaged=True).metadata["gyro_filter_hz"] == 20.0  # INS_GYRO_FILTER
    csv = tmp_path / "flight.csv"
    meta_path(csv).write_text(json.dumps({"format": "ardupilot-dataflash", "input_source": "controller",
                                          "loop_rate_hz": 400.0, "gyro_filter_hz": 20.0}))
    assert _imported_from(csv)["imported_from"]["gyro_filter_hz"] == 20.0


def test_a_stated_filter_is_kept_in_the_models_sources_and_checked_when_read():
    from model_store.model_file import ModelFileError, _sources

    [src] = _sources({"sources": [{"file": "f.csv", "sha256": "ab", "controller_loop_hz": 400,
                                   "gyro_filter_hz": 20}]}, "model.json")
    assert src.gyro_filter_hz == 20.0 and src.to_dict()["gyro_filter_hz"] == 20.0
    with pytest.raises(ModelFileError, match="gyro_filter_hz' must be a filter's corner in Hz above 0, got -1"):
        _sources({"sources": [{"file": "f.csv", "sha256": "ab", "gyro_filter_hz": -1}]}, "model.json")
