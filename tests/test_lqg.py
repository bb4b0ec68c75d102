"""The LQG baseline (controllers.lqg): margins of the design, the LQR against python-control's, the Kalman
filter on a noise-free simulation, the policy interface (batched, deterministic, episode starts), files and
bad inputs."""

import json
import math
import warnings

import control
import numpy as np
import pytest

from controllers.errors import AgentError, DesignError
from controllers.lqg import LQGController, LQGWeights, WindModel, axis_model, design_axis, design_lqg, loop_margins
from controllers.lqg.design import compensator, predicted_errors
from heli_core.linear import hover_linearisation
from heli_core.terms import AXES


@pytest.fixture(scope="module")
def design(shipped):
    """The LQG of the shipped model as ``scripts/lqg_baseline.py`` designs it (defaults)."""
    return design_lqg(shipped)


def _observations(model_by_axis, x_by_axis):
    """Noise-free observations ``(E, 12)`` of an attitude hold for per-axis states ``(E, n_axis)``."""
    E = x_by_axis[0].shape[0]
    obs = np.zeros((E, 12))
    for i, (m, x) in enumerate(zip(model_by_axis, x_by_axis)):
        y = x @ m.C.T  # (E, 2): angle, gyro
        obs[:, i], obs[:, 3 + i], obs[:, 6 + i] = -y[:, 0], y[:, 1], -y[:, 1]
    return obs


def _split(state, sizes):
    return np.split(state, np.cumsum(sizes)[:-1], axis=-1)


# ----------------------------------------------------------------- the design
def test_design_keeps_the_margins_and_python_control_agrees(design):
    """Every axis' sampled loop at the plant input is stable with >= 6 dB and >= 45 deg, and the margins read
    off the batched response equal python-control's stability_margins on the same loop."""
    for a in design.axes:
        assert a.gain_margin_db >= 6.0 and a.phase_margin_deg >= 45.0, a.summary()
        A, B, C, F = a.model.A, a.model.B, a.model.C, np.eye(a.model.n) - a.M @ a.model.C
        Z = np.block([[A - B @ a.K @ a.M @ C, -B @ a.K @ F], [(A - B @ a.K) @ a.M @ C, (A - B @ a.K) @ F]])
        assert np.max(np.abs(np.linalg.eigvals(Z))) < 1.0  # plant and filter together
        Ap, Bp, Cp = a.model.plant()
        dt = a.model.dt
        loop = -control.series(control.ss(Ap, Bp, Cp, np.zeros((2, 1)), dt),
                               control.ss(*compensator(a.model, a.K, a.M), dt))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gm, pm, *_ = control.stability_margins(control.frd(loop, np.geomspace(1e-2, math.pi / dt, 3000)[:-1]),
                                                   returnall=True)
        np.testing.assert_allclose(np.min(np.abs(20 * np.log10(gm))), a.gain_margin_db, atol=0.02)
        np.testing.assert_allclose(np.min(np.abs(pm)), a.phase_margin_deg, atol=0.05)
        # the smallest recovery weight that keeps them: the one before it on the grid did not
        kept = [row["kept"] for row in a.search]
        assert kept[-1] and not any(kept[:-1])


def test_lqr_equals_dlqr_without_wind_and_with_the_true_state(shipped):
    """Without gust states and lines, the regulator is python-control's dlqr on the axis' own block of the
    linearisation sampled by zero-order hold, and the policy fed the true state applies -K x."""
    w = LQGWeights(0.2, 1.0, 0.8)
    models = [axis_model(shipped.params, shipped.sensors, None, a, 0.01, 0.2, lines=False) for a in AXES]
    designs = [design_axis(m, w, recovery=0.0) for m in models]
    lin = hover_linearisation(shipped.params, 0.2)
    for i, d in enumerate(designs):
        A, B, _ = lin.axis_block(i)
        sys = control.c2d(control.ss(A, B[:, :1], np.eye(A.shape[0]), np.zeros((A.shape[0], 1))), 0.01, "zoh")
        Q = np.zeros((A.shape[0], A.shape[0]))
        Q[-1, -1], Q[0, 0] = 1 / math.radians(0.2) ** 2, 1 / math.radians(1.0) ** 2
        K_ref = control.dlqr(sys.A, sys.B, Q, np.array([[1 / 0.8 ** 2]]))[0]
        np.testing.assert_allclose(d.K, K_ref, rtol=1e-9, atol=1e-12)
    ctrl = LQGController([{"A": d.model.A, "B": d.model.B, "C": d.model.C, "K": d.K, "M": d.M} for d in designs])
    rng = np.random.default_rng(4)
    x = [rng.normal(0, 1e-3, (5, m.n)) for m in models]  # small: no clip
    action, _ = ctrl.predict(_observations(models, x), state=np.hstack(x))
    expected = np.column_stack([-(xi @ d.K.T)[:, 0] for xi, d in zip(x, designs)])
    np.testing.assert_allclose(action, expected.astype(np.float32), rtol=1e-5, atol=1e-7)


