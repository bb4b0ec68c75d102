"""Tests of the shared error metrics (:mod:`controllers.metrics`), the agent evaluator
(:mod:`controllers.evaluate`) and ``heli evaluate``.

The evaluator is held against the gain sweep: a PD controller flown by the
environment on one gust window must show the sweep's metrics for that pair and
window (both replay the window through the same physics core from rest).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from controllers.errors import AgentError
from controllers.evaluate import EvaluationConfig, evaluate_agent
from controllers.evaluate_report import evaluation_markdown, plot_episode
from controllers.evaluate_report import comparison_markdown
from controllers.metrics import METRIC_NAMES, error_metrics, histogram_edges
from controllers.pd import PDController, PDGains, design_gains
from controllers.sweep import sweep_pairs
from controllers.trace_split import TraceSegment, split_traces
from heli_cli.main import main


@pytest.fixture(scope="module")
def pd(shipped):
    return PDController.from_model(shipped.params, design_gains(shipped.params))


@pytest.fixture(scope="module")
def pd_result(shipped, pd):
    return evaluate_agent(pd, shipped, episodes_per_trace=3, episode_seconds=10.0, seed=5)


# -------------------------------------------------------------------------------------------- metrics
def test_error_metrics_match_numpy():
    rng = np.random.default_rng(0)
    att, rate, act = rng.normal(0, 2, 1001), rng.normal(0, 10, 1001), rng.uniform(-1.2, 1.2, 1001)
    act = np.clip(act, -1, 1)
    m = error_metrics(att, rate, act)
    assert_allclose(m["att_rms_deg"], np.sqrt(np.mean(att ** 2)), rtol=1e-12)
    assert_allclose([m["att_p50_deg"], m["att_p90_deg"], m["att_p99_deg"]], np.percentile(np.abs(att), [50, 90, 99]),
                    rtol=1e-12)
    assert_allclose(m["rate_p90_dps"], np.percentile(np.abs(rate), 90), rtol=1e-12)
    assert_allclose(m["stick_p99"], np.percentile(np.abs(act), 99), rtol=1e-12)
    assert m["saturation"] == pytest.approx(np.mean(np.abs(act) == 1.0))
    assert m["hist_counts"].sum() + m["hist_overflow"] == 1001
    assert m["n_samples"] == 1001 and set(METRIC_NAMES) <= set(m)


def test_error_metrics_rows_and_histogram_bins():
    rng = np.random.default_rng(1)
    att, rate, act = rng.normal(0, 3, (4, 500)), rng.normal(0, 3, (4, 500)), rng.uniform(-1, 1, (4, 500))
    rows = error_metrics(att, rate, act)
    for i in range(4):
        one = error_metrics(att[i], rate[i], act[i])
        for k in METRIC_NAMES:
            assert rows[k][i] == pytest.approx(one[k], rel=1e-12)
        assert_array_equal(rows["hist_counts"][i], one["hist_counts"])
    edges = histogram_edges(5.0, 10)
    m = error_metrics(np.array([0.0, 0.005, 0.01, 4.99, 5.0, 7.0]), np.zeros(6), np.zeros(6), hist_edges=edges)
    assert m["hist_counts"][0] == 2 and m["hist_counts"][1] == 1 and m["hist_counts"][-1] == 1
    assert m["hist_overflow"] == 2  # at or above the last edge
    sat = error_metrics(np.ones(4), np.ones(4), np.zeros(4), saturated=[True, False, False, False])
    assert sat["saturation"] == 0.25


def test_error_metrics_bad_input():
    with pytest.raises(ValueError, match="share one shape"):
        error_metrics(np.ones(3), np.ones(4), np.ones(3))
    with pytest.raises(ValueError, match="at least one sample"):
        error_metrics(np.ones(0), np.ones(0), np.ones(0))
    with pytest.raises(ValueError, match="histogram"):
        histogram_edges(0.001)


def test_non_finite_samples_give_nan_metrics():
    m = error_metrics(np.array([1.0, np.nan]), np.ones(2), np.zeros(2))
    assert all(np.isnan(m[k]) for k in METRIC_NAMES)


# ------------------------------------------------------------------------------------------ evaluator
def test_same_seed_same_evaluation(shipped, pd, pd_result):
    again = evaluate_agent(pd, shipped, episodes_per_trace=3, episode_seconds=10.0, seed=5)
    assert again.summary() == pd_result.summary()
    assert again.episodes == pd_result.episodes
    assert_array_equal(again.samples["att_err_deg"], pd_result.samples["att_err_deg"])
    other = evaluate_agent(pd, shipped, episodes_per_trace=3, episode_seconds=10.0, seed=6)
    assert [e["offset"] for e in other.episodes] != [e["offset"] for e in pd_result.episodes]


def test_a_plain_predict_and_one_with_memory_fly_alike(shipped, pd, pd_result):
    """An agent whose predict takes only (observation, deterministic) is flown as before; one that takes SB3's
    state and episode_start gets them: its state comes back at the next step, episode_start on the first."""

    class Plain:
        def predict(self, observation, deterministic=True):
            return pd.predict(observation)

    class Remembering:
        def __init__(self):
            self.starts, self.states = [], []

        def predict(self, observation, state=None, episode_start=None, deterministic=False):
            self.starts.append(bool(np.all(episode_start)))
            self.states.append(state)
            return pd.predict(observation)[0], len(self.states)

    episodes = EvaluationConfig(episodes_per_trace=3, episode_seconds=10.0, seed=5)  # pd_result's
    assert_array_equal(evaluate_agent(Plain(), shipped, episodes).samples["att_err_deg"],
                       pd_result.samples["att_err_deg"])
    memory = Remembering()
    assert_array_equal(evaluate_agent(memory, shipped, episodes).samples["att_err_deg"],
                       pd_result.samples["att_err_deg"])
    assert memory.starts[0] and not any(memory.starts[1:])
    assert memory.states[:3] == [None, 1, 2]


def test_evaluation_flies_held_out_traces_only(shipped, pd_result):
    held = {s.trace for s in split_traces(shipped.n_traces).held_out}
    assert {e["trace"] for e in pd_result.episodes} == held
    assert len(pd_result.episodes) == 3 * len(held)
    assert all(e["steps"] == 1000 and not e["terminated"] for e in pd_result.episodes)
    assert pd_result.metrics["roll"]["n_samples"] == 1000 * len(pd_result.episodes)
    assert pd_result.kind == "pd" and pd_result.mean_return < 0


def test_evaluator_reports_the_sweeps_metrics(ideal):
    """One window, roll gains (kp, kd) and the sweep's nominal gains on pitch and yaw: the evaluator's roll
    metrics equal the sweep's row for that pair (the held axes matter through the attitude kinematics). On a
    model measured exactly: the env and the sweep draw their sensor noise from different streams."""
    kp, kd = 6.0, 1.2
    probe = evaluate_agent(PDController(PDGains(1.0, 0.5), (1, -1, 1)), ideal, traces=[0], episodes_per_trace=1,
                           episode_seconds=20.0, seed=2)
    window = (probe.episodes[0]["trace"], probe.episodes[0]["offset"])
    sweep = sweep_pairs(ideal, [(kp, kd)], axis="roll", duration=20.0, traces=[window], progress=False)
    nominal = np.array(sweep.settings["nominal_gains"])
    ctrl = PDController.from_model(ideal.params, PDGains([kp, *nominal[1:, 0]], [kd, *nominal[1:, 1]]))
    res = evaluate_agent(ctrl, ideal, traces=[0], episodes_per_trace=1, episode_seconds=20.0, seed=2)
    assert (res.episodes[0]["trace"], res.episodes[0]["offset"]) == window
    row = sweep.row(0)
    for k in ("att_rms_deg", "att_p50_deg", "att_p90_deg", "att_p99_deg", "rate_rms_dps", "rate_p50_dps",
              "rate_p90_dps", "rate_p99_dps", "stick_rms", "stick_p99", "saturation"):
        assert res.metrics["roll"][k] == pytest.approx(row[k], rel=1e-5, abs=1e-9), k  # float32 observations


def test_time_split_windows_and_explicit_segments(shipped, pd):
    res = evaluate_agent(pd, shipped, traces=[TraceSegment(1, 0.5, 1.0)], episodes_per_trace=2,
                         episode_seconds=5.0, seed=0)
    assert all(e["trace"] == 1 and e["offset"] >= 10000 for e in res.episodes)
    with pytest.raises(ValueError, match="shorter than one episode"):
        evaluate_agent(pd, shipped, traces=[TraceSegment(1, 0.9, 1.0)], episode_seconds=30.0)
    with pytest.raises(ValueError, match="episodes_per_trace"):
        evaluate_agent(pd, shipped, episodes_per_trace=0)


@pytest.mark.parametrize("kw, match", [({"episode_seconds": 300.0}, "shorter than one episode"),
                                       ({"traces": "sideways"}, "split side"),
                                       ({"traces": [99]}, "the library holds"),
                                       ({"task": "flip"}, "task must be one of"),
                                       ({"episodes_per_trace": 1.5}, "episodes_per_trace")])
def test_bad_evaluation_requests(shipped, pd, kw, match):
    with pytest.raises(AgentError, match=match):
        evaluate_agent(pd, shipped, **kw)


def _same_evaluation(a, b):
    assert a.episodes == b.episodes and a.metrics.keys() == b.metrics.keys()
    for ax in a.metrics:
        for k in METRIC_NAMES:
            assert_array_equal(b.metrics[ax][k], a.metrics[ax][k], err_msg=f"{ax} {k}")
    for k, v in a.samples.items():
        assert_array_equal(b.samples[k], v, err_msg=k)


def test_an_evaluation_takes_its_settings_as_one_config_or_by_keyword(shipped, pd, pd_result):
    """The same episodes, bit for bit, from an EvaluationConfig and from its fields by keyword; a keyword given
    beside a config replaces the config's field (as SweepConfig's and TrainConfig's do)."""
    config = EvaluationConfig(episodes_per_trace=3, episode_seconds=10.0, seed=5)
    _same_evaluation(pd_result, evaluate_agent(pd, shipped, config))
    reseeded = evaluate_agent(pd, shipped, config, seed=6)
    assert reseeded.settings["seed"] == 6 and config.seed == 5
    _same_evaluation(evaluate_agent(pd, shipped, episodes_per_trace=3, episode_seconds=10.0, seed=6), reseeded)
    with pytest.raises(TypeError, match="unknown evaluation settings episodes; expected fields of EvaluationConfig"):
        evaluate_agent(pd, shipped, episodes=3)
    with pytest.raises(TypeError, match="config must be an EvaluationConfig"):
        evaluate_agent(pd, shipped, "held-out")


