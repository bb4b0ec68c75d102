"""The end of a training run (:mod:`controllers.rl.training_report`, ``heli train``): the learning curve recorded
by an SB3 callback (:class:`controllers.sb3_training.LearningCurve`), the final agent against a PD on the same
held-out gusts, and the warning when the agent is worse. Training runs are a few hundred steps."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from controllers.pd import PDController, design_gains  # noqa: E402
from controllers.rl import train_agent  # noqa: E402
from controllers.rl.training_report import compare_with_pd, plot_learning_curve, reference_pd  # noqa: E402
from controllers.trace_split import TraceSegment  # noqa: E402
from heli_cli.main import main  # noqa: E402

TINY = {"n_steps": 64, "batch_size": 64, "n_epochs": 2}


def _run(shipped, out, seed=3):
    return train_agent("ppo", model=shipped, timesteps=256, out=out, seed=seed, n_envs=2, eval_freq=128,
                       checkpoint_freq=0, progress=False, eval_episodes=2, episode_seconds=1.0, algo_kwargs=TINY)


@pytest.fixture(scope="module")
def runs(shipped, tmp_path_factory):
    """Two runs with one seed, in two folders."""
    return [_run(shipped, tmp_path_factory.mktemp(f"run{i}") / "ppo") for i in range(2)]


def test_the_learning_curve_callback_records_returns_and_held_out_p90(runs):
    curve = runs[0].learning_curve
    episodes = np.array(curve["episodes"])
    assert len(episodes) == 2  # each of the 2 copies ends one 1 s episode (100 steps) in its 128 steps
    assert np.all(np.diff(episodes[:, 0]) >= 0) and np.all(np.isfinite(episodes[:, 1]))
    assert [e["timesteps"] for e in curve["evaluations"]] == [128, 256]
    for e, (t, mean, _) in zip(curve["evaluations"], runs[0].evaluations):
        assert e["timesteps"] == t and e["mean_return"] == pytest.approx(mean)
        assert len(e["p90_deg"]) == 3 and all(v > 0 and np.isfinite(v) for v in e["p90_deg"])
    assert json.loads((runs[0].run_dir / "training.json").read_text())["learning_curve"] == curve


def test_the_same_seed_gives_the_same_curve_and_comparison(runs, shipped):
    from controllers.rl import load_agent

    assert runs[0].learning_curve == runs[1].learning_curve
    pd = PDController.from_model(shipped.params, design_gains(shipped.params))
    held_out = [TraceSegment(**d) for d in runs[0].metadata["eval_segments"]]
    a, b = (compare_with_pd(load_agent(r.path), pd, shipped, held_out, 3, 1.0, episodes_per_trace=1).to_dict()
            for r in runs)
    assert a == b


def test_an_agent_no_worse_than_the_pd_draws_no_warning(shipped, tmp_path):
    """The PD against itself: ratios 1, no axis worse, no warning; the figure draws without a curve too."""
    pd = reference_pd(shipped)
    assert pd.filtered  # heli design's defaults carry the derivative filter
    c = compare_with_pd(pd, pd, shipped, [TraceSegment(2)], 0, 1.0, episodes_per_trace=1)
    assert c.ratios == [1.0, 1.0, 1.0] and c.worse_axes == [] and c.warning() is None
    assert "| pitch |" in c.table() and "equal" in c.table()
    png = plot_learning_curve({"episodes": [], "evaluations": []}, tmp_path / "lc.png", c, 100)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_heli_train_warns_when_the_agent_is_worse_than_the_pd(tmp_path, capsys):
    """A few hundred steps of PPO hold attitude far worse than the designed PD: one warning line on stderr, the
    table on stdout, the report opening with the warning and showing the learning curve."""
    out = tmp_path / "ppo"
    assert main(["train", "--algo", "ppo", "--timesteps", "128", "--out", str(out), "--n-envs", "2",
                 "--episode-seconds", "1", "--eval-freq", "128", "--eval-episodes", "2", "--checkpoint-freq", "0",
                 "--no-progress", "--algo-kwargs", json.dumps(TINY)]) == 0
    captured = capsys.readouterr()
    warnings = [ln for ln in captured.err.splitlines() if "WARNING" in ln]
    assert len(warnings) == 1 and "the agent holds attitude worse than the PD (heli design's defaults)" in warnings[0]
    assert "agent vs PD (heli design's defaults)" in captured.out and "  pitch: agent " in captured.out
    run_dir = tmp_path / "ppo_training"
    report = (run_dir / "report.md").read_text()
    assert report.splitlines()[2].startswith("**WARNING") and "![learning curve](learning_curve.png)" in report
    assert "| pitch |" in report and (run_dir / "learning_curve.png").stat().st_size > 0
    assert (run_dir / "report.html").exists()
    comparison = json.loads((run_dir / "comparison.json").read_text())
    assert comparison["worse_axes"] and comparison["pd"] == "heli design's defaults"


def test_the_pd_compared_with_is_named_and_a_bad_one_refused_before_training(tmp_path, capsys):
    """--compare-pd names its file, a --residual run compares with its base; a file that is no PD ends the
    command before any training (exit 2, nothing written)."""
    import argparse

    from controllers.pd import PDGains
    from heli_cli.train import _comparison_pd

    pd_file = PDController(PDGains([20.0, 30.0, 4.0], [3.0, 5.0, 0.5]), [1, -1, 1]).save(tmp_path / "pd.json")
    pd, label = _comparison_pd(argparse.Namespace(compare_pd=str(pd_file), residual=None), None, 0.01)
    assert label == str(pd_file) and pd.gains.kp == (20.0, 30.0, 4.0)
    _, label = _comparison_pd(argparse.Namespace(compare_pd=None, residual=str(pd_file)), None, 0.01)
    assert label == f"the residual's base {pd_file}"
    (tmp_path / "bad.json").write_text("{}")
    assert main(["train", "--algo", "ppo", "--timesteps", "64", "--out", str(tmp_path / "a"), "--compare-pd",
                 str(tmp_path / "bad.json"), "--no-progress"]) == 2
    assert "--compare-pd must be a PD controller JSON" in capsys.readouterr().err
    assert not (tmp_path / "a.zip").exists() and not (tmp_path / "a_training").exists()


def test_a_residual_on_an_lqg_base_is_compared_with_the_lqg_by_name(shipped):
    """A residual trained on ``heli design --lqg``'s controller is compared with an LQG: the table, the warning
    and the JSON say "LQG", never "PD"."""
    from controllers.lqg.design import design_lqg

    lqg = design_lqg(shipped).controller()
    c = compare_with_pd(reference_pd(shipped), lqg, shipped, [TraceSegment(2)], 0, 1.0, pd_label="lqg.json",
                        episodes_per_trace=1)
    assert c.base_kind == "LQG" and c.to_dict()["base_kind"] == "LQG"
    assert "| LQG p90 [°] | agent / LQG |" in c.table() and " PD " not in c.table()
    if c.warning() is not None:  # the PD flown as the "agent" is worse than the LQG on some axis
        assert "worse than the LQG (lqg.json)" in c.warning() and "PD" not in c.warning()
    assert c.worse_axes, "the designed PD should hold attitude worse than the LQG on at least one axis"
