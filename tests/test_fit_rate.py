"""The rate a log is fitted at (``identification.fit_rate``): a gyro low-passed before it was logged (a flight
controller's filter, ``FlightConfig.gyro_filter_hz``) has noise the likelihood takes for motion at the log's rate;
the data decide to fit such a log at a fraction of its rate, and leave a white gyro's log at its own."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from identification.bench.cells import BENCH_CELLS
from identification.bench.synthetic import simulate_flight
from identification.fit_rate import FitRate, at_fit_rate, choose_fit_rate, every_for, nth, thinned
from identification.likelihood.estimator import MaximumLikelihoodIdentifier


@pytest.fixture(scope="module")
def filtered():
    """120 s of the independent cell, its gyro through ArduPilot's default 20 Hz 2-pole filter, logged at 100 Hz."""
    return simulate_flight(120, seed=3, config=replace(BENCH_CELLS["independent"], gyro_filter_hz=20.0))


def test_a_filtered_gyros_log_is_fitted_at_half_its_rate_and_fits_there(filtered):
    """At 100 Hz the damping reads several times the truth; the data choose 50 Hz, where it is within 10 % (the log
    states no corner here: a CSV cannot)."""
    truth = filtered.truth.values()
    (flight,), chosen = at_fit_rate([filtered.flight.with_metadata(gyro_filter_hz=None)])
    assert chosen.every == 2 and flight.sample_rate == pytest.approx(50.0)
    assert np.array_equal(flight.rates, filtered.flight.rates[:, ::2])
    assert "fitted at 50 Hz, every 2nd sample of the 100 Hz log" in flight.metadata["fit_rate"]
    assert flight.metadata["fit_rate_by"] == "data"
    (rate, ratios), *_ = chosen.steps
    assert rate == 100.0 and max(ratios.values()) > 2.0  # the full rate's damping inflated
    fitted = MaximumLikelihoodIdentifier().fit(flight).params_.values()
    for k in ("k3", "k7", "k11"):
        assert abs(fitted[k] / truth[k] - 1.0) < 0.10, (k, fitted[k], truth[k])
    full = MaximumLikelihoodIdentifier().fit(filtered.flight).params_.values()
    assert full["k3"] > 2.0 * truth["k3"]  # what the log's rate gives: why it is not kept


def test_a_log_that_states_its_gyro_filter_is_thinned_until_its_noise_is_white_enough(filtered):
    """20 Hz stated on a 100 Hz log: neighbouring samples of the filtered noise correlate by 0.58 at 100 Hz and 0.13
    at 50 Hz, so 50 Hz is taken and the data are not asked."""
    from identification.fit_rate import WHITE_ENOUGH, filtered_noise_correlation, stated_every

    assert filtered_noise_correlation(20.0, 0.01) == pytest.approx(0.578, abs=1e-3)
    assert filtered_noise_correlation(20.0, 0.02) < WHITE_ENOUGH < filtered_noise_correlation(20.0, 0.01)
    assert stated_every([filtered.flight], 100.0) == (2, 20.0)
    assert stated_every([filtered.flight], 400.0) == (8, 20.0)
    assert stated_every([filtered.flight], 50.0) == (1, None)  # white enough at the log's own rate
    assert stated_every([filtered.flight.with_metadata(gyro_filter_hz=None)], 100.0) == (1, None)
    (flight,), chosen = at_fit_rate([filtered.flight])
    assert chosen.every == 2 and chosen.corner == 20.0 and chosen.steps == ()
    assert "its gyro is stated low-passed at 20 Hz" in flight.metadata["fit_rate"]
    assert flight.metadata["fit_rate_by"] == "corner"
    fast = simulate_flight(10, seed=3, config=replace(BENCH_CELLS["independent"], gyro_filter_hz=45.0)).flight
    (same,), kept = at_fit_rate([fast])  # 45 Hz stated: white enough at 100 Hz, and the data not asked
    assert same is fast and kept == FitRate(1, 100.0)


def test_a_white_gyros_log_is_fitted_at_its_own_rate_untouched():
    flight = simulate_flight(120, seed=3, config=BENCH_CELLS["independent"]).flight
    (same,), chosen = at_fit_rate([flight])
    assert same is flight and chosen.every == 1 and len(chosen.steps) == 1
    assert max(chosen.steps[0][1].values()) < 1.15
    assert chosen.describe().startswith("fitted at the log's 100 Hz: the dampings fitted there and at half of it agree")