@pytest.mark.parametrize("field, value, match", [
    ("episodes_per_trace", 0, "episodes_per_trace must be a whole number >= 1, got 0"),
    ("episode_seconds", 0.0, "episode_seconds must be a positive number of seconds, got 0.0"),
    ("seed", 1.5, "seed must be a whole number >= 0, got 1.5"),
    ("init_rate_deg", -1.0, "init_rate_deg must be a number >= 0, got -1.0"),
    ("split", "held-out", "split must be a TraceSplit or None, got 'held-out'"),
])
def test_a_bad_evaluation_setting_is_named(field, value, match):
    with pytest.raises(AgentError, match=match):
        EvaluationConfig(**{field: value})


def test_evaluation_builds_one_environment(shipped, pd, monkeypatch):
    import heli_env.vector_env as vector_env

    built = []

    class Counted(vector_env.HeliAttitudeVectorEnv):
        def __init__(self, num_envs=1, *args, **kwargs):
            built.append(num_envs)
            super().__init__(num_envs, *args, **kwargs)

    monkeypatch.setattr(vector_env, "HeliAttitudeVectorEnv", Counted)
    res = evaluate_agent(pd, shipped, traces=[0, 2], episodes_per_trace=3, episode_seconds=2.0, seed=1)
    assert built == [6] and len(res.episodes) == 6


