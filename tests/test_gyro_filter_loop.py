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

from identification.bench.aircraft import AIRCRAFT
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
def test_a_loop_read_through_a_stated_filter_is_flown_through_it_and_its_bias_removed(seed):
    """Fitted at 50 Hz with the filter's lag on the input side (identification.likelihood.gyro_path), the loop 8x
    faster than the samples reads the roll damping high: +12 / +12 / +17 % (seeds 1-3); the world that flies the
    filter and the loop measures +10 / +8 / +14 % and removes it, ending at +1.0 / +2.3 / +1.3 %. Before the filter
    was on the input side its lag biased the fit down (-10 to -11 %); before the world flew the filter, the check
    left the dampings 47-97 % low."""
    sim, flight = _filtered_autopilot(seed)
    ml = MaximumLikelihoodIdentifier(axes=("roll",), closed_loop="auto").fit(flight)
    check = ml.closed_loop_.axes["roll"]
    assert check.checked and check.gyro_filter and check.loop_ticks == 8, check.reason
    assert check.fitted["k3"] / sim.truth.k3 - 1.0 > 0.05
    assert check.bias["k3"] > 2.0 * check.bias_se["k3"] and "k3" in check.removed and check.loops_direction
    assert abs(ml.params_.k3 / sim.truth.k3 - 1.0) < 0.04
    assert "through the low-pass the log states" in ml.closed_loop_.lines()[0]


def test_a_loop_whose_gyro_filter_is_not_stated_is_not_flown_and_says_how_to_state_it():
    """The fit rate lowered for a filtered gyro, the loop faster than the log, and no corner stated: the world
    cannot fly what the law read, so the axis is not checked (the fit's own values stand) and the reason says how to
    state the filter."""
    sim, flight = _filtered_autopilot(1)
    unstated = flight.with_metadata(gyro_filter_hz=None, fit_rate_by="data")  # as at_fit_rate's test thins it
    ml = MaximumLikelihoodIdentifier(axes=("roll",), closed_loop="auto").fit(unstated)
    check = ml.closed_loop_.axes["roll"]
    assert not check.checked and "--gyro-filter HZ" in check.reason and "low-passed" in check.reason
    assert ml.params_.k3 == ml.axes_["roll"].params["k3"]
    asked = flight.with_metadata(gyro_filter_hz=None, fit_rate_by="asked")  # --fit-rate 50: nothing said of a filter
    flown = MaximumLikelihoodIdentifier(axes=("roll",), closed_loop="auto").fit(asked).closed_loop_.axes["roll"]
    assert flown.checked and not flown.gyro_filter


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


def test_a_csvs_gyro_filter_is_stated_on_the_command_line_and_kept_in_its_source(tmp_path, capsys, monkeypatch):
    """A CSV cannot state its gyro filter: simulate-flight says how to, ``heli identify --gyro-filter HZ`` fits it
    where its noise is white enough and flies the loop through it, the model's source records it, and the integral
    method and diagnosis, which fly no loop, refuse it in one line."""
    import json

    from heli_cli import diagnose
    from heli_cli.main import main

    monkeypatch.setenv("HELI_CLOSED_LOOP", "auto")
    monkeypatch.setenv("HELI_FIT_RATE", "auto")
    flight = tmp_path / "ap.csv"
    assert main(["simulate-flight", "--cell", "broadband-autopilot", "--log-every", "4", "--gyro-filter", "20",
                 "--duration", "60", "--seed", "1", "--out", str(flight)]) == 0
    assert "--controller-loop 400 --gyro-filter 20 flies that loop through its gyro filter" in capsys.readouterr().out
    out = tmp_path / "m"
    assert main(["identify", str(flight), "--out", str(out), "--no-plots", "--no-disturbances", "--delay", "none",
                 "--servo-lag", "none", "--controller-loop", "400", "--gyro-filter", "20", "-q"]) == 0
    model = json.loads((out / "model.json").read_text())
    assert model["sample_rate_hz"] == pytest.approx(50.0)  # 20 Hz noise correlates by 0.58 at 100 Hz
    assert model["provenance"]["sources"][0]["gyro_filter_hz"] == 20.0
    axes = model["fit_statistics"]["closed_loop"]["axes"]
    assert any(c["checked"] and c["gyro_filter"] for c in axes.values()), axes
    report = (out / "report.md").read_text()
    assert "its gyro is stated low-passed at 20 Hz" in report
    assert "its law reading the gyro through the filter the log states" in report
    capsys.readouterr()
    assert main(["identify", str(flight), "--out", str(tmp_path / "integral"), "--method", "integral",
                 "--gyro-filter", "20"]) == 2
    assert "--gyro-filter needs the maximum-likelihood estimator" in capsys.readouterr().err
    seen = {}
    monkeypatch.setattr(diagnose, "_run_ml", lambda args, read, *rest: seen.update(read.metadata) or 0)
    assert main(["diagnose", str(flight), "--out", str(tmp_path / "d"), "--gyro-filter", "20"]) == 0
    assert seen["gyro_filter_hz"] == 20.0 and "loop_rate_hz" not in seen  # the filter alone stated


