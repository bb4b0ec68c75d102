"""Tests of the diagnosis (issue 6): hidden effects in synthetic flights are named, added, and shrink the gap.

Every flight is 180 s of the aggressive manoeuvre pilot (``MANOEUVRE_CONFIG``) in the paper's wind; the
diagnosis is never told which effect the truth model carries.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from heli_core.terms import AXES, TERMS
from identification.bench.flight_config import EFFECTS, MANOEUVRE_CONFIG, PAPER_PARAMS, FlightConfig
from identification.bench.synthetic import simulate_flight
from identification.diagnosis.effects import CATALOGUE
from identification.diagnosis.heldout_diagnoser import Diagnoser, paired_log_test
from identification.diagnosis.residual_tests import cross_correlation, whiteness
from identification.errors import IdentifiabilityError, NotFittedError
from identification.preprocess import shift_inputs

DURATION = 180.0
STRONG_NONLINEAR_DAMPING = {k: 5 * v for k, v in EFFECTS["nonlinear_damping"].items()}
"""Quadratic damping at a size that matters to the flight (the synthetic default is invisible under the wind)."""


def _flight(seed=1, effects=(), truth=None, duration=DURATION, config=MANOEUVRE_CONFIG):
    return simulate_flight(duration, seed=seed, effects=effects, config=config, truth=truth).flight


def _effect_axes(name):
    return {AXES[TERMS[p].axis] for p in CATALOGUE[name].terms}


def _assert_found(d, effect, axes=None):
    assert d.verdict_ == "found", d.evidence_
    names = {e for e, _ in d.effects_found_}
    assert names == {effect}, d.effects_found_
    for step in d.steps_:
        if axes is not None:
            assert step.axis in axes
        assert step.gap_after["mae_deg_s"] < step.gap_before["mae_deg_s"]
        assert step.gain >= d.min_gain and step.p_value <= step.threshold_p
    final, base = d.final_score_.mse.sum(axis=1), d.baseline_score_.mse.sum(axis=1)
    for step in d.steps_:
        a = AXES.index(step.axis)
        assert final[a] < base[a]


def test_no_effect_control_flight_is_none():
    d = Diagnoser().fit(_flight(seed=1))
    assert d.verdict_ == "none", d.steps_
    assert d.effects_found_ == [] and d.steps_ == []
    assert all(max(r["gain"] for r in rows) < d.min_gain for rows in d.rounds_)


SLOW = pytest.mark.slow  # over 5 s each: make test-slow (the same path as the two kept in make test)


@pytest.mark.parametrize("effect", ["cross_coupling", pytest.param("gyroscopic", marks=SLOW), "gain_scheduling",
                                    pytest.param("collective_torque", marks=SLOW)])
def test_hidden_term_effect_is_named_on_its_axis(effect):
    d = Diagnoser().fit(_flight(seed=1, effects=(effect,)))
    _assert_found(d, effect, _effect_axes(effect))
    for step in d.steps_:  # the fitted parameters are the catalogue's terms of that axis
        assert set(step.parameters) == set(CATALOGUE[effect].terms_on(AXES.index(step.axis)))
        assert step.runner_up != effect


def test_strong_nonlinear_damping_is_named():
    d = Diagnoser().fit(_flight(seed=1, truth=PAPER_PARAMS.with_values(**STRONG_NONLINEAR_DAMPING)))
    _assert_found(d, "nonlinear_damping")


def test_servo_delay_is_found_with_its_value():
    d = Diagnoser().fit(_flight(seed=1, effects=("servo_delay",)))
    _assert_found(d, "servo_delay")
    truth = EFFECTS["servo_delay"]
    for step in d.steps_:
        (name, value), = step.parameters.items()
        assert name == f"tau_{step.axis}"
        assert abs(value - truth[name]) <= 0.03


@pytest.mark.parametrize("shift", [0.3, -0.45], ids=["input-lags-0.3s", "input-leads-0.45s"])
def test_log_time_misalignment_in_either_direction_is_a_servo_delay(shift):
    flight = shift_inputs(_flight(seed=1), (shift,) * 3)  # the logged sticks moved by `shift` s
    d = Diagnoser().fit(flight)
    _assert_found(d, "servo_delay")
    assert {s.axis for s in d.steps_} == set(AXES)
    for step in d.steps_:
        (value,) = step.parameters.values()
        assert abs(value + shift) <= 0.02  # the alignment undoes the shift


@pytest.mark.slow  # over 5 s; each effect alone is named in make test
def test_two_hidden_effects_are_both_found():
    d = Diagnoser().fit(_flight(seed=1, effects=("cross_coupling", "gain_scheduling")))
    assert d.verdict_ == "found"
    assert {e for e, _ in d.effects_found_} == {"cross_coupling", "gain_scheduling"}
    for step in d.steps_:
        assert step.axis in _effect_axes(step.effect)
        assert step.gap_after["mae_deg_s"] < step.gap_before["mae_deg_s"]


def test_too_short_flight_says_so_instead_of_naming():
    d = Diagnoser().fit(_flight(seed=1, effects=("cross_coupling",), duration=40.0))
    assert d.verdict_ == "undecided" and d.steps_ == []
    assert "too short" in d.evidence_["reason"] and "40.0 s" in d.evidence_["reason"]


def test_poorly_excited_flight_says_so_instead_of_naming():
    hover = FlightConfig(sweep_amplitude=(0.0, 0.0, 0.0))  # the pilot only holds attitude against the wind
    d = Diagnoser().fit(_flight(seed=1, effects=("cross_coupling",), config=hover))
    assert d.verdict_ == "undecided" and d.steps_ == []
    assert "poorly excited" in d.evidence_["reason"]
    assert d.evidence_["undecided_axes"]


def test_same_flight_same_diagnosis():
    flight = _flight(seed=3, effects=("cross_coupling",), duration=70.0)
    effects = ("cross_coupling", "servo_delay")
    a, b = Diagnoser(effects=effects).fit(flight).summary(), Diagnoser(effects=effects).fit(flight).summary()
    assert json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True, default=str)


def test_diagnose_and_report_takes_its_settings_as_one_config_or_by_keyword(tmp_path):
    """The same diagnosis files from a DiagnosisConfig and from its fields by keyword; a keyword given beside a
    config replaces the config's field (as SweepConfig's and TrainConfig's do); a bad field is named."""
    from identification.workflows.diagnose import DiagnosisConfig, diagnose_and_report

    flight = _flight(seed=3, effects=("cross_coupling",), duration=70.0)
    source = {"file": "flight.csv", "sha256": "0" * 64}
    config = DiagnosisConfig(diagnoser=Diagnoser(effects=("cross_coupling", "servo_delay")), plots=False)
    by_keyword = diagnose_and_report(flight, tmp_path / "a", source=source, plots=False,
                                     diagnoser=Diagnoser(effects=("cross_coupling", "servo_delay")))
    by_config = diagnose_and_report(flight, tmp_path / "b", config, source=source)
    assert by_config.document["steps"] and by_config.document["model_file"] == str(tmp_path / "b" / "model.json")
    assert {**by_config.document, "model_file": None} == {**by_keyword.document, "model_file": None}
    assert (tmp_path / "b" / "model.json").exists() and not (tmp_path / "b" / "diagnosis_residuals.png").exists()
    with_plots = diagnose_and_report(flight, tmp_path / "c", config, source=source, plots=True, draw_figures=False)
    assert with_plots.figures and not config.plots  # the keyword won, the config is unchanged
    with pytest.raises(TypeError, match="unknown diagnosis settings plot; expected fields of DiagnosisConfig"):
        diagnose_and_report(flight, tmp_path / "d", plot=False)
    with pytest.raises(ValueError, match="diagnoser must be a Diagnoser or None, got 'ml'"):
        DiagnosisConfig(diagnoser="ml")
    with pytest.raises(ValueError, match="wait must be True or False, got None"):
        DiagnosisConfig(wait=None)


