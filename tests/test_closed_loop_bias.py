"""scripts/closed_loop_bias.py: the study of docs/method.md's closed-loop damping bias runs and reports."""

from __future__ import annotations

import pytest


def test_the_study_reports_each_damping_over_its_flights(capsys, load_script):
    study = load_script("closed_loop_bias")
    assert study.main(["--seeds", "2", "--duration", "60", "--workers", "1", "--gyro", "0.01",
                       "--set", "pilot_bandwidth=1.5"]) == 0
    out = capsys.readouterr().out
    assert "paper, cell independent, gyro 0.01 rad/s, wind, hold 1, {'pilot_bandwidth': 1.5}; 2 flights" in out
    for k in ("k3", "k7", "k11"):
        line = next(line for line in out.splitlines() if line.startswith(f"- {k}: mean error "))
        assert abs(float(line.split("mean error ")[1].split(" %")[0])) < 30.0  # a fit, not a failure


def test_a_setting_that_is_not_field_equals_value_is_refused(capsys, load_script):
    with pytest.raises(SystemExit):
        load_script("closed_loop_bias").main(["--set", "pilot_bandwidth"])
    assert "expected FIELD=VALUE" in capsys.readouterr().err