def test_the_filters_lag_is_not_taken_for_a_servo_lag_under_a_fast_loop():
    """The sluggish aircraft's pitch under an 800 Hz loop behind a 20 Hz filter, fitted at 50 Hz (120 s, seed 2).
    With the filter read as the aircraft's, the search took an 11.8 ms servo lag, which the world, flying the filter
    too, flew twice (on 300 s flights dampings -49 and -59 % where the fit was +73 and +63 %); a lag inside one sample
    of such a loop is removed as the filter's (delay_check.check_filter_lag). With the filter on the input side no lag
    is taken: the fit reads the loop's +59 % and the check ends at +13 %."""
    from identification.likelihood.estimator import CLI_TIMING

    sluggish = AIRCRAFT["sluggish"]

    config = replace(BENCH_CELLS["broadband-autopilot"], vibration_lines=(), vibration=0.0, log_every=8,
                     duration=120.0, gyro_filter_hz=20.0)
    sim = simulate_flight(120.0, seed=2, config=config, truth=sluggish)
    ml = MaximumLikelihoodIdentifier(**CLI_TIMING, axes=("pitch",), closed_loop="auto").fit(thinned(sim.flight, 2))
    assert ml.axes_["pitch"].lag == 0.0 and ml.axes_["pitch"].delay == 0.0 and not ml.closed_loop_.delays
    assert ml.closed_loop_.axes["pitch"].fitted["k7"] / sim.truth.k7 - 1.0 > 0.3  # the loop's bias, measured
    assert abs(ml.params_.k7 / sim.truth.k7 - 1.0) < 0.2


def test_the_warning_says_to_state_the_filter_where_the_check_could_not_fly_the_loop_without_it():
    from identification.validation.fit_warnings import controller_loop_warning

    flight = SimpleNamespace(metadata={"input_source": "flight controller commands", "loop_rate_hz": 400.0,
                                       "fit_rate_by": "data"}, sample_rate=50.0)  # thinned by the data's test
    unflown = SimpleNamespace(checked=False, loop_ticks=8, bias={}, removed=(),
                              reason="... the loop's world cannot fly it (state it: --gyro-filter HZ, ...)")
    [line] = controller_loop_warning([flight], check=SimpleNamespace(axes={"roll": unflown}))
    assert "State the gyro filter's corner (--gyro-filter HZ" in line and "Identify from the pilot's sticks" in line
    stated = SimpleNamespace(metadata={**flight.metadata, "gyro_filter_hz": 20.0}, sample_rate=50.0)
    [plain] = controller_loop_warning([stated], check=SimpleNamespace(axes={}))
    assert "--gyro-filter" not in plain


def test_the_loops_gyro_is_its_rate_through_the_filter_and_the_aircraft_flies_the_true_rate():
    """Open loop (sweeps replayed, no gusts, no noise): with the filter the gyro returned is the unfiltered one
    through it, and the angle integrates the true rate, not the filtered one."""
    from scipy.signal import lfilter

    from identification.likelihood.loop_world import _compiled_fly, gyro_biquad
    from identification.likelihood.state_space import discrete_model

    dt, n = 1 / 400.0, 2000
    stick = 0.5 * np.sin(np.arange(n) * dt * 9.0)
    Ad, g0, g1, _ = discrete_model(1.3, 4.0, 0.3, 1.0, 1.0, 0.5, dt, "zoh", "gm2")
    servo = np.array([0.0, 0.0, g0[0], 0.0, g1[0], 0.0])
    biquad = gyro_biquad(SimpleNamespace(metadata={"gyro_filter_hz": 20.0}), dt)
    args = (Ad, g0, g1, np.zeros((Ad.shape[0], n)), np.zeros(n), 2.0, np.zeros(n), 1, np.zeros(5), 0.0, stick, dt,
            0.0, servo)
    raw, angle_raw, _ = _compiled_fly()(*args, np.zeros(0))
    gyro, angle, _ = _compiled_fly()(*args, biquad)
    np.testing.assert_allclose(gyro, lfilter(biquad[:3], np.r_[1.0, biquad[3:]], raw), atol=1e-12)
    np.testing.assert_array_equal(angle, angle_raw)
    assert np.max(np.abs(gyro - raw)) > 0.01 * np.max(np.abs(raw))  # the filter's lag shows