@pytest.mark.slow
def test_cli_writes_diagnosis_and_a_model_the_env_and_pd_accept(tmp_path):
    import gymnasium as gym

    import heli_env  # noqa: F401 - registers the env
    from controllers.pd import design_gains
    from heli_cli.main import main
    from heli_env import load_env_model
    from model_store.model_file import load_model

    sim = simulate_flight(DURATION, seed=1, effects=("cross_coupling",), config=MANOEUVRE_CONFIG)
    sim.save(tmp_path / "flight.csv")
    out = tmp_path / "diag"
    assert main(["diagnose", str(tmp_path / "flight.csv"), "--out", str(out), "--method", "integral"]) == 0
    doc = json.loads((out / "diagnosis.json").read_text())
    assert doc["verdict"] == "found" and doc["steps"]
    for step in doc["steps"]:
        assert {"axis", "effect", "parameters", "gap_before", "gap_after", "runner_up", "margin"} <= set(step)
    md = (out / "diagnosis.md").read_text()
    assert "cross_coupling" in md and "diagnosis_residuals.png" in md
    assert (out / "diagnosis_residuals.png").stat().st_size > 0 and (out / "diagnosis_windows.png").exists()
    params, model_doc = load_model(out)
    assert params.k4 != 0.0 or params.k8 != 0.0
    assert model_doc.to_dict()["diagnosis"]["added"]
    env = gym.make("HeliAttitude-v0", model=str(out))
    env.reset(seed=0)
    env.step(np.zeros(3, dtype=np.float32))
    assert load_env_model(out).params == params
    assert len(design_gains(params).kp) == 3


