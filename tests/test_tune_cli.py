"""``heli tune``: bad input ends in one line and exit 2 with nothing written; a run writes every promised file."""

import json
from pathlib import Path

import pytest

from heli_cli.main import main

import firmware_plain_loop as plain

LOGS = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "logs"


@pytest.fixture()
def ap_params(tmp_path):
    path = tmp_path / "flown.param"
    path.write_text("ATC_ANG_RLL_P,4.5\nATC_RAT_RLL_P,0.05\nATC_ANG_PIT_P,4.5\n")
    return path


def _refused(argv, capsys, match, out):
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and match in err[0], err
    assert not Path(out).exists() or not any(Path(out).iterdir())


@pytest.mark.parametrize("content, match", [
    ("ATC_RAT_RLL_PP,0.1\n", "unknown parameter 'ATC_RAT_RLL_PP'"),
    ("ATC_RAT_RLL_P,0.9\n", "outside ArduPilot's documented range"),
    ("ATC_RAT_RLL_P 0.1 7\n", "expected 'NAME,VALUE'"),
])
def test_bad_parameter_files_are_refused(tmp_path, capsys, flight_csv, ideal_model_dir, content, match):
    params = tmp_path / "bad.param"
    params.write_text(content)
    out = tmp_path / "out"
    _refused(["tune", str(flight_csv), "--firmware", "ardupilot", "--model", str(ideal_model_dir), "--params",
              str(params), "--out", str(out)], capsys, match, out)


def test_a_csv_flight_without_params_is_refused(tmp_path, capsys, flight_csv, ideal_model_dir):
    out = tmp_path / "out"
    _refused(["tune", str(flight_csv), "--firmware", "rotorflight", "--model", str(ideal_model_dir), "--out",
              str(out)], capsys, "a CSV flight holds no parameters: give the gains the aircraft flew with --params",
             out)


@pytest.mark.skipif(not LOGS.is_dir(), reason="the shared real-log fixtures are absent")
def test_a_log_of_the_other_firmware_is_refused(tmp_path, capsys, ideal_model_dir):
    out = tmp_path / "out"
    _refused(["tune", str(LOGS / "ardupilot_copter_log171.bin"), "--firmware", "rotorflight", "--model",
              str(ideal_model_dir), "--out", str(out)], capsys, "ardupilot-dataflash log, not rotorflight's", out)


@pytest.mark.parametrize("firmware, content, match", [
    ("rotorflight", "ATC_RAT_RLL_P,0.05\nATC_ANG_RLL_P,4.5\n", "an ArduPilot parameter file (line 1"),
    ("rotorflight", "# nothing\nsave\n", "no 'set name = value' line"),
    ("ardupilot", "set roll_p_gain = 50\n", "a Rotorflight CLI line"),
    ("ardupilot", "# only a comment\n", "no 'NAME,VALUE' line"),
])
def test_the_other_firmwares_file_or_an_empty_one_is_refused(tmp_path, capsys, flight_csv, ideal_model_dir, firmware,
                                                              content, match):
    """A parameter file of the other firmware, or one without any setting, would tune from the defaults in silence."""
    params = tmp_path / "flown.txt"
    params.write_text(content)
    out = tmp_path / "out"
    _refused(["tune", str(flight_csv), "--firmware", firmware, "--model", str(ideal_model_dir), "--params",
              str(params), "--out", str(out)], capsys, match, out)


@pytest.mark.parametrize("content, match", [
    (b"time,p\nfoo,bar\n", "FlightLogError"),
    (b"\x9aX\x89y\xf2<\xda\x99" * 50, "LogFormatError: "),
])
def test_with_model_and_params_the_log_is_still_read(tmp_path, capsys, ideal_model_dir, ap_params, content, match):
    """LOG gives the scale and what the log flew even when --model and --params give the rest: a file that does not
    read as a flight is refused before any work, as it is without them."""
    log = tmp_path / "flight.csv"
    log.write_bytes(content)
    out = tmp_path / "out"
    _refused(["-q", "tune", str(log), "--firmware", "ardupilot", "--model", str(ideal_model_dir), "--params",
              str(ap_params), "--scale", "12", "--out", str(out)], capsys, match, out)


