"""``heli evaluate PARAMS --firmware F``: the firmware's own loop, from its parameter file, flown by the one evaluator."""

import json

import pytest

from heli_cli.main import main

QUICK = ["--episodes-per-trace", "1", "--episode-seconds", "2", "--no-plots"]


@pytest.fixture()
def ap_params(tmp_path):
    path = tmp_path / "flown.param"
    path.write_text("ATC_ANG_RLL_P,4.5\nATC_RAT_RLL_P,0.05\nATC_ANG_PIT_P,4.5\n")
    return path


def test_a_parameter_file_is_flown_as_the_firmware_loop_the_library_flies(ap_params, tmp_path, capsys):
    """The command's figures are evaluate_firmware's on the same windows (the loop at its 400 Hz, the model's
    stick signs, the given scale); robustness flies the same loop off the model; the default scale is said."""
    from controllers.evaluate import EvaluationConfig
    from controllers.firmware.ardupilot_params import read_ardupilot_values
    from controllers.firmware.firmwares import FIRMWARES
    from controllers.firmware.loop_rate_env import evaluate_firmware
    from controllers.firmware.tune import control_signs
    from controllers.trace_split import split_traces
    from heli_env.env_model import load_env_model

    out = tmp_path / "ev"
    assert main(["evaluate", str(ap_params), "--firmware", "ardupilot", "--scale", "0.8", "--robustness",
                 "--out", str(out), *QUICK]) == 0
    printed = capsys.readouterr().out
    assert "flown.param (ardupilot loop at 400 Hz)" in printed and "+20 ms servo delay" in printed
    doc = json.loads((out / "evaluation.json").read_text())
    env_model = load_env_model(None)
    spec = FIRMWARES["ardupilot"]
    params, _ = spec.params_from(read_ardupilot_values(ap_params)[0], str(ap_params), True)
    loop = spec.loop_class(params, (0.8,) * 3, control_signs(env_model.params))
    config = EvaluationConfig(traces="held-out", episodes_per_trace=1, episode_seconds=2.0, seed=0,
                              split=split_traces(env_model.n_traces, seed=0))
    res = evaluate_firmware(loop, env_model, config)
    assert doc["kind"] == "ardupilot" and doc["settings"]["agent"] == "ardupilot attitude loop at 400 Hz"
    for axis in ("roll", "pitch", "yaw"):
        assert doc["summary"]["axes"][axis]["att_p90_deg"] == pytest.approx(res.metrics[axis]["att_p90_deg"],
                                                                            rel=1e-12)
    robust = json.loads((out / "robustness.json").read_text())["cases"]
    assert list(robust) == ["nominal", "+20 ms servo delay", "gain -20 %", "gain +20 %"]
    assert robust["nominal"]["p90_deg"]["roll"] == pytest.approx(res.metrics["roll"]["att_p90_deg"], rel=1e-12)
    assert main(["evaluate", str(ap_params), "--firmware", "ardupilot", "--out", str(tmp_path / "d"), *QUICK]) == 0
    assert "note: command scale: no --scale given" in capsys.readouterr().out


@pytest.mark.parametrize("argv, match", [
    (["--scale", "2"], "--scale is the firmware's command scale: give it with --firmware"),
    (["--firmware", "rotorflight"], "an ArduPilot parameter file (line 1"),
    (["--firmware", "ardupilot", "MISSING"], "no such parameter file or log"),
])
def test_a_firmware_evaluation_with_bad_input_ends_in_one_line(ap_params, tmp_path, capsys, argv, match):
    """Refused in one line on stderr, exit 2, before any work: nothing written."""
    out = tmp_path / "out"
    agent = [str(tmp_path / "missing.param")] if "MISSING" in argv else [str(ap_params)]
    argv = [a for a in argv if a != "MISSING"]
    assert main(["evaluate", *agent, *argv, "--out", str(out), *QUICK]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0], err
    assert not out.exists() or not any(out.iterdir())
