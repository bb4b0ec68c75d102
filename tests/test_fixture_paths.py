"""The README's path from a log to a controller, followed on every airborne fixture log (issue #31's first target).

For ``ardupilot_copter_log171.bin``, ``betaflight_quad_btfl_035.bbl`` and ``trex550_hovertest.csv`` the
README's own commands (read from its Quick start, run as written in a fresh folder: relative paths) go
import → identify → diagnose → design → evaluate through :func:`heli_cli.main.main`. Each step ends in what
the next needs, or in exit status 2 and ONE line saying why and what to try; where that line prints a command
to run next ("Identify with it: heli identify ..."), the test runs it as a user would and goes on. Every
``model.json`` written on the way is checked: a damping at the estimator's search bound, or a control gain whose
sign the integral method contradicts on the same flight, only ever appears with a verdict that says so (the
integral method is the reference because the sign convention is the log's: the paper's helicopter has a
negative pitch gain).

What :mod:`tests.test_real_log_verdicts` asserts about the individual lines (the Betaflight verdict's
reasons, the ArduPilot divergence's cause) is not repeated here: these tests assert the chain.

The logs sit outside the repository (``../shared/fixtures/logs`` or ``$HELI_FIXTURES``); the tests skip,
saying why, when they or their parser are absent. Each chain takes 1-3 minutes on two shared cores: slow
(the README check alone is not).
"""

from __future__ import annotations

import json
import re
import shlex
import shutil
from pathlib import Path

import pytest
from test_import_logs import _fixture

from heli_cli.main import main
from identification.validation.model_verdict import BOUND_TOLERANCE, DAMPING, GAIN, ML_DAMPING_BOUNDS

README = Path(__file__).resolve().parents[1] / "README.md"
STEPS = ("import", "identify", "diagnose", "design", "evaluate")
QUIET = ["-q"]
"""Appended to every step: no progress lines (the figures are the HTML tests' business, --no-plots below)."""
NEXT = re.compile(r"Identify with it: (heli identify .*)$")
"""A refusal's command to run next."""
ADVICE = re.compile(r"Identify with it: heli |What to try|--[a-z][\w-]+|heli [a-z-]+|leave out|identify from")
"""Words of a refusal that say what to try: a command, an option, or a flight to fly."""


def readme_path() -> dict[str, list[str]]:
    """The README's commands from a log to a controller: {step: argv after ``heli``}, comments dropped."""
    text = README.read_text()
    block = re.search(r"```bash\n(heli import .*?)```", text, re.S)
    assert block, "README: no bash block starting with 'heli import' (the path from a log to a controller)"
    steps = {}
    for line in block.group(1).splitlines():
        argv = shlex.split(line.split("#", 1)[0])
        if argv and argv[0] == "heli":
            steps[argv[1]] = argv[1:]
    assert tuple(steps) == STEPS, f"README's path is {tuple(steps)}, expected {STEPS}"
    return steps


def test_readme_path_reads_as_the_chain_below():
    """The fast half: the README's commands are those the chains run (a renamed option breaks this first)."""
    steps = readme_path()
    assert steps["import"][1:] == ["mylog.ulg", "--out", "flight.csv"]
    assert steps["identify"][1] == "flight.csv"
    assert steps["diagnose"][steps["diagnose"].index("--model") + 1] == "model/model.json"
    assert steps["evaluate"][1] == "pd/pd.json"


