"""Tests of the ``heli`` command line, called through :func:`heli_cli.main.main` (in-process, for speed).

Session fixtures write one 40 s synthetic flight with ``heli simulate-flight``
and identify it twice (default; ``--coupled --no-plots``). One test runs the
installed ``heli`` console script.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from heli_cli.main import main
from heli_core.terms import BASE_PARAMS
from model_store.model_file import load_model


PRINTED = {}
"""What the ``identified`` fixture's command printed: its stdout under "out", its stderr (progress) under "err"."""


@pytest.fixture(scope="session")
def identified(flight_csv, tmp_path_factory):
    """``heli identify X.csv --out DIR`` with the defaults (decoupled model, figures, the closed-loop check)."""
    out = tmp_path_factory.mktemp("ident") / "DIR"
    saved = os.environ.pop("HELI_CLOSED_LOOP", None)  # conftest turns the check off for the other CLI tests
    stdout, stderr = io.StringIO(), io.StringIO()  # not a terminal: one progress line per stage
    try:
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            assert main(["identify", str(flight_csv), "--out", str(out)]) == 0
    finally:
        if saved is not None:
            os.environ["HELI_CLOSED_LOOP"] = saved
    PRINTED.update(out=stdout.getvalue(), err=stderr.getvalue())
    return out


def test_identify_runs_the_closed_loop_check_by_default_and_records_it(identified):
    model = _model(identified)
    assert model["identification"]["closed_loop"] == "auto"
    check = model["fit_statistics"]["closed_loop"]
    assert check["n_flights"] >= 8 and set(check["axes"]) == {"roll", "pitch", "yaw"}
    for axis, found in check["axes"].items():  # the bench's pilot sees the aircraft: every axis flown
        assert found["checked"] and found["pilots"][0]["flies_on"] == "aircraft", axis
        for name, value in found["corrected"].items():
            assert model["parameters"][name] == pytest.approx(value)
    assert "Closed-loop check (" in (identified / "report.md").read_text()