def test_a_stated_rate_is_the_logs_over_a_whole_number(filtered):
    (flight,), chosen = at_fit_rate([filtered.flight], 25.0)
    assert chosen == FitRate(4, 100.0) and flight.sample_rate == pytest.approx(25.0)
    assert "as asked" in flight.metadata["fit_rate"] and flight.metadata["fit_rate_by"] == "asked"
    (same,), _ = at_fit_rate([filtered.flight], "log")
    assert same is filtered.flight
    with pytest.raises(ValueError, match=r"the log's rate divided by a whole number \(100, 50, 33.3333 \.\.\. Hz "
                                         r"for this log\), got 33 Hz"):
        every_for(100.0, 33.0)
    assert every_for(100.0, 100.0 / 3) == 3 and [nth(k) for k in (1, 2, 3, 4, 12, 22)] == [
        "1st", "2nd", "3rd", "4th", "12th", "22nd"]


def test_no_log_is_thinned_below_the_least_rate_and_flights_of_two_rates_are_refused(filtered):
    slow = simulate_flight(60, seed=3, config=replace(BENCH_CELLS["independent"], sample_rate=25.0))
    assert choose_fit_rate([slow.flight]) == FitRate(1, 25.0)  # 12.5 Hz would be below MIN_RATE: nothing tried
    with pytest.raises(ValueError, match="expected flights of one sample rate"):
        choose_fit_rate([filtered.flight, slow.flight])


def test_thinning_keeps_every_column_and_says_so(filtered):
    flight = filtered.flight.with_metadata(import_warnings=["kept"])
    thin = thinned(flight, 4)
    assert thin.n == (flight.n + 3) // 4 and np.array_equal(thin.time, flight.time[::4])
    assert np.array_equal(thin.sticks, flight.sticks[:, ::4]) and np.array_equal(thin.attitude, flight.attitude[:, ::4])
    assert thin.metadata["fit_every"] == 4 and thin.metadata["import_warnings"] == ["kept"]


def test_the_fit_warnings_and_a_refresh_say_and_keep_the_fitted_rate(filtered):
    from identification.validation.fit_warnings import fit_warnings
    from identification.workflows.refresh import _at_model_rate

    (flight,), _ = at_fit_rate([filtered.flight], 50.0)
    assert sum("fitted at 50 Hz" in line for line in fit_warnings([flight, flight])) == 1  # once for a log
    again = _at_model_rate(filtered.flight, 50.0)  # a model fitted at 50 Hz reads its 100 Hz flights so
    assert again.sample_rate == pytest.approx(50.0) and "the model's 50 Hz" in again.metadata["fit_rate"]
    assert again.metadata["fit_rate_by"] == "model"
    assert _at_model_rate(filtered.flight, 100.0) is filtered.flight
    assert _at_model_rate(filtered.flight, 30.0) is filtered.flight  # not a whole fraction: as read