class Chain:
    """The README's commands run in ``folder`` (the working directory), one step at a time."""

    def __init__(self, capsys):
        self.capsys = capsys
        self.steps = readme_path()
        self.ran: list[tuple[list[str], int, str]] = []

    def run(self, argv: list[str]) -> tuple[int, str]:
        """Run ``heli argv`` quietly: (exit status, its error line or ''). A failure is ONE line with advice."""
        opts = QUIET + (["--no-plots"] if argv[0] != "import" else [])
        code = main([*argv, *[o for o in opts if o not in argv]])
        err = self.capsys.readouterr().err.strip()
        self.ran.append((argv, code, err))
        assert code in (0, 2), f"heli {shlex.join(argv)} exited {code}: {err}"
        if code == 0:
            return 0, ""
        lines = err.splitlines()
        assert len(lines) == 1, f"heli {shlex.join(argv)} refused in {len(lines)} lines:\n{err}"
        assert lines[0].startswith(f"heli {argv[0]}: error: "), lines[0]
        assert ADVICE.search(lines[0].split(": error: ", 1)[1]), f"heli {shlex.join(argv)}: the refusal says why but not what to try: {err}"
        return 2, lines[0]

    def step(self, name: str, **replace) -> tuple[int, str]:
        """The README's ``name`` step with ``replace`` {old word: new word}; a printed next command is followed."""
        argv = [replace.get(w, w) for w in self.steps[name]]
        code, err = self.run(argv)
        follow = NEXT.search(err)
        if follow:
            again = shlex.split(follow.group(1))[1:]
            code2, err2 = self.run(again)
            cause = err.split(": error: ", 1)[1].split(";")[0]
            assert code2 == 0 or cause not in err2, f"the advised command ends in the same refusal: {err2}"
            return code2, err2
        return code, err

    def trail(self) -> str:
        return "\n".join(f"heli {shlex.join(a)} -> {c} {e}" for a, c, e in self.ran)


def check_verdict_speaks(model_json: Path, flight_csv: Path) -> dict:
    """A model.json with a damping at the search bound, or a control gain whose sign the integral method on the
    same flight contradicts (both clear of zero by two standard errors, on an axis whose sticks the model did not
    shift), carries a verdict that names it (issue #31: never confident nonsense); the verdict."""
    from identification.integral.method import IntegralIdentifier
    from identification.io import read_flight

    doc = json.loads(model_json.read_text())
    verdict, params, fit = doc["verdict"], doc["parameters"], doc["fit_statistics"]
    said = " | ".join([*verdict.get("reasons", ()), *verdict.get("doubts", ())])
    lo, hi = ML_DAMPING_BOUNDS
    for name in DAMPING.values():
        if min(abs(params[name] - hi), abs(params[name] - lo)) <= BOUND_TOLERANCE * (hi - lo):
            assert verdict["level"] == "unusable" and f"damping {name} = " in said, (model_json, name, verdict)
    reference = IntegralIdentifier().fit(read_flight(flight_csv)).summary()
    shifts = {**(fit.get("input_shifts_s") or {}), **((doc.get("diagnosis") or {}).get("input_alignment_s") or {})}
    for axis, name in GAIN.items():
        stats = fit["axes"].get(axis, {})
        if shifts.get(axis) or stats.get("delay_s") or axis not in reference:
            continue  # another alignment of stick and response (identify's or diagnose's) can flip the sign
        ref, ref_se = reference[axis]["params"][name], reference[axis]["std_errors"].get(name) or 0.0
        se = (stats.get("std_errors") or {}).get(name) or 0.0
        if abs(params[name]) > 2 * se and abs(ref) > 2 * ref_se and params[name] * ref < 0:
            assert verdict["level"] == "unusable" and f"control gain {name} = " in said, (model_json, name, verdict)
    return verdict