def test_a_bad_closed_loop_default_in_the_environment_is_named(flight_csv, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("HELI_CLOSED_LOOP", "sometimes")
    assert main(["identify", str(flight_csv), "--out", str(tmp_path / "m"), "--no-plots"]) == 2
    assert "HELI_CLOSED_LOOP must be one of auto, report, off; got 'sometimes'" in capsys.readouterr().err


@pytest.fixture(scope="session")
def identified_coupled(flight_csv, tmp_path_factory):
    """``heli identify X.csv --out DIR --coupled --no-plots``."""
    out = tmp_path_factory.mktemp("ident") / "DIR"
    assert main(["identify", str(flight_csv), "--out", str(out), "--coupled", "--no-plots"]) == 0
    return out


def _model(out):
    return json.loads((out / "model.json").read_text())


# ---------------------------------------------------------------------------------------- simulate-flight


def test_simulate_flight_writes_flight_truth_and_wind(flight_csv):
    folder = flight_csv.parent
    assert sorted(p.name for p in folder.iterdir()) == ["X.csv", "X.truth.json", "X.wind.csv"]
    truth = json.loads((folder / "X.truth.json").read_text())
    assert truth["seed"] == 3
    assert truth["config"]["duration"] == 40.0
    assert (folder / "X.csv").read_text().splitlines()[0] == "time,p,q,r,phi,theta,psi,lat,lon,col,ped"
    assert len((folder / "X.wind.csv").read_text().splitlines()) == 4001 + 1  # header + 40 s at 100 Hz


@pytest.mark.parametrize(
    "option, value",
    [("--duration", "-1"), ("--duration", "0"), ("--duration", "nan"), ("--wind", "-0.1"), ("--wind", "inf"),
     ("--effect", "bogus"), ("--log-every", "0"), ("--log-every", "2.5")],
)
def test_simulate_flight_rejects_bad_options(tmp_path, capsys, option, value):
    with pytest.raises(SystemExit) as exc:
        main(["simulate-flight", option, value, "--out", str(tmp_path / "f.csv")])
    assert exc.value.code == 2
    assert f"argument {option}" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_simulate_flight_refuses_a_wind_corner_its_gusts_do_not_have(tmp_path, capsys):
    """A bench cell with Gauss-Markov gusts has no corner: --wind-corner would change nothing, silently."""
    assert main(["simulate-flight", "--cell", "independent", "--wind-corner", "2", "--duration", "5",
                 "--out", str(tmp_path / "f.csv")]) == 2
    err = capsys.readouterr().err
    assert "gauss_markov (from --cell independent): add --wind-model lowpass or dryden" in err
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------- identify


def test_identify_writes_model_report_and_figures(identified):
    assert sorted(p.name for p in identified.iterdir() if not p.name.startswith(".heli-")) == [
        "attitude.png", "disturbance_distributions.png", "disturbance_profile.png", "disturbance_simulation.png",
        "disturbances", "frequency_response.png", "model.json", "rates.png", "report.html", "report.md"]
    for png in ("rates.png", "attitude.png", "frequency_response.png"):
        assert (identified / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (identified / "report.md").read_text()
    assert "![Measured vs modelled body rates](rates.png)" in report
    assert "| Truth |" in report  # the truth written beside X.csv was found


def test_model_json_schema_parameters_and_provenance(identified, flight_csv):
    doc = _model(identified)
    assert doc["schema_version"] == 1
    assert doc["structure"] == "decoupled"
    assert list(doc["parameters"]) == list(BASE_PARAMS)
    assert list(BASE_PARAMS)[0] == "k1" and list(BASE_PARAMS)[-1] == "kd3"
    (source,) = doc["provenance"]["sources"]
    assert source == {"file": "X.csv", "sha256": hashlib.sha256(flight_csv.read_bytes()).hexdigest()}
    params, _ = load_model(identified)  # what the CLI writes, the loader reads
    assert params.k2 > 0 and params.k3 > 0


def test_identify_coupled_without_plots(identified_coupled):
    assert sorted(p.name for p in identified_coupled.iterdir() if not p.name.startswith(".heli-")) == [
        "disturbances", "model.json", "report.html", "report.md"]
    assert _model(identified_coupled)["structure"] == "coupled"
    assert "rates.png" not in (identified_coupled / "report.md").read_text()


def test_identify_writes_the_disturbance_library(identified, flight_csv):
    from model_store.disturbance_library import DisturbanceLibrary

    lib = DisturbanceLibrary.open(identified)
    (trace,) = lib.load()
    assert trace.n == 4001 and abs(trace.sample_rate - 100.0) < 1e-6
    entry = lib.manifest()["traces"][0]
    assert entry["source"]["sha256"] == hashlib.sha256(flight_csv.read_bytes()).hexdigest()
    assert entry["model"]["sha256"] == hashlib.sha256((identified / "model.json").read_bytes()).hexdigest()
    assert "## Wind disturbance (eqs. 41-47)" in (identified / "report.md").read_text()


@pytest.mark.slow
def test_identifying_again_keeps_the_previous_model_and_library_version(flight_csv, tmp_path, capsys):
    out = tmp_path / "DIR"
    fast = ["--no-plots", "--method", "integral"]  # the folder's versions are the CLI's, whatever the method
    assert main(["identify", str(flight_csv), "--out", str(out), *fast]) == 0
    first = (out / "model.json").read_bytes()
    other = tmp_path / "Y.csv"
    assert main(["simulate-flight", "--duration", "30", "--seed", "4", "--out", str(other)]) == 0
    assert main(["identify", str(other), "--out", str(out), *fast]) == 0
    from model_store.disturbance_library import DisturbanceLibrary

    lib = DisturbanceLibrary.open(out)
    assert lib.versions() == [1, 2]
    assert len(lib.load(1)) == 1 and len(lib.load(2)) == 2
    (kept,) = (out / "history").iterdir()
    assert kept.read_bytes() == first
    assert "version 2" in capsys.readouterr().out


def test_identify_several_flights_pools_them(flight_csv, tmp_path):
    other = tmp_path / "Z.csv"
    assert main(["simulate-flight", "--duration", "30", "--seed", "5", "--out", str(other)]) == 0
    out = tmp_path / "DIR"
    # pooling is the CLI's, whatever the method: the integral method's fit is the fast one (ML's pooled fit:
    # tests/test_ml_estimator.py)
    assert main(["identify", str(flight_csv), str(other), "--out", str(out), "--no-plots", "--method",
                 "integral"]) == 0
    assert len(_model(out)["provenance"]["sources"]) == 2
    from model_store.disturbance_library import DisturbanceLibrary

    assert len(DisturbanceLibrary.open(out).load()) == 2


def test_identify_prints_a_summary(identified):
    out = PRINTED["out"]
    assert out.startswith("model verdict: ")  # first: whether the model can be used (issue #31)
    assert "\nidentified decoupled model from 1 flight(s) by maximum likelihood:" in out
    assert f"wrote {identified / 'model.json'}" in out


def test_identify_prints_the_numbers_before_drawing_the_figures(identified):
    lines = PRINTED["out"].splitlines()
    figures = [i for i, line in enumerate(lines) if line.endswith(".png")]
    assert figures and lines.index(f"wrote {identified / 'report.md'}") < min(figures)
    assert all((identified / name).exists() for name in ("rates.png", "attitude.png", "disturbance_simulation.png"))
    # stderr is no terminal here: one line per stage, the figures last
    stages = PRINTED["err"].splitlines()
    assert stages[0].startswith("identify: fitting the decoupled and coupled models by maximum likelihood")
    assert stages[-1] == "identify: drawing the figures ..."


def test_identify_quiet_prints_no_progress(flight_csv, tmp_path, capsys):
    assert main(["--quiet", "identify", str(flight_csv), "--out", str(tmp_path), "--no-plots", "--method",
                 "integral"]) == 0
    captured = capsys.readouterr()
    assert captured.err == "" and captured.out.startswith("model verdict: ")
    assert "\nidentified decoupled model" in captured.out


def test_identify_flight_with_nan_exits_2_naming_the_column(flight_csv, tmp_path, capsys):
    lines = flight_csv.read_text().splitlines()
    row = lines[101].split(",")  # data row 100, t = 1.00 s
    row[lines[0].split(",").index("q")] = "nan"
    lines[101] = ",".join(row)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    assert main(["identify", str(bad), "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.endswith("\n") and captured.err.count("\n") == 1  # one line, no traceback
    assert captured.err.startswith("heli identify: error: FlightLogError: ")
    assert "column 'q' has 1 non-finite values (NaN first), first at row 100 (t=1.00 s)" in captured.err
    assert not (tmp_path / "out").exists()


def test_identify_missing_file_exits_2(tmp_path, capsys):
    assert main(["identify", str(tmp_path / "nowhere.csv"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "nowhere.csv' does not exist" in err


def test_diagnose_of_a_missing_model_says_it_can_fit_its_own(flight_csv, tmp_path, capsys):
    """The README's 'heli diagnose flight.csv --model model/model.json' after identify refused the flight: one
    line that names the way on without identify (leave out --model), not only the refusal it came from."""
    assert main(["diagnose", str(flight_csv), "--model", str(tmp_path / "model" / "model.json"), "--out",
                 str(tmp_path / "diag")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "ModelFileError" in err
    assert "model.json' does not exist" in err and "leave out --model" in err
    assert not (tmp_path / "diag").exists()


def test_identify_refusal_that_alignment_cannot_mend_says_what_to_try():
    """A diverging fit the alignment does not mend (the ArduCopter fixture) advises a flight that moves the axes
    the sticks barely move: no command, as none is known to change the outcome on the same flight."""
    from identification.diagnosis.alignment_check import AlignmentFinding
    from heli_cli.identify import _weak_axes_advice

    finding = AlignmentFinding(shifts={}, delays={"roll": 0.0, "pitch": 0.51, "yaw": 0.02},
                               dampings={"roll": 198.0, "pitch": 200.0, "yaw": 2.5},
                               explained={"roll": 0.08, "pitch": 0.0, "yaw": 0.6}, physical=True, stable=False,
                               seconds=15.0)
    advice = _weak_axes_advice(finding)
    assert advice.startswith(" What to try: identify from a flight whose sticks move the aircraft on roll, pitch")
    assert "heli " not in advice
    assert _weak_axes_advice(AlignmentFinding({}, {}, {"roll": 1.0}, {"roll": 0.5}, True, False, 1.0)) == ""


@pytest.mark.parametrize(
    "option, value", [("--delay", "bogus"), ("--delay", "nan"), ("--delay", "-0.1"), ("--delay", "5"),
                      ("--interval", "nan"), ("--interval", "-1")],
)
def test_identify_rejects_bad_options(flight_csv, tmp_path, capsys, option, value):
    with pytest.raises(SystemExit) as exc:
        main(["identify", str(flight_csv), "--out", str(tmp_path / "out"), option, value])
    assert exc.value.code == 2
    assert f"argument {option}: expected" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------------------- installed script


def test_console_script_help():
    heli = Path(sys.executable).with_name("heli")
    done = subprocess.run([str(heli), "--help"], capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: heli")
    assert "simulate-flight" in done.stdout and "identify" in done.stdout


HEAVY = ("numpy", "matplotlib", "scipy", "torch", "stable_baselines3", "control", "gymnasium", "ray", "numba")


def test_building_the_parser_imports_no_heavy_package():
    # what 'heli --help' and every 'heli COMMAND --help' cost: a handler imports these when its command runs
    code = ("import sys; from heli_cli.main import build_parser; build_parser(); "
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in {set(HEAVY)!r}))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout.strip() == "[]"


def test_heli_alone_lists_every_command_on_one_line_each(capsys, monkeypatch):
    from heli_cli.main import command_names

    monkeypatch.setenv("COLUMNS", "80")
    assert main([]) == 2  # argparse's status for a missing command, but with the list instead of an error
    err = capsys.readouterr().err
    assert err.startswith("usage: heli") and "heli: error" not in err
    lines = err.splitlines()
    for name in command_names():
        line = next(ln for ln in lines if ln.split()[:1] == [name])
        assert len(line.split()) > 2 and len(line) <= 80  # a short description on the same line


def test_version_is_the_package_version(capsys):
    from importlib.metadata import version

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out == f"heli (heli-env) {version('heli-env')}\n"


def test_quiet_and_debug_are_accepted_before_and_after_the_command():
    from heli_cli.main import build_parser

    parser = build_parser()
    for argv in (["--quiet", "design"], ["design", "--quiet"], ["-q", "design"], ["design", "--no-progress"]):
        assert parser.parse_args(argv).quiet is True
    assert parser.parse_args(["design"]).quiet is False
    assert parser.parse_args(["--debug", "design"]).debug is True
    assert parser.parse_args(["design", "--debug"]).debug is True


def _crash(args):
    raise RuntimeError("something nobody expected")


def _user_mistake(args):
    from identification.errors import FlightLogError

    raise FlightLogError("column 'q' is missing")


@pytest.mark.parametrize("debug", [False, True])
def test_an_unexpected_error_is_one_line_and_a_request_to_report_it(monkeypatch, capsys, debug):
    import heli_cli.design

    monkeypatch.setattr(heli_cli.design, "run", _crash)
    assert main(["design"] + (["--debug"] if debug else [])) == 1
    err = capsys.readouterr().err
    assert "heli design: unexpected error: RuntimeError: something nobody expected\n" in err
    assert "please report it" in err
    assert ("Traceback" in err) is debug
    if not debug:
        assert err.count("\n") == 2


def test_a_user_error_stays_one_line_exit_2_and_debug_adds_the_traceback(monkeypatch, capsys):
    import heli_cli.design

    monkeypatch.setattr(heli_cli.design, "run", _user_mistake)
    assert main(["design"]) == 2
    assert capsys.readouterr().err == "heli design: error: FlightLogError: column 'q' is missing\n"
    assert main(["design", "--debug"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and err.endswith("heli design: error: FlightLogError: column 'q' is missing\n")


def test_an_output_path_under_a_file_is_one_line_and_exit_2(tmp_path, capsys):
    blocker = tmp_path / "afile"
    blocker.write_text("")
    assert main(["simulate-flight", "--duration", "10", "--out", str(blocker / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("heli simulate-flight: error:") and "afile" in err and "Traceback" not in err


def test_a_folder_refusing_new_files_is_named_by_the_path_given_not_the_temporary(monkeypatch, tmp_path, capsys):
    import tempfile

    def refuse(prefix, suffix, dir):  # what a read-only folder does to a user who is not root
        raise PermissionError(13, "Permission denied", f"{dir}/{prefix}abc123{suffix}")

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    out = tmp_path / "flights" / "f.csv"
    assert main(["simulate-flight", "--duration", "10", "-q", "--out", str(out)]) == 2
    assert capsys.readouterr().err == f"heli simulate-flight: error: Permission denied: {out}\n"


def _out_of_memory(args):
    import numpy as np

    np.empty((10**8, 10**8))  # 72 PiB: refused by the allocator at once


def test_a_request_larger_than_memory_is_one_line_with_its_size_and_leaves_no_folder(monkeypatch, tmp_path, capsys):
    import heli_cli.design

    monkeypatch.setattr(heli_cli.design, "run", _out_of_memory)
    assert main(["design", "--out", str(tmp_path / "pd")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("heli design: error: not enough memory for this request (Unable to allocate ")
    assert err.count("\n") == 1 and not (tmp_path / "pd").exists()


def test_a_constant_stick_is_an_identifiability_error_naming_the_stick(tmp_path, capsys):
    from identification.integral.method import IntegralIdentifier
    from identification.errors import IdentifiabilityError
    from identification.io import write_csv_flight
    from identification.bench.synthetic import simulate_flight

    flight = simulate_flight(30, seed=2).flight
    sticks = flight.sticks.copy()
    sticks[0] = 0.3  # lat never moves: roll's gain and offset are one column
    flight = dataclasses.replace(flight, sticks=sticks)
    with pytest.raises(IdentifiabilityError, match=r"the lat stick is constant \(0\.3 over the whole flight\)"):
        IntegralIdentifier().fit(flight)
    path = tmp_path / "const.csv"
    write_csv_flight(flight, path)
    assert main(["identify", str(path), "--out", str(tmp_path / "m"), "--no-plots", "-q"]) == 2
    assert "IdentifiabilityError: the lat stick is constant" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()  # a failed run leaves no empty output folder


def test_simulate_flight_scales_effects_and_flies_the_manoeuvre(tmp_path, capsys):
    out = tmp_path / "m.csv"
    assert main(["simulate-flight", "--duration", "10", "--seed", "2", "--effect", "nonlinear_damping",
                 "--effect-scale", "5", "--manoeuvre", "--out", str(out), "-q"]) == 0
    assert "hidden effects: nonlinear_damping (x5)" in capsys.readouterr().out
    truth = json.loads(out.with_suffix(".truth.json").read_text())
    assert {k: truth["parameters"][k] for k in ("nld1", "nld2", "nld3")} == {"nld1": 10.0, "nld2": 10.0, "nld3": 3.0}
    assert truth["config"]["sweep_mode"] == "simultaneous"


def test_simulate_flight_logs_a_faster_world_by_sampling_it(tmp_path, capsys):
    out = tmp_path / "fast.csv"
    assert main(["simulate-flight", "--duration", "4", "--cell", "held-sticks-pd", "--log-every", "4", "--out", str(out),
                 "-q"]) == 0
    printed = capsys.readouterr().out
    assert "401 samples at 100 Hz" in printed
    assert "held over each sample" not in printed  # the link held them at 400 Hz, not the log's samples
    truth = json.loads(out.with_suffix(".truth.json").read_text())
    assert truth["config"]["log_every"] == 4 and truth["config"]["sample_rate"] == 100.0


def test_simulate_flight_refuses_a_faster_world_larger_than_the_memory(tmp_path, capsys, monkeypatch):
    import heli_cli.argtypes as argtypes

    monkeypatch.setattr(argtypes, "available_memory", lambda: 5_000_000)  # 4 s fit; 4 s of a 16x world do not
    out = tmp_path / "f.csv"
    assert main(["simulate-flight", "--duration", "4", "--log-every", "16", "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert "--log-every 16 flies a 1600 Hz world for 4 s" in err and "available" in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_simulate_flight_logs_at_the_rate_asked_and_refuses_what_it_cannot(tmp_path, capsys, monkeypatch):
    """``--rate``: the log's sample rate (the world steps at it, or --log-every times faster); a rate outside
    10-2000 Hz, a gust corner above its Nyquist frequency and a flight too large for the memory are refused in one
    line, nothing written."""
    import heli_cli.argtypes as argtypes

    out = tmp_path / "f.csv"
    assert main(["simulate-flight", "--duration", "4", "--rate", "25", "--log-every", "2", "--out", str(out), "-q"]) == 0
    assert "101 samples at 25 Hz" in capsys.readouterr().out
    truth = json.loads(out.with_suffix(".truth.json").read_text())
    assert truth["config"]["sample_rate"] == 25.0 and truth["config"]["log_every"] == 2
    for option in (["--rate", "5"], ["--rate", "3000"], ["--rate", "fast"]):
        with pytest.raises(SystemExit):
            main(["simulate-flight", *option, "--out", str(tmp_path / "g.csv")])
        assert "a log rate in Hz from 10 to 2000" in capsys.readouterr().err
    assert main(["simulate-flight", "--duration", "4", "--rate", "20", "--wind-model", "dryden", "--wind-corner", "12",
                 "--out", str(tmp_path / "h.csv"), "-q"]) == 2
    assert "not below the Nyquist frequency of a 20 Hz log (10 Hz)" in capsys.readouterr().err
    monkeypatch.setattr(argtypes, "available_memory", lambda: 5_000_000)  # 4 s at 100 Hz fit; at 1600 Hz not
    assert main(["simulate-flight", "--duration", "4", "--rate", "1600", "--out", str(tmp_path / "i.csv"), "-q"]) == 2
    assert "--rate 1600 flies a 1600 Hz world for 4 s" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in tmp_path.glob("f.*"))


def test_a_flight_logged_too_slowly_for_the_prefilter_is_named(tmp_path, capsys):
    from identification.io import write_csv_flight
    from identification.bench.synthetic import simulate_flight

    flight = simulate_flight(120, seed=3).flight
    slow = dataclasses.replace(flight, time=flight.time[::50], rates=flight.rates[:, ::50],
                               attitude=flight.attitude[:, ::50], sticks=flight.sticks[:, ::50])  # 2 Hz
    path = write_csv_flight(slow, tmp_path / "slow.csv")
    assert main(["identify", str(path), "--out", str(tmp_path / "m"), "--method", "integral", "--no-plots",
                 "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("heli identify: error: FlightLogError: the flight is sampled at 2 Hz")
    assert "--no-filter" in err and err.count("\n") == 1


def test_simulate_flight_lists_the_bench_cells_and_effects_the_library_has():
    # written out in heli_cli so that 'heli --help' needs no numpy; they must stay the library's names
    from heli_cli import simulate_flight as cli
    from identification.bench.cells import BENCH_CELLS
    from identification.bench.flight_config import EFFECT_ALIASES, EFFECTS

    assert cli.CELL_NAMES == tuple(BENCH_CELLS)
    assert cli.EFFECT_NAMES == tuple(EFFECTS) and cli.EFFECT_ALIAS_NAMES == tuple(EFFECT_ALIASES)


@pytest.mark.parametrize("option, likelihood_only, refusal, bad, parser_says", [
    ("--servo-lag", "auto", "--servo-lag needs", "2", "servo lag in seconds in [0, 1]"),
    ("--delay", "detect", "--delay detect needs", "sometimes",
     "expected 'detect' or 'auto' or 'none' or a delay in seconds"),
])
def test_identify_timing_options(flight_csv, tmp_path, capsys, option, likelihood_only, refusal, bad, parser_says):
    # --servo-lag and --delay detect (the likelihood's defaults) are the likelihood's: refused with the integral
    # method, naming both; a value the option does not take is refused by the parser, saying what it takes;
    # nothing is written either way
    assert main(["identify", str(flight_csv), "--out", str(tmp_path / "A"), "--method", "integral",
                 option, likelihood_only]) == 2
    assert f"{refusal} the maximum-likelihood estimator" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["identify", str(flight_csv), "--out", str(tmp_path / "B"), option, bad])
    assert parser_says in capsys.readouterr().err
    assert not (tmp_path / "A" / "model.json").exists() and not (tmp_path / "B").exists()


_LOGS = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "logs"


@pytest.mark.skipif(not _LOGS.is_dir(), reason="needs ../shared/fixtures/logs (the shared fixtures are absent)")
def test_identify_takes_the_stretch_of_a_log_the_airborne_detection_misses(tmp_path, capsys, monkeypatch):
    """A log with no airborne segment found is refused in one line advising identify's own --segment; with
    ``--segment all`` the whole log is identified, with T0:T1 that stretch."""
    import identification.workflows.identify as workflow

    log, out = _LOGS / "rotorflight_k110_LOG246.TXT", tmp_path / "out"
    assert main(["identify", str(log), "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pass --segment all" in err[0] and not out.exists(), err
    seen = []

    def identify(flights, folder, **kwargs):
        seen.append(flights[0])
        raise KeyboardInterrupt

    monkeypatch.setattr(workflow, "identify_and_report", identify)
    assert main(["identify", str(log), "--segment", "all", "--out", str(out), "-q"]) == 130
    assert main(["identify", str(log), "--segment", "20:27", "--out", str(out), "-q"]) == 130
    whole, stretch = seen
    assert whole.metadata["segment_mode"] == "all" and whole.duration > 15.0
    assert stretch.duration == pytest.approx(7.0, abs=0.05) and not out.exists()


_INTERRUPTED_TWICE = """
import atexit, sys, time
import heli_cli.design
from heli_cli.main import run

def exit_hook():  # what a worker pool's join does at exit: it takes a while
    print("exiting", file=sys.stderr, flush=True)
    time.sleep(2.0)

def design(args):
    print("ready", file=sys.stderr, flush=True)
    time.sleep(60)

atexit.register(exit_hook)
heli_cli.design.run = design
sys.argv = ["heli", "design"]
sys.exit(run())
"""


def test_a_second_ctrl_c_while_heli_exits_prints_no_traceback(tmp_path):
    """`timeout -s INT` and a double Ctrl-C send a second SIGINT; arriving in an exit hook (a pool's join) it
    printed Python's "Exception ignored" traceback after "interrupted"."""
    import signal

    script = tmp_path / "interrupted_twice.py"
    script.write_text(_INTERRUPTED_TWICE)
    env = dict(os.environ, PYTHONPATH=os.getcwd())
    process = subprocess.Popen([sys.executable, str(script)], env=env, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stderr.readline() == "ready\n"
        process.send_signal(signal.SIGINT)
        assert process.stderr.readline() == "heli design: interrupted\n"
        assert process.stderr.readline() == "exiting\n"
        process.send_signal(signal.SIGINT)
        rest = process.stderr.read()
        process.wait(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
    assert (process.returncode, rest) == (130, "")