def test_estimator_converges_on_a_noise_free_simulation(design):
    """The design model (airframe, gust and line states) from a random state, without process or measurement
    noise, in closed loop with the policy started from the prior: the filter's prediction converges on the
    true state (every state, the gust and the lines included) at the rate of its slowest pole (1.8 s on roll):
    by 25 s to 1e-4 of where it started."""
    models = [a.model for a in design.axes]
    ctrl = design.controller()
    rng = np.random.default_rng(0)
    E = 4
    x = [rng.normal(0, 1, (E, m.n)) * np.r_[np.full(m.n_plant, 0.02), np.full(m.n - m.n_plant, 0.05)]
         for m in models]
    state, errors = None, []
    for k in range(2500):
        u, state = ctrl.predict(_observations(models, x), state, np.full(E, k == 0))
        x = [xi @ m.A.T + u[:, [i]].astype(float) @ m.B.T for i, (xi, m) in enumerate(zip(x, models))]
        errors.append(np.abs(state - np.hstack(x)).max())
    assert errors[-1] < 1e-4 * errors[0], (errors[0], errors[-1])


def test_prediction_is_close_to_the_closed_loop_it_flies(design):
    """The predicted stationary p90 (design model, Lyapunov) matches that of the policy stepped on the same
    model with its noises, to the sampling error of 40 s x 16 copies."""
    models = [a.model for a in design.axes]
    ctrl = design.controller()
    rng = np.random.default_rng(1)
    E, n = 16, 4000
    x = [np.zeros((E, m.n)) for m in models]
    state, angles = None, []
    chol = [np.linalg.cholesky(m.Qw + 1e-30 * np.eye(m.n)) for m in models]
    for k in range(n):
        obs = _observations(models, x)
        for i, m in enumerate(models):
            v = rng.normal(size=(E, 2)) * np.sqrt(np.diag(m.Rv))
            obs[:, i] -= v[:, 0]
            obs[:, 6 + i] -= v[:, 1]
        u, state = ctrl.predict(obs, state)
        angles.append([x[i][:, m.angle_index] for i, m in enumerate(models)])
        x = [xi @ m.A.T + u[:, [i]].astype(float) @ m.B.T + rng.normal(size=(E, m.n)) @ L.T
             for i, (xi, m, L) in enumerate(zip(x, models, chol))]
    flown = np.degrees(np.percentile(np.abs(np.array(angles[500:])), 90, axis=(0, 2)))
    predicted = [predicted_errors(a.model, a.K, a.M)[0] for a in design.axes]
    np.testing.assert_allclose(flown, predicted, rtol=0.1)


