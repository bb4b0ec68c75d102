"""Tests of identification.validation.other_flights and ``heli identify --validate``: the identified model simulated
on flights it was not fitted on, scored as MATLAB's ``compare`` does.

Flights are synthetic, 60 s with every stick swept at once and the paper's wind (Section 3.3): aircraft A
(the paper's, eqs. 68-70) flown twice with different seeds (wind, pilot, sensors), aircraft B with 0.6 times
the control gains and 2.2 times the dampings. A model of A fitted on A's first flight must explain A's second
as well as the true parameters do (the wind, which no sticks-only simulation explains, caps both near 55-60 %),
and B's far worse.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from heli_cli.main import main
from identification.bench.flight_config import PAPER_PARAMS, FlightConfig
from identification.bench.synthetic import simulate_flight
from identification.errors import FlightLogError
from identification.flight import Flight
from identification.likelihood.estimator import MaximumLikelihoodIdentifier
from identification.reports.validation import flight_validation_markdown
from identification.validation.forward_simulation import rate_fit_stats, validate_models
from identification.validation.other_flights import as_fitted, check_validation_flights, validate_on_flight

SWEPT = FlightConfig(sweep_mode="simultaneous")
OTHER_AIRCRAFT = PAPER_PARAMS.with_values(
    k2=0.6 * PAPER_PARAMS.k2, k3=2.2 * PAPER_PARAMS.k3, k6=0.6 * PAPER_PARAMS.k6, k7=2.2 * PAPER_PARAMS.k7,
    k10=0.6 * PAPER_PARAMS.k10, k11=2.2 * PAPER_PARAMS.k11)
"""Aircraft B: softer controls, twice the damping."""


@pytest.fixture(scope="module")
def flights():
    """Aircraft A's two flights and aircraft B's one, as simulated."""
    return {"A1": simulate_flight(60.0, seed=1, config=SWEPT), "A2": simulate_flight(60.0, seed=2, config=SWEPT),
            "B": simulate_flight(60.0, seed=2, config=SWEPT, truth=OTHER_AIRCRAFT)}


@pytest.fixture(scope="module")
def fitted(flights):
    """The decoupled maximum-likelihood model of A fitted on A1."""
    return MaximumLikelihoodIdentifier().fit(flights["A1"].flight)


@pytest.fixture(scope="module")
def csvs(flights, tmp_path_factory):
    """The flights as canonical CSV files (with their truth beside them)."""
    folder = tmp_path_factory.mktemp("validate")
    return {name: sim.save(folder / f"{name}.csv")["flight"] for name, sim in flights.items()}


def test_rate_fit_stats_is_matlabs_nrmse_fit_and_r2():
    rng = np.random.default_rng(0)
    y = rng.normal(size=(3, 500))
    assert all(v["fit_pct"] == pytest.approx(100.0) and v["r2"] == pytest.approx(1.0)
               for v in rate_fit_stats(y, y).values())
    mean = np.repeat(y.mean(axis=1, keepdims=True), 500, axis=1)
    assert all(v["fit_pct"] == pytest.approx(0.0, abs=1e-9) for v in rate_fit_stats(y, mean).values())
    sim = y + 0.3 * rng.normal(size=y.shape)
    stats = rate_fit_stats(y, sim)
    expected = 100 * (1 - np.linalg.norm(y - sim, axis=1) / np.linalg.norm(y - y.mean(axis=1, keepdims=True), axis=1))
    assert_allclose([stats[a]["fit_pct"] for a in stats], expected)
    assert_allclose([stats[a]["r2"] for a in stats], 1 - (1 - expected / 100) ** 2)
    flat = y.copy()
    flat[2] = 0.5
    assert math.isnan(rate_fit_stats(flat, sim)["yaw"]["fit_pct"])


def test_same_aircraft_fits_as_well_as_the_true_parameters(flights, fitted):
    a2 = flights["A2"].flight
    check = validate_on_flight(fitted, a2, "decoupled", "A2.csv")
    truth = validate_models(as_fitted(fitted, a2), {"truth": PAPER_PARAMS})
    truth_fit = rate_fit_stats(truth.measured_rates, truth.simulated["truth"])
    for axis in ("roll", "pitch", "yaw"):
        assert check.fit_pct[axis] >= truth_fit[axis]["fit_pct"] - 5.0, axis
        assert check.fit_pct[axis] >= 45.0, axis
        assert check.ahead_r2[axis] >= 0.8, axis  # the wind estimated from the past: most of the rate predicted
    assert check.diverged is None and check.validation is not None
    assert json.loads(json.dumps(check.to_dict()))["file"] == "A2.csv"


def test_another_aircraft_fits_far_worse(flights, fitted):
    same = validate_on_flight(fitted, flights["A2"].flight, "decoupled")
    other = validate_on_flight(fitted, flights["B"].flight, "decoupled")
    for axis in ("roll", "pitch", "yaw"):
        assert other.fit_pct[axis] <= same.fit_pct[axis] - 40.0, axis
        assert other.ahead_r2[axis] < same.ahead_r2[axis] - 0.5, axis
        assert other.cost[axis] > 3 * same.cost[axis], axis  # its dynamics are not the flight's


def test_a_diverging_simulation_is_a_result_not_an_error(flights, fitted):
    class Unstable:  # the fitted model with negative roll damping, nothing else changed
        axes_ = fitted.axes_
        params_ = fitted.params_.with_values(k3=-5.0)
        prefilter = False

    check = validate_on_flight(Unstable(), flights["A2"].flight, "decoupled", "A2.csv")
    assert check.validation is None and "diverges" in check.diverged and check.ahead_r2 is None
    assert all(math.isnan(v) for v in check.fit_pct.values())
    md = "\n".join(flight_validation_markdown([check]))
    assert "| A2.csv | roll | diverged | diverged | — |" in md and "- A2.csv: model 'decoupled' diverges" in md
    assert "validation_1.png" not in md
    assert check.to_dict()["fit_pct"]["roll"] is None


def test_check_refuses_the_fitted_flight_another_rate_and_a_short_flight(flights):
    a1, a2 = flights["A1"].flight, flights["A2"].flight
    with pytest.raises(FlightLogError, match="--validate A1.csv: the same flight as .* validation needs a flight"):
        check_validation_flights([a1], [a1], ["A1.csv"])
    half = Flight(a2.time[::2], a2.rates[:, ::2], a2.attitude[:, ::2], a2.sticks[:, ::2], a2.metadata)
    with pytest.raises(FlightLogError, match="sampled at 50 Hz, the fitted flights at 100 Hz; expected a flight"):
        check_validation_flights([a1], [half], ["half.csv"])
    with pytest.raises(FlightLogError, match="lasts 3.00 s; expected at least 5 s"):
        check_validation_flights([a1], [a2.segment(0.0, 3.0)], ["short.csv"])


# ------------------------------------------------------------------------------------------- heli identify
def _identify(csvs, tmp_path, *extra):
    return main(["identify", str(csvs["A1"]), "--out", str(tmp_path / "M"), "--method", "integral",
                 "--no-disturbances", *extra])


def test_identify_validate_prints_the_table_and_writes_it(csvs, tmp_path, capsys):
    assert _identify(csvs, tmp_path, "--no-plots", "--validate", str(csvs["A2"]), str(csvs["B"])) == 0
    out = capsys.readouterr().out
    assert "validation on 2 flight(s) not used for the fit (decoupled model" in out
    rows = {tuple(line.split()[:2]): line.split() for line in out.splitlines() if line.startswith("  A2.csv")
            or line.startswith("  B.csv")}
    for axis in ("roll", "pitch", "yaw"):
        assert float(rows[("A2.csv", axis)][2]) >= float(rows[("B.csv", axis)][2]) + 40.0, axis
        assert rows[("A2.csv", axis)][4] == "—"  # the integral method has no wind state to predict with
        assert float(rows[("A2.csv", axis)][5]) < float(rows[("B.csv", axis)][5]), axis  # J
    folder = tmp_path / "M"
    report = (folder / "report.md").read_text()
    assert "## Validation on flights not used for the fit" in report and "| B.csv | yaw |" in report
    assert "## Frequency response: flight and model, with coherence" in report
    assert ".png" not in report  # --no-plots: no figure linked
    stats = json.loads((folder / "model.json").read_text())["fit_statistics"]
    assert [c["file"] for c in stats["validation_flights"]] == ["A2.csv", "B.csv"]
    assert stats["frequency_response"]["coherence_min"] == 0.6


@pytest.mark.slow  # five figures drawn: 4-10 s on 2 shared cores
def test_identify_validate_draws_a_figure_per_flight_into_the_html_report(csvs, tmp_path):
    assert _identify(csvs, tmp_path, "--validate", str(csvs["A2"]), str(csvs["B"])) == 0
    folder = tmp_path / "M"
    report = (folder / "report.md").read_text()
    assert "![A2.csv: measured vs simulated body rates](validation_1.png)" in report
    for figure in ("validation_1.png", "validation_2.png", "frequency_response.png"):
        assert (folder / figure).read_bytes()[:4] == b"\x89PNG", figure
    html = (folder / "report.html").read_text()
    assert html.count("data:image/png;base64") >= 5  # rates, attitude, frequency response, two validations


@pytest.mark.parametrize("case, message", [
    ("missing", "nowhere.csv"),
    ("no yaw columns", "FlightLogError: .*missing required column\\(s\\) \\['r', 'ped'\\]"),
    ("the fitted flight", "FlightLogError: --validate A1.csv: the same flight as"),
])
def test_identify_refuses_a_bad_validation_flight_in_one_line_writing_nothing(csvs, tmp_path, capsys, case,
                                                                              message):
    import re

    if case == "missing":
        other = tmp_path / "nowhere.csv"
    elif case == "no yaw columns":
        lines = csvs["A2"].read_text().splitlines()
        header = lines[0].split(",")
        keep = [i for i, name in enumerate(header) if name not in ("r", "ped")]
        other = tmp_path / "noyaw.csv"
        other.write_text("\n".join(",".join(row.split(",")[i] for i in keep) for row in lines) + "\n")
    else:
        other = csvs["A1"]
    assert _identify(csvs, tmp_path, "--no-plots", "--validate", str(other)) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured.err
    assert re.search(message, captured.err), captured.err
    assert not (tmp_path / "M").exists()
