"""Tests of the servo-activity figures (:mod:`controllers.servo_activity`) and their place in the reports."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from controllers.evaluate_report import evaluation_markdown
from controllers.servo_activity import ACTIVITY_NAMES, activity_table, plot_servo_activity, stick_activity, \
    stick_spectrum

DT = 0.01


def _sticks(n=3000, episodes=2, seed=0):
    """(n, E, 3): roll white noise of std 0.2, pitch a slow 0.5 Hz sine of amplitude 0.3, yaw zero."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    a = np.zeros((n, episodes, 3))
    a[..., 0] = 0.2 * rng.standard_normal((n, episodes))
    a[..., 1] = 0.3 * np.sin(2 * np.pi * 0.5 * t)[:, None]
    return a


def test_white_chatter_and_a_smooth_stick_are_told_apart():
    """White noise steps by sqrt(2) sigma per period with most variance above 10 Hz; a slow sine barely steps."""
    act = _sticks()
    m = stick_activity(act, np.array([3000, 3000]), DT)
    assert set(m["roll"]) == set(ACTIVITY_NAMES)
    assert_allclose(m["roll"]["stick_rms"], 0.2, rtol=0.03)
    assert_allclose(m["roll"]["stick_step_rms"], 0.2 * np.sqrt(2), rtol=0.03)
    assert_allclose(m["roll"]["stick_hf_fraction"], 0.8, atol=0.03)  # 40 of the 50 Hz band
    assert_allclose(m["pitch"]["stick_step_rms"], 0.3 * 2 * np.pi * 0.5 * DT / np.sqrt(2), rtol=0.02)
    assert m["pitch"]["stick_hf_fraction"] < 1e-3
    assert m["yaw"]["stick_rms"] == 0.0 and np.isnan(m["yaw"]["stick_hf_fraction"])


def test_episodes_count_up_to_their_end_only():
    """Samples after an episode ended (zeros here) are not counted, and no step spans two episodes."""
    act = _sticks(episodes=2)
    act[1500:, 1] = 0.0
    m = stick_activity(act, np.array([3000, 1500]), DT)
    full = stick_activity(act[:, :1], np.array([3000]), DT)
    assert_allclose(m["roll"]["stick_rms"], full["roll"]["stick_rms"], rtol=0.05)
    freq, psd = stick_spectrum(act, np.array([3000, 1500]), DT)
    assert freq[-1] == pytest.approx(50.0) and psd.shape == (3, freq.size)
    with pytest.raises(ValueError, match=r"action must be \(steps, episodes, 3\)"):
        stick_activity(act[..., :2], np.array([3000, 1500]), DT)


def test_evaluation_reports_and_draws_the_servo_activity(tmp_path):
    """An evaluated PD carries its activity (report table, JSON summary) and draws servo.png beside another."""
    from controllers.evaluate import evaluate_agent
    from controllers.pd import PDController, PDGains, design_gains
    from heli_env import load_env_model

    shipped = load_env_model()
    gains = design_gains(shipped.params)
    runs = [evaluate_agent(PDController.from_model(shipped.params, g), shipped, episodes_per_trace=1,
                           episode_seconds=3.0, name=name)
            for name, g in (("plain", gains), ("filtered", PDGains(gains.kp, gains.kd, 5.0)))]
    assert runs[1].activity["pitch"]["stick_step_rms"] < 0.6 * runs[0].activity["pitch"]["stick_step_rms"]
    assert "RMS stick step per period" in evaluation_markdown(runs[0])
    assert runs[0].summary()["servo_activity"]["roll"]["stick_step_rms"] > 0
    assert "| filtered | yaw |" in activity_table(runs)
    path = plot_servo_activity(runs, tmp_path / "servo.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