# ----------------------------------------------------------------- the policy
def test_batched_deterministic_and_episode_start_resets(design):
    """A batch is its rows flown one by one; the same observations give the same actions; a copy whose
    episode starts flies as a fresh controller while the others keep their memory."""
    ctrl = design.controller()
    rng = np.random.default_rng(2)
    obs = rng.normal(0, 0.002, (30, 3, 12))
    runs = []
    for _ in range(2):
        state, acts = None, []
        for k in range(30):
            a, state = ctrl.predict(obs[k], state, np.full(3, k == 0))
            acts.append(a)
        runs.append(np.array(acts))
    np.testing.assert_array_equal(runs[0], runs[1])
    for e in range(3):  # a batch row is the single-observation call
        state = None
        for k in range(30):
            a, state = ctrl.predict(obs[k, e], state)
            np.testing.assert_allclose(a, runs[0][k, e], rtol=1e-6, atol=1e-8)
    state, fresh, restarted = None, None, []
    for k in range(30):  # copy 1 starts a new episode at k = 20
        a, state = ctrl.predict(obs[k], state, np.array([k == 0, k in (0, 20), k == 0]))
        np.testing.assert_array_equal(a[[0, 2]], runs[0][k, [0, 2]])
        if k >= 20:
            restarted.append(a[1])
    for k in range(20, 30):
        a, fresh = ctrl.predict(obs[k, 1], fresh)
        np.testing.assert_allclose(restarted[k - 20], a, rtol=1e-6, atol=1e-8)
    assert not np.allclose(restarted[-1], runs[0][-1, 1])  # the restart changed what copy 1 does


def test_flown_by_the_evaluator_deterministically(design, shipped):
    """The one evaluator flies it (memory through state/episode_start); twice with one seed, the same result."""
    from controllers.agent_description import describe_agent
    from controllers.evaluate import evaluate_agent

    ctrl = design.controller()
    settings = dict(episodes_per_trace=1, episode_seconds=2.0, seed=3)
    r1, r2 = evaluate_agent(ctrl, shipped, **settings), evaluate_agent(ctrl, shipped, **settings)
    np.testing.assert_array_equal(r1.samples["action"], r2.samples["action"])
    assert r1.n_terminated == 0
    assert describe_agent(ctrl)[0] == "lqg"


def test_save_load_round_trip(design, tmp_path):
    ctrl = design.controller()
    path = ctrl.save(tmp_path / "lqg.json", {"design": design.summary()})
    back = LQGController.load(path)
    obs = np.random.default_rng(5).normal(0, 0.01, (4, 12))
    a1, s1 = ctrl.predict(obs)
    a2, s2 = back.predict(obs)
    np.testing.assert_array_equal(a1, a2)
    np.testing.assert_array_equal(s1, s2)
    assert json.loads(path.read_text())["metadata"]["design"]["axes"][0]["axis"] == "roll"


# ----------------------------------------------------------------- bad inputs
def test_bad_observation(design):
    with pytest.raises(AgentError, match=r"observation must have shape \(12,\)"):
        design.controller().predict(np.zeros(11))


def test_nonfinite_observation(design):
    with pytest.raises(AgentError, match="observation must be finite"):
        design.controller().predict(np.full(12, np.nan))


def test_bad_state(design):
    with pytest.raises(AgentError, match="state must be the filter state the last predict returned"):
        design.controller().predict(np.zeros((2, 12)), state=np.zeros((2, 3)))


def test_bad_episode_start(design):
    ctrl = design.controller()
    _, state = ctrl.predict(np.zeros((2, 12)))
    with pytest.raises(AgentError, match=r"episode_start must hold one flag per observation \(2\)"):
        ctrl.predict(np.zeros((2, 12)), state, episode_start=[True, False, True])


def test_bad_matrices():
    with pytest.raises(AgentError, match=r"roll: K must have shape \(1, 2\)"):
        LQGController([{"A": np.eye(2), "B": np.ones((2, 1)), "C": np.eye(2), "K": np.ones((1, 3)),
                        "M": np.ones((2, 2))}] * 3)


def test_bad_controller_dt():
    with pytest.raises(AgentError, match=r"dt must be a control period in \(0, 1\) s"):
        LQGController([], dt=0.0)


def test_load_refuses_a_pd_file(tmp_path):
    from controllers.pd import PDController, PDGains

    path = PDController(PDGains(1.0, 0.1)).save(tmp_path / "pd.json")
    with pytest.raises(AgentError, match="expected schema 'heli-env/lqg-controller'"):
        LQGController.load(path)


def test_bad_weights():
    with pytest.raises(DesignError, match="LQGWeights.attitude_deg must be a number > 0"):
        LQGWeights(attitude_deg=0.0)


