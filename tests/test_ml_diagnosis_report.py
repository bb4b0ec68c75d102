"""The diagnosis reports' texts: every setting they quote is filled in (no ``{...}`` left as written)."""

from __future__ import annotations

import re

import pytest

from identification.diagnosis.heldout_diagnoser import Diagnoser
from identification.diagnosis.likelihood_diagnoser import LikelihoodDiagnoser
from identification.reports import diagnosis as diagnose_report, likelihood_diagnosis as ml_diagnosis_report


@pytest.mark.parametrize("module, diagnoser", [(ml_diagnosis_report, LikelihoodDiagnoser(min_duration=37.5)),
                                               (diagnose_report, Diagnoser(min_duration=37.5))],
                         ids=["likelihood", "held-out"])
def test_the_criterion_quotes_its_settings(module, diagnoser):
    text = module.criterion_text(diagnoser)
    assert not re.search(r"\{[^}]*\}", text), text  # an f-prefix forgotten once printed "{d.min_duration:g}"
    assert "37.5 s" in text
