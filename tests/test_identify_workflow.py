"""The identify workflow (``identification.workflows.identify``) as its callers other than ``heli identify`` use it."""

from __future__ import annotations

import json

import pytest


@pytest.fixture(scope="module")
def flight():
    from identification.bench.synthetic import simulate_flight

    return simulate_flight(60, seed=3).flight


def test_without_comparing_structures_only_the_written_model_is_fitted(flight, tmp_path):
    """``compare_structures=False`` (what ``heli tune`` asks): the decoupled model alone is fitted, and
    model.json carries the same parameters and library as the default run, which fits the coupled one beside
    it; the report has no coupled column and says nothing of terms the coupled fit left out."""
    from identification.workflows.identify import identify_and_report

    stages = []
    alone = identify_and_report([flight], tmp_path / "alone", plots=False, compare_structures=False,
                                stage=stages.append)
    both = identify_and_report([flight], tmp_path / "both", plots=False)
    assert list(alone.identifiers) == ["decoupled"] and sorted(both.identifiers) == ["coupled", "decoupled"]
    assert any(s.startswith("fitting the decoupled model by maximum likelihood") for s in stages)
    docs = [json.loads((tmp_path / name / "model.json").read_text()) for name in ("alone", "both")]
    assert docs[0]["parameters"] == docs[1]["parameters"] and docs[0]["structure"] == "decoupled"
    manifests = [json.loads((tmp_path / name / "disturbances" / "manifest-v0001.json").read_text())
                 for name in ("alone", "both")]
    assert [t["sha256"] for t in manifests[0]["traces"]] == [t["sha256"] for t in manifests[1]["traces"]]
    report = (tmp_path / "alone" / "report.md").read_text()
    assert "| Parameter | Unit | decoupled |" in report and "| coupled |" not in report
    assert "Coupled model:" not in report


def test_a_model_fitted_before_is_written_as_it_is_not_fitted_again(flight, tmp_path, monkeypatch):
    """``fitted=`` (``heli refresh`` hands over its drift table's fit of the new flights): that identifier is the
    one written, and no other fit of the model is made (the stick-noise test, which fits its own two with the
    given fit's decisions, is handed the given identifier)."""
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier
    from identification.workflows import identify
    from identification.workflows.identify import identify_and_report

    before = MaximumLikelihoodIdentifier().fit([flight])
    tested = []

    def refuse(self, *args, **kwargs):
        raise AssertionError("fitted again")

    monkeypatch.setattr(MaximumLikelihoodIdentifier, "fit", refuse)
    monkeypatch.setattr(identify, "check_stick_noise", lambda ident: tested.append(ident))
    run = identify_and_report([flight], tmp_path / "given", plots=False, compare_structures=False,
                              fitted={"decoupled": before})
    assert run.identifiers["decoupled"] is before and tested == [before]
    written = json.loads((tmp_path / "given" / "model.json").read_text())["parameters"]
    assert written == pytest.approx(before.params_.values())
