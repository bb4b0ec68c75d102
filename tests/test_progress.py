"""heli_cli.progress: one line per stage off a terminal, a transient status line on one, nothing with --quiet."""

from __future__ import annotations

import io

import pytest

from heli_cli.progress import Progress


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_off_a_terminal_each_stage_is_one_line():
    stream = io.StringIO()
    with Progress("identify", stream=stream) as progress:
        progress.stage("fitting roll/pitch/yaw")
        progress.stage("drawing the figures")
    assert stream.getvalue() == "identify: fitting roll/pitch/yaw ...\nidentify: drawing the figures ...\n"
    assert progress.bars


def test_quiet_shows_nothing_and_turns_the_library_bars_off():
    stream = _Terminal()
    with Progress("sweep", quiet=True, stream=stream) as progress:
        progress.stage("replaying")
    assert stream.getvalue() == ""
    assert not progress.bars


def test_on_a_terminal_a_stage_is_a_status_line_erased_when_done():
    stream = _Terminal()
    progress = Progress("train", stream=stream)
    progress.stage("loading stable-baselines3")
    shown = stream.getvalue()
    assert "train: loading stable-baselines3 ..." in shown and "\n" not in shown
    progress.done()
    assert stream.getvalue().endswith("\r")  # the line is cleared, the cursor back at its start
    assert progress.terminal


@pytest.mark.slow
def test_sweep_and_evaluate_announce_their_stages_off_a_terminal(tmp_path, capsys):
    """A log shows what a long command is doing (issue 18: 'sweep --flights in a log shows nothing for 10 s')."""
    from heli_cli.main import main

    assert main(["sweep", "--kp", "1:4:2", "--kd", "0:1:2", "--duration", "5", "--out", str(tmp_path / "sw")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert "sweep: sweeping 2 x 2 gain pairs on roll in the model's gusts ..." in err
    assert "sweep: drawing the heatmap and the histograms ..." in err
    assert main(["sweep", "--kp", "1:4:2", "--kd", "0:1:2", "--duration", "5", "--out", str(tmp_path / "q"),
                 "-q"]) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.slow  # over 5 s: make test-slow
def test_sweep_and_evaluate_skip_their_figures_with_no_plots(tmp_path):
    from heli_cli.main import main

    assert main(["sweep", "--kp", "1:4:2", "--kd", "0:1:2", "--duration", "5", "--out", str(tmp_path / "sw"),
                 "--no-plots", "-q"]) == 0
    assert sorted(p.name for p in (tmp_path / "sw").iterdir()) == ["sweep.csv", "sweep.html", "sweep.json",
                                                                   "sweep.md"]
    assert main(["design", "--out", str(tmp_path / "pd"), "--no-plots", "-q"]) == 0
    assert main(["evaluate", str(tmp_path / "pd" / "pd.json"), "--episode-seconds", "2", "--out",
                 str(tmp_path / "ev"), "--no-plots", "-q"]) == 0
    assert sorted(p.name for p in (tmp_path / "ev").iterdir()) == ["evaluation.html", "evaluation.json",
                                                                   "evaluation.md"]


def test_the_likelihood_diagnosis_names_each_step_as_it_starts():
    """Issue 31: 'heli diagnose' showed one static line for 18-24 s; its diagnoser now says each step."""
    from identification.diagnosis.likelihood_diagnoser import LikelihoodDiagnoser
    from identification.bench.synthetic import simulate_flight

    steps = []
    LikelihoodDiagnoser(axes=("roll",), max_rounds=1, progress=steps.append).fit(simulate_flight(62, seed=3).flight)
    assert steps[0] == "deciding how the sticks move between samples, every candidate term in"
    assert steps[1] == "fitting the starting structure on roll"
    assert steps[2] == "round 1, roll: refitting the base"
    assert "round 1, roll: trying servo_delay" in steps and "round 1, roll: trying cross_coupling" in steps
    assert steps[-1] == "fitting the final structure"
    quiet = LikelihoodDiagnoser(axes=("roll",), max_rounds=1)
    assert quiet.progress is None  # the default shows nothing
