"""The method comparison of Tables 3-5 (integral method, NLR, EKF) and ``heli compare-methods``.

Runs on a 40 s synthetic flight with the ``--quick`` settings (NLR capped at
QUICK_NLR_MAX_NFEV evaluations, few repeats). Speeds are printed by
``scripts/compare_methods.py``, never asserted here.
"""

from __future__ import annotations

import json
import math

import pytest

from heli_cli import main as cli
from identification.baselines import TABLE3_STARTS, TABLE5_LENGTHS
from identification.errors import IdentifiabilityError
from identification.io import read_flight
from identification.method_comparison import (
    QUICK_NLR_MAX_NFEV,
    SCHEMA,
    TABLE4_CASES,
    MethodComparison,
    compare_methods,
)
from identification.synthetic import load_truth, simulate_flight

QUICK = dict(nlr_max_nfev=QUICK_NLR_MAX_NFEV, repeats={"integral": 3, "ekf": 1}, progress=False, quick=True)

MAE_TOLERANCE = 1.25
"""The integral method's MAE may exceed NLR's by at most 25 %. NLR minimises the
output error itself, so on a windy flight it bends the damping (+9-47 % over those seeds)
to soak up the unmodelled wind and ends below even the true parameters' MAE;
the integral method stays near the truth and 1-24 % above NLR's MAE (seeds 1-5,
40-60 s; +8 % on this flight, +11 % on the 300 s one, +10 % in the paper's Table 3)."""


@pytest.fixture
def heli():
    """The ``heli`` command (compare-methods must be registered in it)."""
    assert "heli_cli.compare_methods" in cli.COMMAND_MODULES
    return cli.main


@pytest.fixture(scope="module")
def flight_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("compare") / "flight.csv"
    simulate_flight(40.0, seed=1).save(path)
    return path


@pytest.fixture(scope="module")
def comparison(flight_path):
    return compare_methods(read_flight(flight_path), truth=load_truth(flight_path)[0], **QUICK)


def test_every_method_and_case_is_run(comparison):
    c = comparison
    assert c.axis == "roll" and c.param_names == ("k3", "k2", "kd1")
    assert [r.settings["start"] for r in c.nlr] == [list(s) for s in TABLE3_STARTS]
    assert [r.label for r in c.ekf] == [label for label, _, _ in TABLE4_CASES]
    assert [r.settings["length_s"] for r in c.sample_lengths] == list(TABLE5_LENGTHS)
    for r in (c.integral, *c.nlr, *c.ekf, *c.sample_lengths):
        assert r.cpu_time > 0 and r.wall_time > 0, r.label
        assert math.isfinite(r.mae) and r.p90 >= r.mae > 0, r.label
        assert set(r.params) == set(c.param_names)
    assert c.integral.repeats == 3 and all(r.repeats == 1 for r in c.nlr + c.ekf)
    assert all(r.settings["max_nfev"] == QUICK_NLR_MAX_NFEV for r in c.nlr)


def test_integral_is_about_as_accurate_as_nlr_and_closer_to_the_truth(comparison):
    c = comparison
    nlr = c.nlr[0]  # eq. (73)'s start, the paper's 710x row
    assert nlr.converged, "NLR from (5, 5, 5) converges within the quick evaluation cap"
    assert c.integral.mae <= MAE_TOLERANCE * nlr.mae
    integral_err, nlr_err = c.param_errors(c.integral), c.param_errors(nlr)
    for name in ("k3", "k2"):
        assert abs(integral_err[name]) < abs(nlr_err[name]), name
    assert abs(integral_err["k2"]) < 5.0  # gain within 5 % (issue #2 target)


def test_speed_ratios_are_taken_from_this_run(comparison):
    ratios = comparison.speed_ratios()
    base = comparison.integral.cpu_time
    for r in comparison.nlr:
        assert ratios["nlr"][r.label] == pytest.approx(r.cpu_time / base)
    assert set(ratios["ekf"]) == {label for label, _, _ in TABLE4_CASES}
    target = comparison.target()
    assert target["nlr_label"] == "NLR [5, 5, 5]"
    assert target["met"] == (target["faster"] and target["as_accurate"])


def test_markdown_holds_all_tables_and_rows(comparison):
    md = comparison.markdown()
    for heading in ("Table 3", "Table 4", "Table 5", "Speed ratios", "Quick run"):
        assert heading in md
    labels = ["Integral method", "True parameters (reference)"] + [r.label for r in comparison.nlr + comparison.ekf]
    for label in labels:
        assert f"| {label} |" in md, label
    for length in ("4.84", "11", "22"):
        assert f"| {length} |" in md
    assert "NLR / integral" in md and "EKF / integral" in md


def test_json_round_trips(comparison):
    d = comparison.to_dict()
    loaded = json.loads(json.dumps(d, allow_nan=False))
    assert loaded["schema"] == SCHEMA
    again = MethodComparison.from_dict(loaded)
    assert again.to_dict() == d
    assert again.markdown() == comparison.markdown()
    with pytest.raises(ValueError, match="schema"):
        MethodComparison.from_dict({**loaded, "schema": "something/else"})


def test_bad_arguments_are_named(comparison, flight_path):
    flight = read_flight(flight_path)
    with pytest.raises(IdentifiabilityError, match="window of 100 s does not fit the flight of 40.00 s"):
        compare_methods(flight, sample_lengths=(100.0,), progress=False)
    with pytest.raises(ValueError, match="positive integer"):
        compare_methods(flight, repeats={"integral": 0}, progress=False)
    with pytest.raises(ValueError, match="repeats keys"):
        compare_methods(flight, repeats={"kalman": 2}, progress=False)
    with pytest.raises(ValueError, match="axis must be one of"):
        compare_methods(flight, axis="heave", progress=False)


def test_cli_writes_json_and_markdown(heli, flight_path, tmp_path, capsys):
    out = tmp_path / "cmp"
    code = heli(["compare-methods", str(flight_path), "--out", str(out), "--quick", "--no-progress"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "--quick" in printed and "Table 3" in printed
    saved = json.loads((out / "comparison.json").read_text())
    assert saved["schema"] == SCHEMA and saved["settings"]["quick"] is True
    assert saved["truth"]["k2"] == pytest.approx(1.3475)
    md = (out / "comparison.md").read_text()
    assert md == MethodComparison.from_dict(saved).markdown()
    assert not list(out.glob("*.tmp"))  # atomic writes leave no temporaries


def test_cli_bad_file_exits_2(heli, tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,foo\n0,1\n0.01,2\n")
    assert heli(["compare-methods", str(bad), "--out", str(tmp_path / "o"), "--quick"]) == 2
    assert "error" in capsys.readouterr().err
    assert heli(["compare-methods", str(tmp_path / "missing.csv"), "--out", str(tmp_path / "o")]) == 2
    assert not (tmp_path / "o").exists()
