"""``heli design``: the PD controller a user flies with ``heli evaluate``, its report and figures."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from controllers.pd import PDController, design_gains, loop_analysis
from heli_cli.main import main
from heli_core.control_period import default_dt
from heli_env import load_env_model


@pytest.fixture(scope="module")
def designed(tmp_path_factory):
    out = tmp_path_factory.mktemp("design") / "pd"
    assert main(["design", "--phase-margin", "50", "--out", str(out)]) == 0
    return out


def test_writes_the_controller_report_and_figures(designed):
    for name in ("pd.json", "design.md", "step.png", "bode_roll.png", "bode_pitch.png", "bode_yaw.png", "servo.png",
                 "design.html"):
        assert (designed / name).stat().st_size > 0, name
    doc = json.loads((designed / "pd.json").read_text())
    assert [a["stable"] for a in doc["metadata"]["analysis"]] == [True, True, True]
    report = (designed / "design.md").read_text()
    assert "| roll |" in report and "## Servo activity" in report and "![servo activity](servo.png)" in report
    assert "| same request, no D filter | pitch |" in report


def test_controller_is_the_python_design_and_meets_the_margin(designed):
    """The CLI's default derivative filter is the design's rule ("auto"); the margin holds with the filter in."""
    params = load_env_model().params
    gains = design_gains(params, phase_margin=50.0, d_filter_hz="auto")
    pd = PDController.load(designed / "pd.json")
    np.testing.assert_allclose(pd.gains.kp, gains.kp, rtol=1e-12)
    np.testing.assert_allclose(pd.gains.kd, gains.kd, rtol=1e-12)
    np.testing.assert_allclose(pd.gains.d_filter_hz, gains.d_filter_hz, rtol=1e-12)
    assert pd.filtered and pd.dt == 0.01
    for i, axis in enumerate(("roll", "pitch", "yaw")):
        an = loop_analysis(params, axis, pd.gains.kp[i], pd.gains.kd[i], d_filter_hz=pd.gains.d_filter_hz[i])
        assert an.stable and an.phase_margin >= 50.0 - 1e-6
        assert pd.gains.d_filter_hz[i] == pytest.approx(20.0 * an.gain_crossover / (2 * np.pi), rel=1e-6)


def test_d_filter_option(tmp_path):
    """--d-filter-hz off writes the unfiltered design (schema version 1), a number a fixed cutoff."""
    params = load_env_model().params
    assert main(["design", "--d-filter-hz", "off", "--no-plots", "--out", str(tmp_path / "off")]) == 0
    off = PDController.load(tmp_path / "off" / "pd.json")
    assert not off.filtered and json.loads((tmp_path / "off" / "pd.json").read_text())["schema_version"] == 1
    np.testing.assert_allclose(off.gains.kp, design_gains(params).kp, rtol=1e-12)
    assert main(["design", "--d-filter-hz", "8", "--no-plots", "--out", str(tmp_path / "f8")]) == 0
    assert PDController.load(tmp_path / "f8" / "pd.json").gains.d_filter_hz == (8.0, 8.0, 8.0)


def test_designed_controller_flies_in_heli_evaluate(designed, tmp_path, capsys):
    out = tmp_path / "ev"
    assert main(["evaluate", str(designed / "pd.json"), "--out", str(out), "--episode-seconds", "5",
                 "--episodes-per-trace", "1"]) == 0
    assert "episodes ended early: 0" in capsys.readouterr().out


def test_infeasible_request_says_what_is_achievable(tmp_path, capsys):
    out = tmp_path / "pd"
    assert main(["design", "--bandwidth", "500", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "DesignError" in err and "the largest bandwidth is" in err
    assert not out.exists()  # nothing written on failure


@pytest.mark.parametrize("args", [["--phase-margin", "0"], ["--phase-margin", "200"], ["--bandwidth", "1,x"],
                                  ["--bandwidth", "1,2"], ["--bandwidth", "-3"], ["--dt", "0"], ["--dt", "nan"],
                                  ["--d-filter-hz", "0"], ["--d-filter-hz", "1,2"], ["--d-filter-hz", "fast"]])
def test_bad_arguments_exit_2_naming_what_was_expected(args, capsys):
    with pytest.raises(SystemExit) as e:
        main(["design", *args])
    assert e.value.code == 2
    assert "expected" in capsys.readouterr().err


def test_missing_model_directory(tmp_path, capsys):
    assert main(["design", "--model", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "EnvModelError" in capsys.readouterr().err


@pytest.fixture(scope="module")
def model_50hz_40s(tmp_path_factory):
    """A model identified (integral method) from a 40 s flight logged at 50 Hz: gust traces at 0.02 s, the
    held-out quarter 10 s long (one sample short of the servo activity's 10 s episode)."""
    folder = tmp_path_factory.mktemp("model50")
    full = folder / "f100.csv"
    assert main(["simulate-flight", "--duration", "40", "--seed", "4", "--out", str(full), "-q"]) == 0
    lines = full.read_text().splitlines()
    (folder / "f50.csv").write_text("\n".join(lines[:1] + lines[1::2]) + "\n")  # every other sample: 50 Hz
    assert main(["identify", str(folder / "f50.csv"), "--method", "integral", "--no-plots", "-q",
                 "--out", str(folder / "model")]) == 0
    return folder / "model"


def test_a_50hz_models_controller_is_designed_for_and_flown_at_its_period(model_50hz_40s, tmp_path, capsys):
    """The default control period is the gust traces' (0.02 s), said in a note; the servo activity is flown in the
    longest episode the short held-out trace holds, and heli evaluate flies the PD at the period it was designed
    for (a 0.01 s design could be flown on neither: 'dt=0.01 s must be a whole number of ... 0.02 s')."""
    out = tmp_path / "pd"
    capsys.readouterr()
    assert main(["design", "--model", str(model_50hz_40s), "--out", str(out), "-q"]) == 0
    printed = capsys.readouterr().out
    assert "note: control period 0.02 s, the sample period of the model's 50 Hz gust traces" in printed
    assert PDController.load(out / "pd.json").dt == 0.02
    report = (out / "design.md").read_text()
    assert re.search(r"episodes of 9\.\d+ s", report) and "![servo activity](servo.png)" in report  # not 10 s
    assert main(["evaluate", str(out / "pd.json"), "--model", str(model_50hz_40s), "--out", str(tmp_path / "ev"),
                 "--episodes-per-trace", "1", "--no-plots", "-q"]) == 0
    assert json.loads((tmp_path / "ev" / "evaluation.json").read_text())["settings"]["dt"] == 0.02


@pytest.mark.slow  # 7-8 s: make test-slow (the suite's 5 minutes on a 2-core AVX2 machine)
def test_servo_activity_that_cannot_be_flown_leaves_the_design_standing(model_50hz_40s, tmp_path, capsys):
    """--dt 0.01 on a 50 Hz model: the loop is designed and written; the servo activity, which the model's
    traces cannot fly at that period, is a note in the terminal and in design.md instead of the command's end."""
    out = tmp_path / "pd"
    capsys.readouterr()
    assert main(["design", "--model", str(model_50hz_40s), "--dt", "0.01", "--out", str(out), "-q"]) == 0
    printed = capsys.readouterr().out
    assert "note: the servo activity was not flown: dt=0.01 s must be a whole number" in printed
    report = (out / "design.md").read_text()
    assert "Not flown in the model's gusts" in report and "servo.png" not in report
    assert not (out / "servo.png").exists() and (out / "pd.json").is_file()


def test_a_pd_of_another_control_period_is_refused_naming_the_design_that_flies(model_50hz_40s, tmp_path, capsys):
    """heli evaluate of a 0.01 s PD on a 50 Hz log's model: one line that names the design to fly instead
    (before: 'dt=0.01 s must be a whole number ...', naming an option heli evaluate does not have)."""
    assert main(["design", "--model", str(model_50hz_40s), "--dt", "0.01", "--no-plots", "-q",
                 "--out", str(tmp_path / "pd")]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(tmp_path / "pd" / "pd.json"), "--model", str(model_50hz_40s), "--no-plots", "-q",
                 "--out", str(tmp_path / "ev")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "designed for a control period of 0.01 s" in err
    assert f"heli design --model {model_50hz_40s}, which picks 0.02 s" in err
    assert not (tmp_path / "ev").exists()


@pytest.mark.parametrize("rate, dt", [(100.0, 0.01), (200.0, 0.01), (1000.0, 0.01), (50.0, 0.02),
                                      (50.000000001, 0.02), (25.0, 0.04), (250.0, 0.012), (120.0, 2 / 120.0)])
def test_the_default_control_period_is_the_shortest_whole_number_of_samples_from_10_ms(rate, dt):
    assert default_dt(rate) == pytest.approx(dt, rel=1e-7, abs=0.0)  # rounded to the ns
    assert abs(default_dt(rate) * rate - round(default_dt(rate) * rate)) < 1e-6


def test_a_50hz_models_env_sweep_and_training_step_at_its_period_by_default(model_50hz_40s, tmp_path, capsys):
    """Unasked, every stage flies a 50 Hz log's model at 0.02 s (before: gym.make, heli sweep and heli train
    refused it with 'dt=0.01 s must be a whole number ...', and heli train had no option to mend it)."""
    import gymnasium as gym

    env = gym.make("HeliAttitude-v0", model=str(model_50hz_40s), episode_seconds=2.0)
    env.reset(seed=0)
    assert env.unwrapped.spec_.dt == 0.02 and np.isfinite(env.step(np.zeros(3, np.float32))[1])
    venv = gym.make_vec("HeliAttitude-v0", num_envs=2, vectorization_mode="vector_entry_point",
                        model=str(model_50hz_40s), episode_seconds=2.0)
    assert venv.unwrapped.spec_.dt == 0.02
    with pytest.raises(ValueError, match=r"got 0\.5 periods \(left unset, dt is 0\.02 s\)"):
        gym.make("HeliAttitude-v0", model=str(model_50hz_40s), dt=0.01)
    capsys.readouterr()
    assert main(["sweep", "--model", str(model_50hz_40s), "--kp", "2", "--kd", "0.2", "--no-extend", "--no-plots",
                 "--duration", "5", "--out", str(tmp_path / "sweep")]) == 0
    assert "note: control period 0.02 s, the sample period of the model's 50 Hz" in capsys.readouterr().out
    assert json.loads((tmp_path / "sweep" / "sweep.json").read_text())["settings"]["dt"] == 0.02
    assert main(["train", "--model", str(model_50hz_40s), "--algo", "ppo", "--timesteps", "64", "--n-envs", "2",
                 "--episode-seconds", "2", "--eval-freq", "0", "--no-compare", "--algo-kwargs", '{"n_steps": 32, "batch_size": 32}',
                 "-q", "--out", str(tmp_path / "agent")]) == 0
    assert json.loads((tmp_path / "agent_training" / "training.json").read_text())["dt"] == 0.02


def test_a_d_filter_above_nyquist_is_said_to_filter_nothing(tmp_path, capsys):
    """A cutoff above the loop's Nyquist frequency is designed (its discrete pole is ~0: no filter) and said."""
    assert main(["design", "--d-filter-hz", "1000", "--no-plots", "-q", "--out", str(tmp_path / "pd")]) == 0
    out = capsys.readouterr().out
    assert "note: D filter above the loop's Nyquist frequency (50 Hz at --dt 0.01 s): roll 1000 Hz" in out
    assert main(["design", "--d-filter-hz", "20", "--no-plots", "-q", "--out", str(tmp_path / "pd20")]) == 0
    assert "Nyquist" not in capsys.readouterr().out
