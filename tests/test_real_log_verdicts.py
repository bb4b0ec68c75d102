"""The verdict on models of real logs (issue #31 points 2-3): each fixture through ``heli import`` and
``heli identify`` (or ``heli diagnose``) ends in a model whose verdict names what is wrong, or in one line
that says why not; and the advice that line gives, followed, changes the outcome.

The logs sit outside the repository (``../shared/fixtures/logs``, or ``$HELI_FIXTURES``); the tests skip
when they or their parser are absent, as :mod:`tests.test_import_logs` does. Each identification takes
15-40 s on two cores: the tests are marked slow.
"""

from __future__ import annotations

import json
import re
import shlex

import pytest

from heli_cli.main import main
from test_import_logs import _fixture

pytestmark = pytest.mark.slow


def _import(filename: str, parser: str, out, capsys, *options) -> str:
    """``heli import`` of a fixture log into ``out``: the CSV's path (what the import printed is dropped)."""
    path = _fixture(filename, parser)
    csv = str(out / (path.stem + ".csv"))
    assert main(["import", str(path), "--out", csv, "-q", *options]) == 0
    capsys.readouterr()
    return csv


def _verdict(model_dir) -> dict:
    return json.loads((model_dir / "model.json").read_text())["verdict"]


def test_betaflight_quad_model_is_unusable_and_says_why(tmp_path, capsys):
    """A rate-controlled quad whose sticks explain 3-4 % of its rates: by default (the timing searched) the fit
    diverges and no model is written, the line saying why, or (the fit is ill-posed, its dampings at the
    search's bound, and the last bits of the machine's arithmetic decide: diverging on a Zen 5, not on a Zen 3)
    a model judged unusable is written; at the logged timing the model is written and judged unusable, its
    dampings at the search's bound and its gains' signs against the integral method's."""
    csv = _import("betaflight_quad_btfl_035.bbl", "orangebox", tmp_path, capsys)
    code = main(["identify", csv, "--out", str(tmp_path / "default"), "--no-plots", "-q"])
    printed = capsys.readouterr()
    if code == 2:
        assert "SimulationDivergedError" in printed.err and "too weakly excited by its stick" in printed.err
        assert not (tmp_path / "default" / "model.json").exists()
    else:
        assert code == 0 and printed.out.startswith("model verdict: unusable:")
        assert _verdict(tmp_path / "default")["level"] == "unusable"
    model = tmp_path / "plain"
    assert main(["identify", csv, "--out", str(model), "--no-plots", "-q", "--delay", "none"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("model verdict: unusable:")  # first, before the parameters
    verdict = _verdict(model)
    assert verdict["level"] == "unusable"
    reasons = " | ".join(verdict["reasons"])
    assert "damping k3 = 200 1/s is at the upper bound" in reasons
    assert "damping k7 = 200 1/s is at the upper bound" in reasons
    assert re.search(r"control gain k2 = -\d+ rad/s² against \+\d+", reasons)
    assert (model / "report.md").read_text().split("\n")[2].startswith("**Model verdict: unusable**")
    # design refuses it in one line, naming the reasons and the override
    assert main(["design", "--model", str(model), "--out", str(tmp_path / "pd"), "--no-plots", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "k3 = 200" in err[0] and "--accept-unusable-model" in err[0]


def _identify_error(csv, out, capsys, *options) -> str:
    code = main(["identify", csv, "--out", str(out), "--no-plots", "-q", *options])
    captured = capsys.readouterr()
    return "" if code == 0 else captured.err.strip()


def test_ardupilot_quad_divergence_names_its_cause_not_absent_terms(tmp_path, capsys):
    csv = _import("ardupilot_copter_log171.bin", "pymavlink", tmp_path, capsys)
    err = _identify_error(csv, tmp_path / "model", capsys)
    assert err.count("\n") == 0 and "SimulationDivergedError" in err
    assert "added terms" not in err  # none were added
    assert re.search(r"decays? faster than the simulation's fixed 0\.02 s step", err)  # one damping or two
    assert not (tmp_path / "model" / "model.json").exists()
    # its inputs are the rate controller's outputs, whose loop the log does not state: named beside the refusal
    assert "Note: the inputs are a flight controller's commands (heli import --inputs controller)" in err


def test_ardupilot_quad_diagnosis_says_what_identify_says(tmp_path, capsys):
    """identify refuses the flight as diverging; the diagnosis' model carries the same finding as its verdict."""
    csv = _import("ardupilot_copter_log171.bin", "pymavlink", tmp_path, capsys)
    out = tmp_path / "diag"
    assert main(["diagnose", csv, "--out", str(out), "--no-plots", "-q"]) == 0
    printed = capsys.readouterr().out
    if not (out / "model.json").exists():  # no effect found: no model written, nothing to judge
        return
    assert printed.startswith("model verdict: unusable:")
    verdict = _verdict(out)
    assert verdict["level"] == "unusable"
    assert any(r.startswith("diverges when simulated from the flight's sticks (the roll rate leaves")
               for r in verdict["reasons"])
    assert json.loads((out / "diagnosis.json").read_text())["model_verdict"] == verdict


ADVICE = re.compile(r"Identify with it: (heli identify .*)$|\(heli import --inputs\)")


def test_following_the_advice_for_the_ardupilot_quad_changes_the_outcome(tmp_path, capsys):
    """Every piece of advice the refusal prints is followed; each must end somewhere else than the refusal
    it came from (a model, or another reason), never in the same message again."""
    csv = _import("ardupilot_copter_log171.bin", "pymavlink", tmp_path, capsys)
    first = _identify_error(csv, tmp_path / "model", capsys)
    if not first:
        return  # a model: nothing was advised
    advice = ADVICE.search(first)
    if advice is None:
        return  # nothing advised, nothing to loop
    cause = first.split(": ", 2)[-1].split(";")[0]
    if advice.group(1):  # the command to run next, as printed
        argv = shlex.split(advice.group(1))[1:]
        argv[argv.index("--out") + 1] = str(tmp_path / "model2")
        code = main(argv)
        assert code == 0 or cause not in capsys.readouterr().err, "the advised command ends in the same refusal"
        return
    outcomes = []
    for inputs in ("sticks",):  # the other input source an ArduCopter log carries (controller is the default)
        (tmp_path / inputs).mkdir()
        other = _import("ardupilot_copter_log171.bin", "pymavlink", tmp_path / inputs, capsys, "--inputs", inputs)
        outcomes.append(_identify_error(other, tmp_path / f"model_{inputs}", capsys))
    same = [o for o in outcomes if "SimulationDivergedError" in o and "(heli import --inputs)" in o]
    assert len(same) < len(outcomes), f"--inputs advised, but each input source ends in the same refusal: {outcomes}"
