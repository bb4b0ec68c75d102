"""The argparse types every ``heli`` sub-command checks its numbers with."""

from __future__ import annotations

import argparse
import re

import pytest

from heli_cli.argtypes import number, seconds_or, whole
from heli_cli.main import main


@pytest.mark.parametrize("text,value", [("0.5", 0.5), ("1e-3", 1e-3)])
def test_number_accepts_values_inside_open_bounds(text, value):
    assert number("x", 0.0, 1.0)(text) == value


@pytest.mark.parametrize("text", ["0", "1", "-2", "nan", "inf", "abc", ""])
def test_number_rejects_bounds_non_finite_and_text(text):
    with pytest.raises(argparse.ArgumentTypeError, match=rf"expected a fraction, got {text!r}"):
        number("a fraction", 0.0, 1.0)(text)


def test_seconds_or_takes_its_words_and_seconds_within_closed_bounds():
    # --delay and --servo-lag of heli identify and heli tune
    parse = seconds_or(("detect", "none"), "delay", 2.0)
    assert parse("detect") == "detect" and parse("none") == "none"
    assert parse("0") == 0.0 and parse("2") == 2.0 and parse("0.08") == 0.08
    for text in ("auto", "-0.01", "2.5", "nan", "inf", ""):
        with pytest.raises(argparse.ArgumentTypeError,
                           match=re.escape(f"expected 'detect' or 'none' or a delay in seconds in [0, 2], got {text!r}")):
            parse(text)


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


# ------------------------------------------------------------------ hostile inputs (issue 15)
def test_whole_with_a_maximum():
    from heli_cli.argtypes import whole

    assert whole(2, 12)("12") == 12
    for text in ("13", "1", "1e9"):
        with pytest.raises(argparse.ArgumentTypeError, match=rf"expected a whole number from 2 to 12, got {text!r}"):
            whole(2, 12)(text)


def test_diagnose_folds_bound_is_the_diagnosers_minimum_of_windows():
    """--folds above Diagnoser.min_windows ended in 'ValueError: Diagnoser.min_windows out of range' (exit 1)."""
    from identification.diagnosis.heldout_diagnoser import MIN_WINDOWS

    assert MIN_WINDOWS == 12  # the bound written in heli_cli/diagnose.py


@pytest.mark.parametrize("text", ["-1", "4294967296", "99999999999999999999", "1e3", "x"])
def test_seed_is_what_numpy_accepts(text):
    from heli_cli.argtypes import seed

    with pytest.raises(argparse.ArgumentTypeError, match=r"expected a whole number from 0 to 4294967295"):
        seed()(text)


@pytest.mark.parametrize("text", ["", "-1", "1,,1", "a,b", "4294967296"])
def test_seed_list_refuses_negatives_duplicates_and_text(text):
    from heli_cli.argtypes import seed_list

    with pytest.raises(argparse.ArgumentTypeError, match=r"expected distinct whole numbers from 0 to 4294967295"):
        seed_list(text)
    assert seed_list("0,3,2") == [0, 3, 2]


def test_output_path_refuses_an_empty_path():
    from heli_cli.argtypes import output_path

    with pytest.raises(argparse.ArgumentTypeError, match=r"expected a path to write to, got ' '"):
        output_path(" ")
    assert output_path("a.csv") == "a.csv"


def test_affordable_refuses_a_request_larger_than_memory_naming_its_size():
    from heli_cli.argtypes import affordable

    parse = affordable("a flight length in seconds > 0", 1000.0, "s", memory=lambda: 2**30)
    assert parse("1000") == 1000.0
    with pytest.raises(argparse.ArgumentTypeError,
                       match=r"expected a flight length in seconds > 0; 1e7 s would need about 9\.31 GiB of "
                             r"memory and 1 GiB are available"):
        parse("1e7")
    for text in ("0", "nan", "inf", "-1"):
        with pytest.raises(argparse.ArgumentTypeError, match=rf"got {text!r}"):
            parse(text)


@pytest.mark.parametrize("argv, message", [
    (["simulate-flight", "--duration", "1e9", "--out", "x.csv"], r"1e9 s would need about .* GiB of memory"),
    (["simulate-flight", "--duration", "1e300", "--out", "x.csv"], r"1e300 s would need about .* GiB of memory"),
    (["simulate-flight", "--out", ""], r"expected a path to write to, got ''"),
    (["simulate-flight", "--wind-corner", "1e300", "--out", "x.csv"], r"below 50 \(Nyquist"),
    (["simulate-flight", "--reaction-delay", "1e300", "--out", "x.csv"], r"seconds from 0 to 5"),
    (["simulate-flight", "--seed", "99999999999999", "--out", "x.csv"], r"from 0 to 4294967295"),
    (["diagnose", "x.csv", "--out", "y", "--folds", "100000"], r"from 2 to 12"),
    (["train", "--algo", "ppo", "--timesteps", "8", "--out", "a", "--seeds", "-1"], r"from 0 to 4294967295"),
    (["evaluate", "a.json", "--episode-seconds", "1e-9"], r"seconds >= 0\.01 \(one control period\)"),
    (["sweep", "--kp", "1", "--kd", "1", "--out", ""], r"expected a path to write to"),
])
def test_hostile_numbers_end_in_argparse_exit_2(argv, message, capsys, tmp_path, monkeypatch):
    """Each ended in 'unexpected error' (exit 1) before: a ValueError or OverflowError deep in the work."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    assert re.search(message, capsys.readouterr().err)
    assert not any(tmp_path.iterdir())