def test_a_fit_rate_the_log_cannot_take_is_refused_in_one_line_before_any_fit(tmp_path, capsys):
    from heli_cli.main import main

    csv = tmp_path / "f.csv"
    simulate_flight(20, seed=1).save(csv)
    for command in (["identify", str(csv), "--out", str(tmp_path / "m")], ["diagnose", str(csv), "--out",
                                                                             str(tmp_path / "d")]):
        assert main([*command, "--fit-rate", "33"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1].startswith(f"heli {command[0]}: error: --fit-rate: a fit rate is the log's rate divided by a "
                                  "whole number") and len(err) <= 2  # a progress line may precede it
    assert not (tmp_path / "m").exists() and not (tmp_path / "d").exists()
    with pytest.raises(SystemExit):
        main(["identify", str(csv), "--out", str(tmp_path / "m"), "--fit-rate", "fast"])
    assert "--fit-rate: expected 'auto', 'log' or a rate in Hz above 0, got 'fast'" in capsys.readouterr().err


def test_heli_fit_rate_sets_the_default_and_a_bad_one_is_refused(tmp_path, capsys, monkeypatch):
    """``$HELI_FIT_RATE`` is ``--fit-rate``'s default (the suite sets 'log'); misspelt, it is refused before any
    fit, as ``$HELI_CLOSED_LOOP`` is."""
    from heli_cli.identify import fit_rate_setting
    from heli_cli.main import main

    monkeypatch.delenv("HELI_FIT_RATE")
    assert fit_rate_setting(None) == "auto" and fit_rate_setting(50.0) == 50.0
    monkeypatch.setenv("HELI_FIT_RATE", "25")
    assert fit_rate_setting(None) == 25.0
    monkeypatch.setenv("HELI_FIT_RATE", "often")
    csv = tmp_path / "f.csv"
    simulate_flight(20, seed=1).save(csv)
    assert main(["identify", str(csv), "--out", str(tmp_path / "m")]) == 2
    assert ("heli identify: error: HELI_FIT_RATE: expected 'auto', 'log' or a rate in Hz above 0, got 'often'"
            in capsys.readouterr().err)
    assert not (tmp_path / "m").exists()


@pytest.mark.slow  # 15-20 s: a 300 s identify with its check
def test_heli_identify_fits_a_filtered_gyros_csv_at_the_rate_its_noise_is_white(tmp_path, capsys, monkeypatch):
    """``heli simulate-flight --gyro-filter 20`` (a flight controller's gyro, filtered at 400 Hz and logged at 100 Hz)
    then ``heli identify`` by default: the model is written at 50 Hz, its dampings near the truth, and the report and
    the terminal say why; ``--fit-rate log`` keeps 100 Hz and the damping it reads there is far off."""
    import json

    from heli_cli.main import main

    monkeypatch.delenv("HELI_FIT_RATE", raising=False)  # the suite's 'log' (conftest): the default is the subject
    csv = tmp_path / "ap.csv"
    assert main(["simulate-flight", "--cell", "independent", "--gyro-filter", "20", "--log-every", "4", "--seed", "7",
                 "--out", str(csv)]) == 0
    truth = json.loads((tmp_path / "ap.truth.json").read_text())["parameters"]
    capsys.readouterr()
    assert main(["identify", str(csv), "--out", str(tmp_path / "m"), "--no-plots", "--no-disturbances"]) == 0
    out = capsys.readouterr().out
    model = json.loads((tmp_path / "m" / "model.json").read_text())
    assert model["sample_rate_hz"] == pytest.approx(50.0)
    assert "warning: fitted at 50 Hz, every 2nd sample of the 100 Hz log" in out
    assert "fitted at 50 Hz" in (tmp_path / "m" / "report.md").read_text()
    for k in ("k3", "k7", "k11"):
        assert abs(model["parameters"][k] / truth[k] - 1.0) < 0.10, k
    assert main(["identify", str(csv), "--out", str(tmp_path / "log"), "--no-plots", "--no-disturbances",
                 "--fit-rate", "log"]) == 0
    at_log = json.loads((tmp_path / "log" / "model.json").read_text())
    assert at_log["sample_rate_hz"] == pytest.approx(100.0) and at_log["parameters"]["k7"] > 1.5 * truth["k7"]


def test_a_damping_inflated_without_a_timing_is_not_searched_for_one(filtered):
    """The choice's fit at a rate is gated by its half rate's dampings: an axis already inflated without a timing
    keeps its undelayed fit (on a filtered gyro the timing's searches at a run-away damping were the slow part);
    the others are searched as ``heli identify`` searches them."""
    from identification.fit_rate import DAMPINGS, _dampings, _exceeds
    from identification.likelihood.estimator import CLI_TIMING

    flight = filtered.flight.with_metadata(gyro_filter_hz=None)
    half = _dampings([flight], 2)
    plain = MaximumLikelihoodIdentifier().fit(flight)
    inflated = {a for a, f in plain.axes_.items() if _exceeds(f.params[DAMPINGS[a]], *half[a])}
    assert inflated  # the case of this test: the 20 Hz filter inflates the 100 Hz damping
    gated = MaximumLikelihoodIdentifier(**CLI_TIMING)
    gated.timing_gate = lambda axis, d: axis in inflated
    gated.fit(flight)
    for axis in inflated:
        assert gated.axes_[axis].delay_profile == () and gated.axes_[axis].params == plain.axes_[axis].params
    assert _dampings([flight], 1, half) == {a: (f.params[DAMPINGS[a]], f.std_errors[DAMPINGS[a]])
                                             for a, f in gated.axes_.items()}