def test_bad_wind_model():
    with pytest.raises(DesignError, match="WindModel.kind must be one of"):
        WindModel("dryden", (1.0, 0.1), (0.1, 0.1))
    with pytest.raises(DesignError, match=r"WindModel.time_constants_s must be 2 numbers > 0"):
        WindModel("gm2", (1.0, -0.1), (0.1, 0.1))


def test_model_without_a_wind_model_is_refused(ideal):
    with pytest.raises(DesignError, match=r"fit_statistics.axes.roll.wind is missing"):
        design_lqg(ideal)


def test_model_without_wind_designs_with_a_given_one(ideal):
    """The ideal model (no servo delay, no sensors) with a given gust model: two airframe states per axis, the
    measurement floor as noise, margins kept (with 0.5 deg allowed: measured exactly, the LQG is the LQR, whose
    yaw loop keeps 6.0 dB at most with the default weights)."""
    d = design_lqg(ideal, weights=LQGWeights(0.5, 2.5), wind=WindModel("gm2", (3.0, 0.3), (0.05, 0.05)))
    assert [a.model.n for a in d.axes] == [4, 4, 4]
    assert all(a.gain_margin_db >= 6 and a.phase_margin_deg >= 45 for a in d.axes)


def test_unreachable_margins(shipped):
    m = axis_model(shipped.params, shipped.sensors, WindModel.from_document(shipped.document, "roll"), "roll", 0.01)
    with pytest.raises(DesignError, match=r"roll: no recovery weight of 0\.\.1 keeps 6 dB and 89 deg"):
        design_axis(m, recovery=(0.0, 1.0), phase_margin_deg=89.0)


def test_bad_axis_and_dt(shipped):
    with pytest.raises(DesignError, match="axis must be one of roll, pitch, yaw"):
        axis_model(shipped.params, shipped.sensors, None, "heave", 0.01)
    with pytest.raises(DesignError, match=r"dt must be a control period in \(0, 1\) s"):
        axis_model(shipped.params, shipped.sensors, None, "roll", 0.0)


def test_loop_margins_of_an_unstable_loop_says_so(shipped):
    """A regulator of the wrong sign destabilises the loop: reported unstable, not kept."""
    m = axis_model(shipped.params, shipped.sensors, None, "roll", 0.01, lines=False)
    d = design_axis(m, recovery=0.0)
    assert not loop_margins(m, -d.K, d.M)["stable"]


def test_load_agent_reads_an_lqg_file(design, tmp_path):
    """``heli evaluate`` loads agents by content: an LQG JSON comes back as the LQG; a broken one says why."""
    from controllers.rl.agent_file import load_agent

    path = design.controller().save(tmp_path / "agent.json")
    back = load_agent(path)
    assert isinstance(back, LQGController)
    obs = np.random.default_rng(6).normal(0, 0.01, (2, 12))
    np.testing.assert_array_equal(back.predict(obs)[0], design.controller().predict(obs)[0])
    doc = json.loads(path.read_text())
    doc["axes"][1]["M"] = [[0.0]]
    path.write_text(json.dumps(doc))
    with pytest.raises(AgentError, match=r"agent.json: pitch: M must have shape \(11, 2\)"):
        load_agent(path)


def test_evaluator_flies_an_lqg_at_its_own_period(shipped):
    """An LQG sampled at 0.02 s is flown at 0.02 s (its matrices are a 0.02 s period's), not the env's 0.01 s."""
    from controllers.evaluate import evaluate_agent

    axes = []
    for axis in AXES:
        m = axis_model(shipped.params, shipped.sensors, WindModel.from_document(shipped.document, axis), axis, 0.02)
        d = design_axis(m, LQGWeights(0.3, 1.5), recovery=0.0)
        axes.append({"A": m.A, "B": m.B, "C": m.C, "K": d.K, "M": d.M})
    res = evaluate_agent(LQGController(axes, dt=0.02), shipped, episodes_per_trace=1, episode_seconds=2.0)
    assert res.settings["dt"] == 0.02 and res.n_terminated == 0


