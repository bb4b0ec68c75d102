"""The gains the aircraft flew: ArduPilot PARM messages and parameter files, Rotorflight headers and CLI files,
the older names, the files written back, and the command scale."""

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from controllers.firmware import ArduPilotHeliParams, RotorflightParams
from controllers.firmware.ardupilot_params import (ardupilot_names, ardupilot_params, clamp_to_ranges,
                                                   parse_param_text, read_ardupilot_values, write_ardupilot_param)
from controllers.firmware.errors import FirmwareParamError
from controllers.firmware.rotorflight_params import (parse_cli_text, read_rotorflight_values, rotorflight_names,
                                                     rotorflight_params, write_rotorflight_cli)
from controllers.firmware.scale import fit_scale, measure_scale

LOGS = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "logs"
needs_logs = pytest.mark.skipif(not LOGS.is_dir(), reason="the shared real-log fixtures are absent (installed copy)")


@needs_logs
def test_ardupilot_log_parm_messages_with_older_names():
    """ArduCopter 3.3's PARM messages: STB_*/RATE_* converted as ArduCopter 3.4 converts them."""
    pytest.importorskip("pymavlink")
    values, kind = read_ardupilot_values(LOGS / "ardupilot_copter_log171.bin")
    assert kind == "log" and values["STB_RLL_P"] == 9.5
    params, notes = ardupilot_params(values, "log171")
    assert params.ang_p == (9.5, 8.0, 7.0)
    assert_allclose(params.rat_p[0], 0.1288 * 1.27, rtol=1e-6)
    assert_allclose(params.rat_imax[0], 3000.0 / 4500.0)
    assert_allclose(params.rat_flte[0], 40.0)
    assert_allclose(params.gyro_filter_hz, 20.0)
    assert any("RATE_RLL_P" in n and "1.27" in n for n in notes)
    assert any("not in log171" in n and "SCHED_LOOP_RATE" in n for n in notes)


@needs_logs
def test_ardupilot_text_log_of_a_tradheli():
    values, kind = read_ardupilot_values(LOGS / "ardupilot_tradheli_v3.0_brownout.log")
    params, notes = ardupilot_params(values, "brownout")
    assert kind == "log"
    assert params.cyc_max == 4500.0 and params.gyro_filter_hz == 10.0  # H_ROL_MAX, INS_MPU6K_FILTER
    assert_allclose(params.rat_ff[0], 0.02 * 1.27)
    assert params.ang_p == (4.5, 3.5, 3.5)


@needs_logs
def test_rotorflight_blackbox_header():
    values, kind = read_rotorflight_values(LOGS / "rotorflight_k110_LOG246.TXT")
    params, notes = rotorflight_params(values, "LOG246")
    assert kind == "log"
    assert params.p == (60.0, 50.0, 40.0) and params.i == (120.0, 110.0, 50.0) and params.d == (0.0, 0.0, 50.0)
    assert params.loop_rate_hz == 2000.0  # looptime 125 us, pid_process_denom 4
    assert params.gyro_lpf1_hz == 150.0
    assert any("roll_f_gain" in n for n in notes)


@needs_logs
def test_logs_of_the_other_firmware_are_refused():
    with pytest.raises(FirmwareParamError, match="not Rotorflight's"):
        read_rotorflight_values(LOGS / "betaflight_quad_btfl_035.bbl")
    with pytest.raises(FirmwareParamError, match="not a blackbox log nor a Rotorflight CLI"):
        read_rotorflight_values(LOGS / "ardupilot_copter_log171.bin")


def test_parameter_file_formats(tmp_path):
    text = ("# Mission Planner\nATC_ANG_RLL_P,6.5\nATC_RAT_RLL_P 0.08\n"
            "1\t1\tATC_RAT_RLL_FF\t0.2\t9\nSCHED_LOOP_RATE,300\n")
    values = parse_param_text(text, "f")
    assert values == {"ATC_ANG_RLL_P": 6.5, "ATC_RAT_RLL_P": 0.08, "ATC_RAT_RLL_FF": 0.2, "SCHED_LOOP_RATE": 300.0}
    params, _ = ardupilot_params(values, "f", from_file=True)
    assert params.ang_p[0] == 6.5 and params.rat_ff[0] == 0.2 and params.loop_rate_hz == 300.0


def test_text_log_without_parameters_is_refused(tmp_path):
    path = tmp_path / "x.log"
    path.write_text("FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns\nATT, 1, 2, 3\n")
    with pytest.raises(FirmwareParamError, match="no parameter .PARM. messages.*--params"):
        read_ardupilot_values(path)


