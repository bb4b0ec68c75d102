"""The argparse types every ``heli`` sub-command checks its numbers with."""

from __future__ import annotations

import argparse

import pytest

from heli_cli.argtypes import number, whole
from heli_cli.main import main


@pytest.mark.parametrize("text,value", [("0.5", 0.5), ("1e-3", 1e-3)])
def test_number_accepts_values_inside_open_bounds(text, value):
    assert number("x", 0.0, 1.0)(text) == value


@pytest.mark.parametrize("text", ["0", "1", "-2", "nan", "inf", "abc", ""])
def test_number_rejects_bounds_non_finite_and_text(text):
    with pytest.raises(argparse.ArgumentTypeError, match=rf"expected a fraction, got {text!r}"):
        number("a fraction", 0.0, 1.0)(text)


def test_closed_lower_bound():
    assert number("x", 0.0, low_open=False)("0") == 0.0
    with pytest.raises(argparse.ArgumentTypeError):
        number("x", 0.0, low_open=False)("-1e-9")


@pytest.mark.parametrize("minimum,text,ok", [(1, "1", True), (1, "0", False), (0, "0", True), (1, "2.5", False),
                                             (1, "x", False)])
def test_whole(minimum, text, ok):
    if ok:
        assert whole(minimum)(text) == int(text)
    else:
        with pytest.raises(argparse.ArgumentTypeError, match=rf"expected a whole number >= {minimum}"):
            whole(minimum)(text)


@pytest.mark.parametrize("argv", [["sweep", "--kp", "1", "--kd", "1", "--windows", "0"],
                                  ["train", "--algo", "ppo", "--timesteps", "0", "--out", "x"],
                                  ["simulate-flight", "--duration", "-1", "--out", "x.csv"],
                                  ["identify", "x.csv", "--out", "y", "--interval", "0"],
                                  ["import", "x", "--out", "y", "--rate", "-3"],
                                  ["diagnose", "x", "--out", "y", "--alpha", "2"],
                                  ["diagnose", "x", "--out", "y", "--folds", "1"],
                                  ["evaluate", "x", "--episodes-per-trace", "0"],
                                  ["refresh", "m", "f.csv", "--bootstrap", "1"],
                                  ["refresh", "m", "f.csv", "--min-change", "-0.1"],
                                  ["design", "--phase-margin", "180"],
                                  ["simulate-flight", "--seed", "-1", "--out", "x.csv"],
                                  ["sweep", "--kp", "1", "--kd", "1", "--seed", "-1"]])
def test_commands_reject_bad_numbers_with_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    assert "expected" in capsys.readouterr().err