def test_outputs(pd_result, pd, shipped, tmp_path):
    doc = json.loads(pd_result.to_json(tmp_path / "e.json").read_text())
    assert doc["summary"]["axes"]["roll"]["att_p90_deg"] == pytest.approx(pd_result.metrics["roll"]["att_p90_deg"])
    assert len(doc["histograms"]["pitch"]["counts"]) == len(doc["histograms"]["pitch"]["edges"]) - 1
    md = evaluation_markdown(pd_result)
    assert "| roll |" in md and "ended early" in md
    assert plot_episode(pd_result, tmp_path / "ep.png").stat().st_size > 10_000
    other = PDController(PDGains(1.0, 0.3), pd.signs)
    r2 = evaluate_agent(other, shipped, episodes_per_trace=3, episode_seconds=10.0, seed=5, name="soft PD")
    assert "soft PD" in comparison_markdown([pd_result, r2])
    assert plot_episode([pd_result, r2], tmp_path / "both.png").exists()
    r3 = evaluate_agent(other, shipped, episodes_per_trace=3, episode_seconds=10.0, seed=4)
    with pytest.raises(ValueError, match="other gust windows"):
        plot_episode([pd_result, r3], tmp_path / "bad.png")


def test_the_results_old_report_methods_warn_and_call_the_report(pd_result, tmp_path):
    """A result no longer imports its report (issue 34); its ``markdown()`` and ``plot_episode()`` answer for one
    release through :func:`heli_core.deprecation.moved_method`, naming the report's function."""
    with pytest.warns(DeprecationWarning, match="evaluate_report.evaluation_markdown.*0.2.0"):
        assert pd_result.markdown() == evaluation_markdown(pd_result)
    with pytest.warns(DeprecationWarning, match="evaluate_report.plot_episode"):
        assert pd_result.plot_episode(tmp_path / "ep.png", others=[pd_result]).exists()