@pytest.fixture
def chain(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    return Chain(capsys)


@pytest.mark.slow
def test_trex_hover_reaches_an_evaluated_controller(chain, tmp_path):
    """The CSV skips the import (README); identify finds the sticks logged late by its default timing test and
    gives a model judged doubtful (yaw barely excited); diagnose, design and evaluate (the held-out trace shorter than the default episode)
    each end in their files."""
    shutil.copy(_fixture("trex550_hovertest.csv", "numpy"), tmp_path / "flight.csv")
    code, err = chain.step("identify")
    assert code == 0, chain.trail()
    shifts = json.loads((tmp_path / "model" / "model.json").read_text())["fit_statistics"]["input_shifts_s"]
    assert shifts["roll"] < -0.2 and shifts["pitch"] < -0.2, shifts
    # doubtful, not usable: yaw's pedal explains 2 % of its rate and its gain is within 2 standard errors of zero
    assert check_verdict_speaks(tmp_path / "model" / "model.json", tmp_path / "flight.csv")["level"] == "doubtful"
    assert chain.step("diagnose")[0] == 0, chain.trail()
    if (tmp_path / "diag" / "model.json").exists():
        check_verdict_speaks(tmp_path / "diag" / "model.json", tmp_path / "flight.csv")
    assert chain.step("design")[0] == 0, chain.trail()
    assert (tmp_path / "pd" / "pd.json").is_file()
    assert chain.step("evaluate")[0] == 0, chain.trail()
    evaluation = json.loads((tmp_path / "evaluation" / "evaluation.json").read_text())
    assert evaluation["summary"]["terminated_episodes"] == 0


@pytest.mark.slow
def test_betaflight_quad_stops_at_design_and_the_override_works(chain, tmp_path):
    """identify's default fit diverges (no model) or, where the machine's last bits decide the ill-posed fit the
    other way, writes a model judged unusable; at the logged timing it writes a model judged unusable;
    diagnose says the flight is too short to decide; design refuses in one line naming the override, and with the
    override design and evaluate end in their files."""
    log = _fixture("betaflight_quad_btfl_035.bbl", "orangebox")
    assert chain.step("import", **{"mylog.ulg": str(log)})[0] == 0, chain.trail()
    code, err = chain.step("identify")
    if code == 0:
        assert check_verdict_speaks(tmp_path / "model" / "model.json", tmp_path / "flight.csv")["level"] == "unusable"
    else:
        assert code == 2 and "SimulationDivergedError" in err, chain.trail()
    assert chain.run([*chain.steps["identify"], "--delay", "none"])[0] == 0, chain.trail()
    assert check_verdict_speaks(tmp_path / "model" / "model.json", tmp_path / "flight.csv")["level"] == "unusable"
    assert chain.step("diagnose")[0] == 0, chain.trail()
    if (tmp_path / "diag" / "model.json").exists():
        check_verdict_speaks(tmp_path / "diag" / "model.json", tmp_path / "flight.csv")
    code, err = chain.step("design")
    assert code == 2 and "--accept-unusable-model" in err, chain.trail()
    assert not (tmp_path / "pd").exists()
    # the override the line names, taken by one who knows: a controller and its evaluation, not another refusal
    assert chain.run([*chain.steps["design"], "--accept-unusable-model"])[0] == 0, chain.trail()
    assert chain.run([*chain.steps["evaluate"], "--accept-unusable-model"])[0] == 0, chain.trail()
    assert (tmp_path / "evaluation" / "evaluation.json").is_file()


@pytest.mark.slow
def test_ardupilot_quad_ends_in_a_refusal_that_says_what_to_try(chain, tmp_path):
    """identify refuses (no model); the README's diagnose of the missing model says to leave --model out;
    followed, it writes a model whose verdict refuses it to design, in one line."""
    log = _fixture("ardupilot_copter_log171.bin", "pymavlink")
    assert chain.step("import", **{"mylog.ulg": str(log)})[0] == 0, chain.trail()
    code, err = chain.step("identify")
    assert code == 2 and not (tmp_path / "model" / "model.json").exists(), chain.trail()
    code, err = chain.step("diagnose")
    assert code == 2 and "--model" in err, chain.trail()
    argv = chain.steps["diagnose"]
    i = argv.index("--model")
    if chain.run(argv[:i] + argv[i + 2:])[0] != 0 or not (tmp_path / "diag" / "model.json").exists():
        return  # the diagnosis found no effect: no model written, the chain ends at identify's refusal
    verdict = check_verdict_speaks(tmp_path / "diag" / "model.json", tmp_path / "flight.csv")
    code, err = chain.step("design", **{"model/": "diag/"})
    if verdict["level"] == "unusable":
        assert code == 2 and "--accept-unusable-model" in err, chain.trail()
    else:
        assert code == 0, chain.trail()