def test_a_diverging_simulation_is_clipped_and_named_in_the_windows_plot():
    from identification.reports.diagnosis import window_limits

    t = np.linspace(0, 4, 400)
    measured = 10 * np.sin(t)
    close = 12 * np.sin(t)  # a fair model that overshoots: shown whole
    diverged = np.where(t < 0.5, measured, 2000.0)
    (lo, hi), notes = window_limits(measured, {"before": diverged, "after": close})
    assert lo < close.min() and close.max() < hi < 20  # the 2000 deg/s do not flatten the comparison
    assert notes == {"before": " (diverged: up to 2000 deg/s, clipped)", "after": ""}
    _, notes = window_limits(measured, {"before": np.full_like(t, np.nan)})
    assert notes == {"before": " (diverged, clipped)"}


# ------------------------------------------------------------------ bad input and pieces
def test_bad_settings_and_inputs_raise_named_errors():
    flight = _flight(seed=1, duration=30.0)
    with pytest.raises(ValueError, match=r"Diagnoser.folds out of range: 1"):
        Diagnoser(folds=1).fit(flight)
    with pytest.raises(ValueError, match=r"unknown effect\(s\) \['drag'\]; the catalogue holds servo_delay"):
        Diagnoser(effects=["drag"]).fit(flight)
    with pytest.raises(TypeError, match=r"flight must be a Flight, got ndarray"):
        Diagnoser().fit(np.zeros(3))
    with pytest.raises(TypeError, match=r"model must be a ModelParams or None, got dict"):
        Diagnoser().fit(flight, model={})
    with pytest.raises(NotFittedError, match=r"not fitted yet"):
        Diagnoser().summary()
    with pytest.raises(IdentifiabilityError, match=r"interval"):
        Diagnoser().fit(_flight(seed=1, duration=1.5))
    with pytest.raises(ValueError, match=r"shifts must be 3 finite seconds"):
        shift_inputs(flight, (0.1, 0.2))


def test_residual_tests_on_known_signals():
    rng = np.random.default_rng(0)
    white = rng.standard_normal(4000)
    assert whiteness(white, 20).white
    coloured = np.convolve(white, np.ones(10) / 10, mode="same")
    assert not whiteness(coloured, 20).white
    u = rng.standard_normal(4000)
    e = np.roll(u, 5) + 0.5 * rng.standard_normal(4000)  # the input leads the residual by 5 samples
    cc = cross_correlation(e, {"u": u, "other": rng.standard_normal(4000)}, 10)
    assert cc.significant() == ["u"]
    assert cc.summary(0.1)["u"]["signal_leads"]["lag_s"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match=r"max_lag must be in \[0, 3999\] for 4000 samples, got 4000"):
        whiteness(white, 4000)
    t, p = paired_log_test(np.full(20, 2.0) + rng.random(20) * 0.1, np.ones(20))
    assert t > 10 and p < 1e-6