# ------------------------------------------------------------------------------------------------ CLI
def test_heli_evaluate_pd_json(pd, tmp_path, capsys):
    agent = pd.save(tmp_path / "pd.json")
    out = tmp_path / "ev"
    assert main(["evaluate", str(agent), "--out", str(out), "--episode-seconds", "5",
                 "--episodes-per-trace", "2"]) == 0
    text = capsys.readouterr().out
    assert "held-out traces" in text and "default split" in text
    assert sorted(p.name for p in out.iterdir()) == ["episode.png", "evaluation.html", "evaluation.json", "evaluation.md",
                                                     "servo.png"]


def test_heli_evaluate_robustness_is_written(pd, tmp_path, capsys):
    import json

    agent = pd.save(tmp_path / "pd.json")
    out = tmp_path / "ev"
    assert main(["evaluate", str(agent), "--out", str(out), "--episode-seconds", "2", "--episodes-per-trace", "1",
                 "--no-plots", "--robustness"]) == 0
    printed = capsys.readouterr().out
    saved = json.loads((out / "robustness.json").read_text())
    assert list(saved["cases"]) == ["nominal", "+20 ms servo delay", "gain -20 %", "gain +20 %"]
    delayed = saved["cases"]["+20 ms servo delay"]
    assert saved["cases"]["nominal"]["ratio"] == {"roll": 1.0, "pitch": 1.0, "yaw": 1.0}
    assert f"roll {delayed['p90_deg']['roll']:.3f} deg (x{delayed['ratio']['roll']:.2f})" in printed
    assert "+20 ms servo delay" in (out / "robustness.md").read_text()
    assert f"wrote {out / 'robustness.json'}" in printed