@pytest.mark.skipif(not LOGS.is_dir(), reason="the shared real-log fixtures are absent")
def test_a_log_of_another_firmware_gives_neither_scale_nor_flown_errors(flight_csv):
    """Given with --params, another firmware's log is a flight: its output units and attitude target are not the
    tuned firmware's, so neither the scale nor 'what the log flew' is taken from it."""
    from argparse import Namespace

    from controllers.firmware.firmwares import FIRMWARES
    from heli_cli.tune import _own_log

    ap = Namespace(log=str(LOGS / "ardupilot_copter_log171.bin"))
    rf = Namespace(log=str(LOGS / "rotorflight_k110_LOG246.TXT"))
    assert _own_log(ap, FIRMWARES["ardupilot"]) is None and _own_log(rf, FIRMWARES["rotorflight"]) is None
    assert "not rotorflight's" in _own_log(ap, FIRMWARES["rotorflight"])
    assert "not ardupilot's" in _own_log(rf, FIRMWARES["ardupilot"])
    assert _own_log(Namespace(log=str(flight_csv)), FIRMWARES["rotorflight"]) is None


def test_a_missing_model_and_a_bad_scale_are_refused(tmp_path, capsys, flight_csv, ap_params):
    out = tmp_path / "out"
    _refused(["tune", str(flight_csv), "--firmware", "ardupilot", "--model", str(tmp_path / "nope"), "--params",
              str(ap_params), "--out", str(out)], capsys, "no such model directory", out)
    with pytest.raises(SystemExit) as e:
        main(["tune", str(flight_csv), "--firmware", "ardupilot", "--params", str(ap_params), "--out", str(out),
              "--scale", "1,2"])
    assert e.value.code == 2


def test_the_servo_lag_option_takes_identifys_words_or_seconds(tmp_path, capsys, flight_csv, ap_params):
    from heli_cli.argtypes import servo_lag

    assert [servo_lag(w) for w in ("detect", "auto", "none", "0.03")] == ["detect", "auto", "none", 0.03]
    with pytest.raises(SystemExit) as e:
        main(["tune", str(flight_csv), "--firmware", "ardupilot", "--params", str(ap_params), "--out",
              str(tmp_path / "out"), "--servo-lag", "2"])
    assert e.value.code == 2 and "servo lag" in capsys.readouterr().err and not (tmp_path / "out").exists()


def test_tune_identifies_a_log_with_identifys_settings(monkeypatch, flight_csv, ap_params):
    """Without --model, ``heli tune LOG`` fits the model ``heli identify LOG`` would write: the same timing
    defaults and the closed-loop check (it fitted with --delay auto and no check before), each option passed on."""
    from heli_cli.identify import closed_loop_mode, ml_settings
    from heli_cli.main import build_parser

    monkeypatch.delenv("HELI_CLOSED_LOOP", raising=False)
    parse = build_parser().parse_args

    def settings(*words):
        args = parse(list(words))
        return ml_settings(args, closed_loop_mode(args))

    tune = ("tune", str(flight_csv), "--firmware", "ardupilot", "--params", str(ap_params), "--out", "t")
    identify = ("identify", str(flight_csv), "--out", "m")
    assert settings(*tune) == settings(*identify)
    assert settings(*tune)["closed_loop"] == "auto" and settings(*tune)["delay"] == "detect"
    for option, value, key, expected in (("--delay", "auto", "delay", "auto"), ("--delay", "none", "delay", None),
                                         ("--servo-lag", "0.03", "servo_lag", 0.03),
                                         ("--closed-loop", "off", "closed_loop", None)):
        assert settings(*tune, option, value)[key] == expected == settings(*identify, option, value)[key]