def test_heli_design_lqg_writes_an_agent_heli_evaluate_flies(tmp_path):
    """``heli design --lqg`` writes lqg.json (load_agent reads it back as the LQG), lqg.md linking the recovery
    and the three loops' Bode figures, and lqg.html with them inside; --no-plots draws none of them."""
    from controllers.rl.agent_file import load_agent
    from heli_cli.main import main

    assert main(["design", "--lqg", "--out", str(tmp_path)]) == 0
    assert isinstance(load_agent(tmp_path / "lqg.json"), LQGController)
    text = (tmp_path / "lqg.md").read_text()
    assert "Bryson's weights" in text and "| roll | 11 |" in text
    figures = ["recovery.png"] + [f"bode_{a}.png" for a in ("roll", "pitch", "yaw")]
    for name in figures:
        assert f"]({name})" in text and (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "data:image/png;base64," in (tmp_path / "lqg.html").read_text()
    bare = tmp_path / "bare"
    assert main(["design", "--lqg", "--no-plots", "--out", str(bare)]) == 0
    assert not any((bare / name).exists() for name in figures) and ".png" not in (bare / "lqg.md").read_text()
    assert (bare / "lqg.html").exists()


def test_the_lqg_recovers_from_an_attitude_error_as_its_loop_predicts(design):
    """The recovery figure's response: from 2 degrees, the noise-free loop brings every axis back (under 5 % of
    the error after 40 / crossover) with sticks inside the env's ±1; the loop drawn in the Bode figure is the
    one whose margins the design reports."""
    import math

    from controllers.lqg.design import loop_margins, plant_input_loop, recovery_response

    for a in design.axes:
        t, angle, stick = recovery_response(a.model, a.K, a.M, math.radians(2.0), 40.0 / a.crossover_rad_s)
        assert angle[0] == pytest.approx(math.radians(2.0)) and abs(angle[-1]) < 0.05 * math.radians(2.0)
        assert np.max(np.abs(stick)) < 1.0 and t[1] == pytest.approx(a.model.dt)
        assert plant_input_loop(a.model, a.K, a.M).dt == a.model.dt
        assert loop_margins(a.model, a.K, a.M)["phase_margin_deg"] == pytest.approx(a.phase_margin_deg)


def test_heli_design_lqg_refuses_a_pd_option_and_a_model_without_wind(tmp_path, ideal_model_dir, capsys):
    from heli_cli.main import main

    assert main(["design", "--lqg", "--bandwidth", "5", "--out", str(tmp_path)]) == 2
    assert "--bandwidth sets a PD's bandwidth" in capsys.readouterr().err
    assert main(["design", "--lqg", "--model", str(ideal_model_dir), "--out", str(tmp_path)]) == 2
    assert "ideal_model: model.json fit_statistics.axes.roll.wind is missing" in capsys.readouterr().err
    assert not (tmp_path / "lqg.json").exists()


def test_rl_targets_puts_the_lqg_beside_the_best_pd(tmp_path, capsys):
    """scripts/rl_targets.py: a run that flew the LQG (train_compare.py does) gets each RL agent's p90 over the
    LQG's in the targets table; the LQG is a reference, not a row of its own; a run without it shows '—'."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("rl_targets", Path(__file__).parents[1] / "scripts" / "rl_targets.py")
    targets = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(targets)

    def run(folder, p90):
        results = [{"summary": {"name": name, "axes": {a: {"att_p90_deg": v} for a, v in zip(AXES, values)}}}
                   for name, values in p90.items()]
        folder.mkdir()
        (folder / "comparison.json").write_text(json.dumps({"results": results, "training": {}}))
        return folder

    pds = {"PD robust swept": (0.20, 0.10, 0.30), "PD best swept": (0.10, 0.09, 0.12)}
    with_lqg = run(tmp_path / "a", {**pds, "PPO-RESIDUAL": (0.10, 0.09, 0.12), "LQG": (0.08, 0.09, 0.10)})
    without = run(tmp_path / "b", {**pds, "PPO-RESIDUAL": (0.10, 0.09, 0.12)})
    assert targets.main([str(with_lqg), str(without)]) == 0
    out = capsys.readouterr().out
    assert "| ÷ best PD | ÷ LQG |" in out
    assert "| 1.00 / 1.00 / 1.00 | 1.25 / 1.00 / 1.20 | yes | yes |" in out
    assert "| 1.00 / 1.00 / 1.00 | — | yes | yes |" in out
    assert "| a | LQG |" not in out
