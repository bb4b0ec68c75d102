"""``heli refresh`` keeps the ``--validate`` results (:mod:`identification.workflows.refresh_validation`).

A refresh rewrites ``model.json`` and ``report.md``; the model's scores on flights it was not fitted on must not
disappear with them: the refreshed model is validated again on each flight whose file is still found (by its
SHA-256), and an entry whose file is gone is carried over, marked with the model it was computed on.
"""

from __future__ import annotations

import json
import math
import shutil

import pytest

from heli_cli.main import main
from heli_core.files import sha256_of
from identification.bench.synthetic import simulate_flight
from identification.reports.validation import flight_validation_markdown
from identification.validation.other_flights import FlightValidation
from identification.workflows.refresh_validation import kept_validation


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    """Short synthetic flights (the function reads them, no fit): a, b, c, d at 100 Hz; slow = a at 50 Hz."""
    folder = tmp_path_factory.mktemp("rv_flights")
    for i, name in enumerate(("a", "b", "c", "d")):
        simulate_flight(duration=8.0, seed=40 + i).save(folder / f"{name}.csv")
    lines = (folder / "a.csv").read_text().splitlines()
    (folder / "slow.csv").write_text("\n".join(lines[:1] + lines[1::2]) + "\n")
    return folder


def _entry(file, name=None, **extra) -> dict:
    """A ``validation_flights`` entry of ``model.json`` for the file ``file`` (recorded as ``name``)."""
    return {"file": name or file.name, "sha256": sha256_of(file), "duration_s": 8.0, "model": "decoupled",
            "fit_pct": {"roll": 41.0, "pitch": None, "yaw": -27.3}, "r2": {"roll": 0.65, "pitch": None, "yaw": -0.6},
            "ahead_r2": None, "frequency_response_cost": {"roll": 10.6, "pitch": None, "yaw": 11.9},
            "diverged": None, **extra}


def test_found_flights_are_validated_again_and_lost_ones_carried_over_marked(flights, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.copy(flights / "b.csv", elsewhere / "renamed_b.csv")
    gone = tmp_path / "gone.csv"
    shutil.copy(flights / "d.csv", gone)
    entries = [
        _entry(flights / "a.csv", path=str(flights / "a.csv")),  # at its recorded path
        _entry(flights / "b.csv"),  # given as a --previous-flights file under another name
        _entry(gone, path=str(gone)),  # removed below: carried over
        _entry(flights / "c.csv", name="c.csv"),  # found by name in a search folder; but now fitted: dropped
        _entry(flights / "slow.csv", path=str(flights / "slow.csv")),  # found, at another rate: carried over
        _entry(gone, name="older.csv", computed_on={"model_sha256": "0" * 64, "reason": "carried before"}),
    ]
    gone.unlink()
    kept = kept_validation(entries, "f" * 64, [flights], candidates=[elsewhere / "renamed_b.csv"],
                           fitted_sha256=[sha256_of(flights / "c.csv")], sample_rate=100.0)
    assert kept.names == ["a.csv", "b.csv"]
    assert kept.paths == [str((flights / "a.csv").resolve()), str((elsewhere / "renamed_b.csv").resolve())]
    assert [f.sample_rate for f in kept.flights] == pytest.approx([100.0, 100.0])
    carried = {c.name: c for c in kept.carried}
    assert set(carried) == {"gone.csv", "slow.csv", "older.csv"}
    assert carried["gone.csv"].computed_on["model_sha256"] == "f" * 64
    assert "not found" in carried["gone.csv"].computed_on["reason"]
    assert "sampled at 50 Hz" in carried["slow.csv"].computed_on["reason"]
    assert carried["older.csv"].computed_on == {"model_sha256": "0" * 64, "reason": "carried before"}  # its own
    assert math.isnan(carried["gone.csv"].fit_pct["pitch"]) and carried["gone.csv"].validation is None
    assert carried["gone.csv"].to_dict()["computed_on"]["model_sha256"] == "f" * 64
    assert any("c.csv is now one of the fitted flights" in n for n in kept.notes)
    assert sum("carried over" in n for n in kept.notes) == 3


def test_a_carried_entry_is_marked_in_the_report_and_draws_no_figure(flights):
    entry = _entry(flights / "a.csv")
    carried = FlightValidation.from_dict(entry, {"model_sha256": "ab" * 32, "reason": "its file was not found"})
    fresh = FlightValidation.from_dict({**entry, "file": "b.csv"})
    lines = "\n".join(flight_validation_markdown([fresh, carried]))
    assert "| a.csv † | roll | 41.0 |" in lines and "| b.csv | roll | 41.0 |" in lines
    assert "- a.csv †: computed on an earlier model (model.json SHA-256 `abababababab…`), not on this one: its " \
           "file was not found" in lines
    assert "validation_2.png" not in lines  # no simulation kept: no figure promised


def test_model_without_validation_flights_keeps_none(flights):
    assert kept_validation((), "f" * 64, [flights]).carried == []


@pytest.mark.slow
def test_refresh_keeps_the_validation_table(tmp_path, capsys):
    """identify --validate, then two refreshes: the first finds the validation flight and scores the refreshed
    model on it; after the file is moved away, the second carries the table over, marked (about 20 s)."""
    for seed in (1, 2, 3, 4):
        assert main(["simulate-flight", "--duration", "60", "--seed", str(seed), "--out", str(tmp_path / f"f{seed}.csv"),
                     "-q"]) == 0
    model = tmp_path / "DIR"
    assert main(["identify", str(tmp_path / "f1.csv"), "--method", "integral", "--no-plots", "-q", "--validate",
                 str(tmp_path / "f2.csv"), "--out", str(model)]) == 0
    first = json.loads((model / "model.json").read_text())["fit_statistics"]["validation_flights"]
    assert [e["file"] for e in first] == ["f2.csv"] and first[0]["path"] == str((tmp_path / "f2.csv").resolve())

    assert main(["refresh", str(model), str(tmp_path / "f3.csv"), "--bootstrap", "20", "--no-plots", "-q"]) == 0
    again = json.loads((model / "model.json").read_text())["fit_statistics"]["validation_flights"]
    assert [e["file"] for e in again] == ["f2.csv"] and "computed_on" not in again[0]
    assert again[0]["fit_pct"] != first[0]["fit_pct"]  # the refreshed model's own scores
    report = (model / "report.md").read_text()
    assert "## Validation on flights not used for the fit" in report and "| f2.csv | roll |" in report

    before = sha256_of(model / "model.json")
    (tmp_path / "f2.csv").rename(tmp_path / "f2.moved")
    capsys.readouterr()
    assert main(["refresh", str(model), str(tmp_path / "f4.csv"), "--bootstrap", "20", "--no-plots", "-q"]) == 0
    assert "note: validation flight f2.csv: its earlier scores are carried over" in capsys.readouterr().out
    kept = json.loads((model / "model.json").read_text())["fit_statistics"]["validation_flights"]
    assert kept[0]["computed_on"]["model_sha256"] == before and kept[0]["fit_pct"] == again[0]["fit_pct"]
    report = (model / "report.md").read_text()
    assert "| f2.csv † | roll |" in report and f"computed on an earlier model (model.json SHA-256 `{before[:12]}" in report