def test_heli_evaluate_split_seed_holds_out_another_trace_for_the_evaluation_and_the_check(pd, tmp_path, capsys):
    """--split-seed flies the held-out traces of 'heli train --split-seed'; the robustness check's nominal case
    flies the same windows as the evaluation (it flew the default split before)."""
    import json

    from controllers.trace_split import split_traces
    from heli_env.env_model import load_env_model

    agent = pd.save(tmp_path / "pd.json")
    out = tmp_path / "ev"
    assert main(["evaluate", str(agent), "--out", str(out), "--episode-seconds", "2", "--episodes-per-trace", "1",
                 "--no-plots", "--robustness", "--split-seed", "1"]) == 0
    printed = capsys.readouterr().out
    env_model = load_env_model(None)
    held_out = [env_model.trace_ids[s.trace] for s in split_traces(env_model.n_traces, seed=1).held_out]
    assert held_out != [env_model.trace_ids[s.trace] for s in split_traces(env_model.n_traces).held_out]
    assert f"held-out traces {', '.join(held_out)} (split seed 1)" in printed
    evaluation = json.loads((out / "evaluation.json").read_text())["summary"]["axes"]
    nominal = json.loads((out / "robustness.json").read_text())["cases"]["nominal"]["p90_deg"]
    assert nominal == {a: evaluation[a]["att_p90_deg"] for a in ("roll", "pitch", "yaw")}


def test_heli_evaluate_errors(pd, tmp_path, capsys):
    agent = pd.save(tmp_path / "pd.json")
    assert main(["evaluate", str(agent), "--model", str(tmp_path / "missing")]) == 2
    assert "EnvModelError" in capsys.readouterr().err
    assert main(["evaluate", str(tmp_path / "nope.json")]) == 2
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "bad.json").write_text("[1, 2]")
    assert main(["evaluate", str(tmp_path / "bad.json")]) == 2
    assert "AgentError" in capsys.readouterr().err
    assert main(["evaluate", str(agent), "--episode-seconds", "300", "--out", str(tmp_path / "ev")]) == 2
    err = capsys.readouterr().err
    assert "AgentError" in err and "shorter than one episode" in err and "Traceback" not in err
    assert not (tmp_path / "ev").exists()


def test_cli_episode_longer_than_the_traces_names_the_option_and_the_longest_that_fits(tmp_path, capsys):
    """Issue 31: the refusal named neither the option nor the longest episode that fits; the advised one runs."""
    import re

    from heli_cli.main import main

    assert main(["design", "--out", str(tmp_path / "pd"), "--no-plots", "-q"]) == 0
    agent = str(tmp_path / "pd" / "pd.json")
    assert main(["evaluate", agent, "--episode-seconds", "5000", "--out", str(tmp_path / "ev"), "-q"]) == 2
    err = capsys.readouterr().err
    advised = re.search(r"the longest episode that fits every trace is ([\d.]+) s: pass --episode-seconds \1 or less",
                        err)
    assert advised and "episode_seconds=" not in err, err
    assert main(["evaluate", agent, "--episode-seconds", advised.group(1), "--episodes-per-trace", "1", "--out",
                 str(tmp_path / "ev"), "--no-plots", "-q"]) == 0


def test_default_episode_fits_a_short_flights_traces():
    """A short flight's held-out trace (the T-REX hover's 20 s) is flown in the longest episode that fits,
    said in a note; a trace that fits the default, or one too short for any useful episode, keeps 30 s."""
    from argparse import Namespace
    from types import SimpleNamespace

    from controllers.trace_split import split_traces
    from heli_cli.evaluate import DEFAULT_EPISODE_S, _episode_seconds

    def model(seconds):
        return SimpleNamespace(lengths=np.array([int(seconds * 100)]), n_traces=1, trace_ids=["t0"], sample_rate=100.0)

    split = split_traces(1, seed=0)  # one trace: its last quarter held out
    args = Namespace(episode_seconds=None, traces="held-out")
    length, note = _episode_seconds(args, model(80.0), split)
    assert length == pytest.approx(19.99, abs=0.011) and "--episode-seconds" in note and "19.9" in note
    assert _episode_seconds(args, model(400.0), split) == (DEFAULT_EPISODE_S, None)
    assert _episode_seconds(args, model(12.0), split) == (DEFAULT_EPISODE_S, None)  # 3 s: refused, naming why
    assert _episode_seconds(Namespace(episode_seconds=7.5, traces="held-out"), model(80.0), split) == (7.5, None)