def test_a_misspelt_closed_loop_variable_is_refused_before_any_work(tmp_path, capsys, monkeypatch, flight_csv,
                                                                     ap_params):
    monkeypatch.setenv("HELI_CLOSED_LOOP", "of")
    out = tmp_path / "out"
    _refused(["tune", str(flight_csv), "--firmware", "ardupilot", "--params", str(ap_params), "--out", str(out)],
             capsys, "HELI_CLOSED_LOOP must be one of auto, report, off; got 'of'", out)


def test_a_loop_rate_the_gusts_cannot_hold_is_refused(tmp_path, capsys, flight_csv, ideal_model_dir):
    params = tmp_path / "p.param"
    params.write_text("SCHED_LOOP_RATE,250\n")
    out = tmp_path / "out"
    _refused(["tune", str(flight_csv), "--firmware", "ardupilot", "--model", str(ideal_model_dir), "--params",
              str(params), "--out", str(out)], capsys, "whole multiple of the control rate", out)


@pytest.mark.slow
def test_tune_writes_the_files_and_the_plain_loop_flies_them(tmp_path, capsys, flight_csv, ideal_model_dir,
                                                              ap_params):
    """A whole run on the ideal model (about 7 s): the promised files and keys, margins kept, the proposed gains
    within the documented ranges and the file as the plain loop reads it equal to what was predicted
    (scripts/firmware_tune_check.py flies it)."""
    out = tmp_path / "out"
    assert main(["-q", "tune", str(flight_csv), "--firmware", "ardupilot", "--model", str(ideal_model_dir),
                 "--params", str(ap_params), "--out", str(out), "--scale", "12,12,2", "--window", "10",
                 "--no-plots", "--candidates", "2"]) == 0
    doc = json.loads((out / "tune.json").read_text())
    for axis in ("roll", "pitch", "yaw"):
        row = doc["axes"][axis]
        for label in ("current", "default", "proposed"):
            assert {"p50_deg", "p90_deg", "p99_deg", "p90_deg_interval", "gain_margin_db", "phase_margin_deg",
                    "gains"} <= set(row[label])
        assert row["proposed"]["gain_margin_db"] >= 6.0 and row["proposed"]["phase_margin_deg"] >= 45.0
    assert doc["loop_rate_hz"] == 400.0 and doc["command_scale"]["roll"] == 12.0
    for name in ("ardupilot.param", "ardupilot.current.param", "tune.md", "tune.html"):
        assert (out / name).is_file()
    assert "Flight-test card" in (out / "tune.md").read_text()
    values = plain.read_param_file(out / "ardupilot.param")
    assert 3.0 <= values["ATC_ANG_RLL_P"] <= 12.0 and 0.0 <= values["ATC_RAT_RLL_P"] <= 0.35
    assert values == pytest.approx(doc["written_values"])


@pytest.mark.skipif(not LOGS.is_dir(), reason="needs ../shared/fixtures/logs (the shared fixtures are absent)")
def test_a_log_the_airborne_detection_misses_is_tuned_with_segment(tmp_path, capsys, monkeypatch):
    """A Rotorflight log with no airborne segment found is refused in one line advising tune's own --segment;
    with ``--segment all`` the whole log is identified (the gains stay read from the log: the way round through
    ``heli import`` would lose them)."""
    import identification.workflows.identify as workflow

    log, out = LOGS / "rotorflight_k110_LOG246.TXT", tmp_path / "out"
    _refused(["tune", str(log), "--firmware", "rotorflight", "--out", str(out), "-q"], capsys, "pass --segment all", out)
    seen = []

    def identify(flights, folder, **kwargs):
        seen.append(flights[0])
        raise KeyboardInterrupt

    monkeypatch.setattr(workflow, "identify_and_report", identify)
    assert main(["tune", str(log), "--firmware", "rotorflight", "--segment", "all", "--out", str(out)]) == 130
    assert seen and seen[0].duration > 15.0 and seen[0].metadata["segment_mode"] == "all"
    with pytest.raises(SystemExit) as e:
        main(["tune", str(log), "--firmware", "rotorflight", "--segment", "5:2", "--out", str(out)])
    assert e.value.code == 2 and "T0 < T1" in capsys.readouterr().err