@pytest.mark.parametrize("text, match", [
    ("ATC_RAT_RLL_P\n", "expected 'NAME,VALUE'"),
    ("atc_rat_rll_p,0.1\n", "not an ArduPilot parameter name"),
    ("ATC_RAT_RLL_P,fast\n", "expected a number"),
    ("ATC_RAT_RLL_PP,0.1\n", "unknown parameter 'ATC_RAT_RLL_PP'"),
    ("ATC_ANG_RLL_Q,4\n", "unknown parameter 'ATC_ANG_RLL_Q'"),
    ("ATC_RAT_RLL_P,0.9\n", r"ATC_RAT_RLL_P = 0.9 is outside ArduPilot's documented range \[0, 0.35\]"),
])
def test_bad_ardupilot_parameter_files(text, match):
    with pytest.raises(FirmwareParamError, match=match):
        ardupilot_params(parse_param_text(text, "f.param"), "f.param", from_file=True)


def test_ardupilot_file_round_trip_and_clamp(tmp_path):
    p = ArduPilotHeliParams(ang_p=(7.5, 5.0, 4.0), rat_p=(0.12, 0.1, 0.3), rat_ff=(0.2, 0.18, 0.05))
    path = write_ardupilot_param(tmp_path / "a.param", ardupilot_names(p), ["test"])
    assert path.read_text().startswith("# test\nATC_ANG_RLL_P,7.5\n")
    values, kind = read_ardupilot_values(path)
    back, _ = ardupilot_params(values, "a.param", from_file=True)
    assert kind == "file" and back == p
    clamped, notes = clamp_to_ranges({"ATC_RAT_RLL_P": 0.5, "ATC_ANG_YAW_P": 8.0, "ATC_RAT_PIT_P": 0.1})
    assert clamped == {"ATC_RAT_RLL_P": 0.35, "ATC_ANG_YAW_P": 6.0, "ATC_RAT_PIT_P": 0.1}
    assert len(notes) == 2 and "clamped to 0.35" in notes[0]


def test_rotorflight_cli_files(tmp_path):
    text = ("# diff\nprofile 0\nset roll_p_gain = 120\nset error_limit = 20,25,40\nset angle_level_strength = 60\n"
            "profile 1\nset roll_p_gain = 999\nsave\n")
    values = parse_cli_text(text, "cli")
    assert values == {"roll_p_gain": 120.0, "error_limit": [20.0, 25.0, 40.0], "angle_level_strength": 60.0}
    params, notes = rotorflight_params(values, "cli", from_file=True)
    assert params.p[0] == 120.0 and params.error_limit == (20.0, 25.0, 40.0) and params.level_strength == 60.0
    assert any("pid_process_denom" in n for n in notes)
    p = RotorflightParams(p=(120, 90, 70), level_strength=30, error_limit=(20, 25, 40))
    path = write_rotorflight_cli(tmp_path / "rf.txt", rotorflight_names(p), ["test"])
    assert "set roll_p_gain = 120\n" in path.read_text() and path.read_text().endswith("save\n")
    back, _ = rotorflight_params(read_rotorflight_values(path)[0], "rf.txt", from_file=True)
    assert back.p == p.p and back.level_strength == 30.0 and back.error_limit == p.error_limit


@pytest.mark.parametrize("text, match", [
    ("set roll_p_gain 120\n", "expected 'set name = value'"),
    ("set roll_q_gain = 120\n", "unknown setting 'roll_q_gain'"),
    ("set roll_x_cutoff = 20\n", "unknown setting 'roll_x_cutoff'"),
    ("set roll_p_gain = 1200\n", r"roll_p_gain = 1200.0 is outside Rotorflight's range \[0, 1000\]"),
    ("set angle_level_strength = 250\n", r"outside Rotorflight's range \[0, 200\]"),
])
def test_bad_rotorflight_cli_files(text, match):
    with pytest.raises(FirmwareParamError, match=match):
        rotorflight_params(parse_cli_text(text, "cli"), "cli", from_file=True)


def test_scale_fit_recovers_a_known_scale():
    rng = np.random.default_rng(0)
    out = rng.normal(0.0, 0.2, (3, 2000))
    stick = np.array([[2.0], [0.5], [8.0]]) * out + 0.3 + rng.normal(0.0, 0.01, (3, 2000))
    s, r2 = fit_scale(stick, out)
    assert_allclose(s, [2.0, 0.5, 8.0], rtol=0.01)
    assert np.all(r2 > 0.99)


@needs_logs
def test_a_csv_flight_gets_the_stated_default_scale():
    scale = measure_scale(LOGS / "trex550_hovertest.csv", None)
    assert scale.source == "default" and scale.scale == (1.0, 1.0, 1.0) and "--scale" in scale.detail
