"""Run ``heli`` on a list of hostile-but-fair inputs; count tracebacks, unexpected errors and timeouts.

Issue 15's target: **no traceback for any input**. Every case is a real ``heli`` command in a subprocess (with
a timeout and a cap on its address space, so a request for absurd memory cannot take the machine down). A case
may succeed (exit 0) or be refused (exit 2, one line naming what is wrong); it must never end in a traceback,
the "unexpected error ... please report" of exit 1, a multi-line error, or the timeout::

    python scripts/hostile_inputs.py                 # every case, 2 at a time
    python scripts/hostile_inputs.py --jobs 2 --only identify,import --timeout 120 --verbose

The inputs are made in a temporary folder first: synthetic flights (``heli simulate-flight --duration 30``),
a model (``heli identify --method integral``), a PD agent (``heli design``), and from them the bad ones: wrong
file kinds (a folder, an empty file, binary bytes, UTF-16), broken CSVs (truncated, NaN, gaps, time going back,
time in ms, rates in deg/s, PWM sticks, ...), output paths that are files, under a file or read-only, corrupt
model folders (a flipped byte in a trace, a truncated ``model.json``, a missing manifest) and wrong agent files;
plus bad numbers on every numeric option (negative, zero, nan, inf, 1e300, huge sizes).

Prints one Markdown table per command (cases, exit 0, exit 2 clean, exit 1 unexpected, tracebacks, timeouts),
a total, and every case that ended in exit 1, a traceback, a multi-line error or a timeout, with its command
line. Exit status 1 when any such case remains.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
COMMANDS = ("simulate-flight", "import", "identify", "diagnose", "refresh", "check", "compare-methods", "design",
            "sweep", "train", "evaluate", "tune")
MEMORY_CAP = 6 * 2**30
"""Address space of each case (bytes): a request for more ends in MemoryError instead of swapping."""

ERROR_LINE = re.compile(r"^(heli[\w -]*|usage): |^heli[\w -]*: (error|unexpected error)")


def heli_argv(*args) -> list:
    return [sys.executable, "-m", "heli_cli.main"] + [str(a) for a in args]


def run_env() -> dict:
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""),
           "MPLBACKEND": "Agg", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    env.pop("HELI_FAULT_AFTER", None)
    return env


def _cap_memory():  # pragma: no cover - runs in the child
    os.setsid()  # own process group: a timeout kills the whole case, workers included
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP, MEMORY_CAP))


# ---------------------------------------------------------------- fixtures
def _heli(tmp: Path, *args, timeout=300):
    r = subprocess.run(heli_argv("-q", *args), cwd=tmp, env=run_env(), capture_output=True, text=True,
                       timeout=timeout)
    if r.returncode != 0:
        raise SystemExit(f"fixture 'heli {' '.join(map(str, args))}' failed:\n{r.stderr}")


def _csv(path: Path, header, data, fmt="%.17g"):
    with open(path, "w") as fh:
        fh.write(",".join(header) + "\n")
        np.savetxt(fh, data, delimiter=",", fmt=fmt)
    return path


def make_fixtures(tmp: Path) -> dict:
    """The good inputs and, from them, every bad file the cases use. Returns names -> paths."""
    for seed in (1, 2, 3):
        _heli(tmp, "simulate-flight", "--duration", 30, "--seed", seed, "--out", f"f{seed}.csv")
    _heli(tmp, "identify", "f1.csv", "--out", "model", "--method", "integral", "--no-plots")
    _heli(tmp, "design", "--model", "model", "--out", "pd", "--no-plots")
    # models whose gust traces a default episode does not fit: a 15 s flight (held-out 3.7 s) and a 50 Hz log
    _heli(tmp, "simulate-flight", "--duration", 15, "--seed", 4, "--out", "short.csv")
    _heli(tmp, "identify", "short.csv", "--out", "model_short", "--method", "integral", "--no-plots")
    lines = (tmp / "f1.csv").read_text().splitlines()
    (tmp / "f50.csv").write_text("\n".join(lines[:1] + lines[1::2]) + "\n")  # every other sample: 50 Hz
    _heli(tmp, "identify", "f50.csv", "--out", "model_50hz", "--method", "integral", "--no-plots")
    _heli(tmp, "design", "--model", "model_50hz", "--out", "pd_50hz", "--no-plots")
    fx = {"good": tmp / "f1.csv", "good2": tmp / "f2.csv", "good3": tmp / "f3.csv", "model": tmp / "model",
          "pd": tmp / "pd" / "pd.json", "model_short": tmp / "model_short", "model_50hz": tmp / "model_50hz",
          "good_50hz": tmp / "f50.csv", "pd_50hz": tmp / "pd_50hz" / "pd.json"}
    good = fx["good"]
    text = good.read_text()
    header = text.splitlines()[0].split(",")
    data = np.loadtxt(good, delimiter=",", skiprows=1)
    col = {h: i for i, h in enumerate(header)}
    bad = tmp / "bad"
    bad.mkdir()

    def variant(name, fn):
        d = data.copy()
        out = fn(d)
        fx[name] = _csv(bad / f"{name}.csv", header, d if out is None else out)

    (bad / "empty.csv").write_text("")
    fx["empty"] = bad / "empty.csv"
    (bad / "binary.csv").write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 20000, dtype=np.uint8)))
    fx["binary"] = bad / "binary.csv"
    (bad / "zeros.csv").write_bytes(b"\0" * 5000)
    fx["zeros"] = bad / "zeros.csv"
    (bad / "utf16.csv").write_bytes(text.encode("utf-16"))
    fx["utf16"] = bad / "utf16.csv"
    (bad / "truncated.csv").write_text(text[: len(text) // 2])  # ends mid-line
    fx["truncated"] = bad / "truncated.csv"
    (bad / "header_only.csv").write_text(text.splitlines()[0] + "\n")
    fx["header_only"] = bad / "header_only.csv"
    (bad / "one_row.csv").write_text("\n".join(text.splitlines()[:2]) + "\n")
    fx["one_row"] = bad / "one_row.csv"
    (bad / "three_rows.csv").write_text("\n".join(text.splitlines()[:4]) + "\n")
    fx["three_rows"] = bad / "three_rows.csv"
    (bad / "crlf.csv").write_text(text.replace("\n", "\r\n"))
    fx["crlf"] = bad / "crlf.csv"
    (bad / "bom.csv").write_bytes(b"\xef\xbb\xbf" + text.encode())
    fx["bom"] = bad / "bom.csv"
    (bad / "semicolon.csv").write_text(text.replace(",", ";"))
    fx["semicolon"] = bad / "semicolon.csv"
    (bad / "tabs.csv").write_text(text.replace(",", "\t"))
    fx["tabs"] = bad / "tabs.csv"
    (bad / "decimal_comma.csv").write_text(text.replace(",", ";").replace(".", ","))
    fx["decimal_comma"] = bad / "decimal_comma.csv"
    lines = text.splitlines()
    (bad / "blank_lines.csv").write_text("\n".join(lines[:100] + ["", ""] + lines[100:]) + "\n")
    fx["blank_lines"] = bad / "blank_lines.csv"
    (bad / "text_field.csv").write_text("\n".join(lines[:50] + [lines[50].replace(lines[50].split(",")[1], "abc", 1)]
                                                  + lines[51:]) + "\n")
    fx["text_field"] = bad / "text_field.csv"
    (bad / "short_row.csv").write_text("\n".join(lines[:50] + [",".join(lines[50].split(",")[:5])] + lines[51:]) + "\n")
    fx["short_row"] = bad / "short_row.csv"
    (bad / "long_row.csv").write_text("\n".join(lines[:50] + [lines[50] + ",1,2"] + lines[51:]) + "\n")
    fx["long_row"] = bad / "long_row.csv"
    (bad / "no_header.csv").write_text("\n".join(lines[1:]) + "\n")
    fx["no_header"] = bad / "no_header.csv"
    (bad / "dup_header.csv").write_text(lines[0].replace("q", "p") + "\n" + "\n".join(lines[1:]) + "\n")
    fx["dup_header"] = bad / "dup_header.csv"
    (bad / "upper_header.csv").write_text(lines[0].upper() + "\n" + "\n".join(lines[1:]) + "\n")
    fx["upper_header"] = bad / "upper_header.csv"
    (bad / "quoted.csv").write_text("\n".join(",".join(f'"{v}"' for v in ln.split(",")) for ln in lines) + "\n")
    fx["quoted"] = bad / "quoted.csv"
    (bad / "long_line.csv").write_text(lines[0] + "\n" + "9" * 2_000_000 + "\n" + "\n".join(lines[1:]) + "\n")
    fx["long_line"] = bad / "long_line.csv"
    variant("nan", lambda d: d.__setitem__((slice(1200, 1203), col["p"]), np.nan))
    variant("nan_time", lambda d: d.__setitem__((500, col["time"]), np.nan))
    variant("inf", lambda d: d.__setitem__((700, col["lat"]), np.inf))
    variant("huge_value", lambda d: d.__setitem__((700, col["q"]), 1e300))
    variant("gap", lambda d: np.delete(d, np.s_[1000:1500], axis=0))
    variant("nonmono", lambda d: d.__setitem__((slice(800, 802), col["time"]), d[[801, 800], col["time"]]))
    variant("dup_time", lambda d: d.__setitem__((900, col["time"]), d[899, col["time"]]))
    variant("ms_time", lambda d: d.__setitem__((slice(None), col["time"]), d[:, col["time"]] * 1000))
    variant("us_time", lambda d: d.__setitem__((slice(None), col["time"]), d[:, col["time"]] * 1e6))
    variant("epoch_time", lambda d: d.__setitem__((slice(None), col["time"]), d[:, col["time"]] + 1.7e9))
    variant("negative_time", lambda d: d.__setitem__((slice(None), col["time"]), d[:, col["time"]] - 100))
    variant("deg_rates", lambda d: d.__setitem__((slice(None), slice(col["p"], col["r"] + 1)),
                                                 np.degrees(d[:, col["p"]:col["r"] + 1])))
    variant("deg_all", lambda d: d.__setitem__((slice(None), slice(col["p"], col["psi"] + 1)),
                                               np.degrees(d[:, col["p"]:col["psi"] + 1])))
    variant("pwm_sticks", lambda d: d.__setitem__((slice(None), slice(col["lat"], col["ped"] + 1)),
                                                  1500 + 500 * d[:, col["lat"]:col["ped"] + 1]))
    variant("percent_sticks", lambda d: d.__setitem__((slice(None), slice(col["lat"], col["ped"] + 1)),
                                                      100 * d[:, col["lat"]:col["ped"] + 1]))
    variant("constant_stick", lambda d: d.__setitem__((slice(None), col["lat"]), 0.2))
    variant("zero_sticks", lambda d: d.__setitem__((slice(None), slice(col["lat"], col["ped"] + 1)), 0.0))
    variant("zero_rates", lambda d: d.__setitem__((slice(None), slice(col["p"], col["psi"] + 1)), 0.0))
    variant("constant_time", lambda d: d.__setitem__((slice(None), col["time"]), 5.0))
    variant("reversed", lambda d: d[::-1])
    variant("shuffled", lambda d: d[np.random.default_rng(1).permutation(len(d))])
    variant("all_nan", lambda d: d.__setitem__((slice(None), col["p"]), np.nan))
    variant("slow_rate", lambda d: d[::50])  # 2 Hz
    variant("jitter", lambda d: d.__setitem__((slice(None), col["time"]),
                                              d[:, col["time"]] + np.random.default_rng(2).uniform(0, 0.009, len(d))))
    variant("short_flight", lambda d: d[:100])  # 1 s
    fx["no_attitude"] = _csv(bad / "no_attitude.csv", [h for h in header if h not in ("phi", "theta", "psi")],
                             np.delete(data, [col["phi"], col["theta"], col["psi"]], axis=1))
    fx["missing_p"] = _csv(bad / "missing_p.csv", [h for h in header if h != "p"], np.delete(data, col["p"], axis=1))
    fx["missing_sticks"] = _csv(bad / "missing_sticks.csv", header[: col["lat"]], data[:, : col["lat"]])
    fx["two_angles"] = _csv(bad / "two_angles.csv", [h for h in header if h != "psi"],
                            np.delete(data, col["psi"], axis=1))
    fx["extra_cols"] = _csv(bad / "extra_cols.csv", header + ["rpm", "p "], np.c_[data, data[:, :2]])
    servo = ["time", "p", "q", "r", "u_aile", "u_aux", "u_elev", "u_rudd"]
    fx["servo_no_cal"] = _csv(bad / "servo.csv", servo,
                              np.c_[data[:, :4], 1500 + 400 * data[:, col["lat"]:col["ped"] + 1]])
    # a log-like binary with a plausible extension
    for ext in ("ulg", "bin", "bbl", "bfl", "txt", "json"):
        (bad / f"garbage.{ext}").write_bytes(b"ULog\x01\x12\x35" + bytes(range(256)) * 20 if ext == "ulg"
                                             else bytes(np.random.default_rng(3).integers(0, 256, 4096, dtype=np.uint8)))
        fx[f"garbage_{ext}"] = bad / f"garbage.{ext}"
    (bad / "empty.ulg").write_bytes(b"")
    fx["empty_ulg"] = bad / "empty.ulg"
    (bad / "blackbox_header.bbl").write_text("H Product:Blackbox flight data recorder by Nicholas Sherlock\n"
                                             "H Data version:2\nH I interval:1\n")
    fx["bbl_header_only"] = bad / "blackbox_header.bbl"
    fx["dir"] = bad / "a_folder.csv"
    fx["dir"].mkdir()
    fx["missing"] = bad / "does_not_exist.csv"
    fx["fifo"] = bad / "fifo.csv"
    os.mkfifo(fx["fifo"])
    fx["symlink_loop"] = bad / "loop.csv"
    os.symlink(fx["symlink_loop"], fx["symlink_loop"])
    # calibration files for import
    (bad / "cal_garbage.json").write_text("{not json")
    fx["cal_garbage"] = bad / "cal_garbage.json"
    (bad / "cal_list.json").write_text("[1, 2, 3]")
    fx["cal_list"] = bad / "cal_list.json"
    (bad / "cal_nan.json").write_text('{"center": NaN, "range": 0}')
    fx["cal_nan"] = bad / "cal_nan.json"

    # output paths
    out = tmp / "out"
    out.mkdir()
    (out / "a_file").write_text("x")
    fx["out_file"] = out / "a_file"
    fx["out_under_file"] = out / "a_file" / "sub"
    (out / "ro").mkdir()
    os.chmod(out / "ro", 0o555)
    fx["out_ro"] = out / "ro" / "x"
    (out / "a_dir").mkdir()
    fx["out_dir"] = out / "a_dir"
    fx["out_proc"] = Path("/proc/heli-hostile-out")

    # corrupt model folders
    models = tmp / "models"
    models.mkdir()

    def model_variant(name, fn):
        d = models / name
        shutil.copytree(fx["model"], d)
        fn(d)
        fx[f"model_{name}"] = d

    def flip_trace(d):
        trace = next((d / "disturbances" / "traces").glob("*.npy"))
        b = bytearray(trace.read_bytes())
        b[len(b) // 2] ^= 0x40
        trace.write_bytes(bytes(b))

    def truncate(p, frac=0.5):
        b = p.read_bytes()
        p.write_bytes(b[: int(len(b) * frac)])

    def set_param(d, key, value):
        m = json.loads((d / "model.json").read_text())
        m["parameters"][key] = value  # the model file's key (a top-level "k2" was ignored: no corruption at all)
        (d / "model.json").write_text(json.dumps(m, allow_nan=True))

    model_variant("flipped_trace", flip_trace)
    model_variant("truncated_model", lambda d: truncate(d / "model.json"))
    model_variant("empty_model", lambda d: (d / "model.json").write_text(""))
    model_variant("model_list", lambda d: (d / "model.json").write_text("[]"))
    model_variant("model_empty_obj", lambda d: (d / "model.json").write_text("{}"))
    model_variant("no_model_json", lambda d: (d / "model.json").unlink())
    model_variant("no_manifest", lambda d: [p.unlink() for p in (d / "disturbances").glob("manifest-*.json")])
    model_variant("truncated_manifest", lambda d: [truncate(p) for p in (d / "disturbances").glob("manifest-*.json")])
    model_variant("no_traces", lambda d: shutil.rmtree(d / "disturbances" / "traces"))
    model_variant("truncated_trace", lambda d: [truncate(p, 0.3) for p in (d / "disturbances" / "traces").glob("*.npy")])
    model_variant("no_library", lambda d: shutil.rmtree(d / "disturbances"))
    model_variant("nan_param", lambda d: set_param(d, "k2", float("nan")))
    model_variant("huge_param", lambda d: set_param(d, "k3", 1e300))
    model_variant("string_param", lambda d: set_param(d, "k2", "fast"))
    model_variant("model_json_dir", lambda d: ((d / "model.json").unlink(), (d / "model.json").mkdir()))

    def set_verdict(d, verdict):
        m = json.loads((d / "model.json").read_text())
        m["verdict"] = verdict
        (d / "model.json").write_text(json.dumps(m))

    model_variant("unusable", lambda d: set_verdict(d, {"level": "unusable", "reasons": [
        "roll: damping k3 = 200 1/s is at the upper bound of the estimator's search (the data did not place it)"]}))
    model_variant("bad_verdict", lambda d: set_verdict(d, {"level": "great", "reasons": "none"}))
    fx["model_empty_dir"] = models / "empty"
    fx["model_empty_dir"].mkdir()
    fx["model_is_file"] = fx["good"]
    fx["model_missing"] = models / "nowhere"

    # wrong agent files
    agents = tmp / "agents"
    agents.mkdir()
    for name, content in {"empty.json": "", "garbage.json": "{oops", "list.json": "[1]", "obj.json": "{}",
                          "empty.zip": "", "garbage.zip": "PK\x03\x04garbage", "agent.txt": "hello"}.items():
        (agents / name).write_text(content)
        fx[f"agent_{name.replace('.', '_')}"] = agents / name
    pd = json.loads(fx["pd"].read_text())

    def pd_variant(name, mutate):
        p = json.loads(json.dumps(pd))
        mutate(p)
        (agents / f"{name}.json").write_text(json.dumps(p, allow_nan=True))
        fx[f"agent_{name}"] = agents / f"{name}.json"

    def set_first_number(d, value):
        """Replace the first numeric leaf of a JSON object (a gain) by ``value``."""
        stack = [d]
        while stack:
            node = stack.pop(0)
            items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else []
            for k, v in items:
                if isinstance(v, (int, float)) and not isinstance(v, bool):
                    node[k] = value
                    return
                stack.append(v)

    pd_variant("pd_nan", lambda p: set_first_number(p, float("nan")))
    pd_variant("pd_huge", lambda p: set_first_number(p, 1e300))
    pd_variant("pd_string", lambda p: set_first_number(p, "big"))
    pd_variant("pd_dropped_key", lambda p: p.pop(next(iter(p))) if isinstance(p, dict) and p else None)
    fx["agent_csv"] = fx["good"]
    # the gains a firmware flew (heli tune --params): good, and bad in each way a file can be
    params = tmp / "params"
    params.mkdir()
    for name, content in {"ap.param": "ATC_ANG_RLL_P,4.5\nATC_RAT_RLL_P,0.05\nATC_ANG_PIT_P,4.5\n",
                          "ap_unknown.param": "ATC_RAT_RLL_PP,0.1\n", "ap_range.param": "ATC_RAT_RLL_P,0.9\n",
                          "ap_nan.param": "ATC_RAT_RLL_P,nan\n", "ap_inf.param": "ATC_ANG_RLL_P,inf\n",
                          "ap_words.param": "ATC_RAT_RLL_P 0.1 7\n", "ap_empty.param": "",
                          "ap_loop250.param": "SCHED_LOOP_RATE,250\n", "ap_loop0.param": "SCHED_LOOP_RATE,0\n",
                          "ap_huge.param": "ATC_ANG_RLL_P,1e300\n", "rf.txt": "set pid_mode = 3\n",
                          "rf_garbage.txt": "set = = =\n", "rf_nan.txt": "set angle_level_strength = nan\n"}.items():
        (params / name).write_text(content)
        fx[f"params_{name.replace('.', '_')}"] = params / name
    (params / "binary.param").write_bytes(bytes(np.random.default_rng(4).integers(0, 256, 4096, dtype=np.uint8)))
    fx["params_binary"] = params / "binary.param"
    fx["agent_dir"] = agents
    fx["agent_missing"] = agents / "nowhere.zip"
    return fx


# ------------------------------------------------------------------- cases
@dataclass
class Case:
    command: str
    name: str
    args: list
    result: dict = field(default_factory=dict)

    def argv(self) -> list:
        return heli_argv(self.command, *self.args)

    def line(self) -> str:
        return "heli " + " ".join([self.command] + [str(a) for a in self.args])


BAD_FLOATS = ("-1", "0", "nan", "inf", "-inf", "1e300", "abc", "")


def make_cases(fx: dict, tmp: Path) -> list[Case]:
    cases = []
    counter = iter(range(10**6))

    def out(kind="dir"):
        return tmp / "runs" / f"o{next(counter)}{'.csv' if kind == 'csv' else ''}"

    def add(command, name, *args):
        cases.append(Case(command, name, list(args)))

    copies = iter(range(10**6))

    def model_copy(src):
        """A copy of a model folder for a case that writes into it (the cases share the fixtures)."""
        d = tmp / "copies" / f"m{next(copies)}"
        if Path(src).is_dir():
            shutil.copytree(src, d)
            return d
        return src

    bad_csvs = [k for k in fx if Path(fx[k]).parent.name == "bad" and k not in ("dir",)] + ["dir", "missing"]
    out_paths = ("out_file", "out_under_file", "out_ro", "out_proc")

    # simulate-flight: numbers and output paths
    for opt, values in {"--duration": BAD_FLOATS + ("1e9", "1e6", "0.001"), "--seed": ("-1", "1.5", "1e30", "x"),
                        "--wind": ("-1", "nan", "1e300"), "--wind-scale": ("0", "1e300"),
                        "--wind-corner": ("0", "1e300"), "--slow-gusts": ("1", "-0.1"),
                        "--reaction-delay": ("-1", "1e300", "100"), "--gyro-noise": ("-1", "1e300"),
                        "--vibration-line": ("27", "nan:1", "1e300:1", "27:1e300", "-5:1"),
                        "--input-shift": ("1e300", "-1e300", "100")}.items():
        for v in values:
            add("simulate-flight", f"{opt} {v!r}", "--duration", 5, "--out", out("csv"), opt, v)
    for o in out_paths + ("out_dir",):
        add("simulate-flight", f"--out {o}", "--duration", 5, "--out", fx[o])
    add("simulate-flight", "--seed 2**64", "--duration", 5, "--out", out("csv"), "--seed", 2**64)
    add("sweep", "--seed 2**64", "--model", fx["model"], "--kp", "1", "--kd", "1", "--duration", 2, "--windows", 2,
        "--seed", 2**64, "--out", out())
    add("simulate-flight", "--out ''", "--duration", 5, "--out", "")

    # import
    for k in bad_csvs:
        add("import", f"log {k}", fx[k], "--out", out("csv"))
    for k in ("good",):
        for opt, values in {"--rate": BAD_FLOATS + ("1e9",), "--segment": ("5:2", "nan:3", "0:1e300", "x", "-5:-1",
                                                                           "100:200"),
                            "--log": ("0", "99", "-1")}.items():
            for v in values:
                add("import", f"{opt} {v!r}", fx[k], "--out", out("csv"), opt, v)
    for k in ("cal_garbage", "cal_list", "cal_nan", "missing", "dir", "binary"):
        add("import", f"--calibration {k}", fx["servo_no_cal"], "--out", out("csv"), "--calibration", fx[k])
    add("import", "servo log, no calibration", fx["servo_no_cal"], "--out", out("csv"))
    add("import", "--list on garbage", fx["garbage_bin"], "--list")
    for o in out_paths + ("out_dir",):
        add("import", f"--out {o}", fx["good"], "--out", fx[o])

    # identify: every bad CSV (integral is quick), bad numbers, outputs
    for k in bad_csvs:
        add("identify", f"flight {k}", fx[k], "--out", out(), "--method", "integral", "--no-plots")
    for k in ("nan", "ms_time", "gap", "constant_stick", "truncated", "utf16", "deg_rates", "pwm_sticks"):
        add("identify", f"flight {k} (ml)", fx[k], "--out", out(), "--no-plots")
    for opt, values in {"--delay": BAD_FLOATS + ("1e3", "auto:x"), "--interval": BAD_FLOATS + ("1e9", "1e-9"),
                        "--workers": ("0", "-1", "1e9", "100000")}.items():
        for v in values:
            add("identify", f"{opt} {v!r}", fx["good"], "--out", out(), "--method", "integral", "--no-plots", opt, v)
    add("identify", "same flight twice", fx["good"], fx["good"], "--out", out(), "--method", "integral", "--no-plots")
    add("identify", "--backend local 2 flights", fx["good"], fx["good2"], "--out", out(), "--method", "integral",
        "--no-plots", "--backend", "local", "--workers", "2")
    for o in out_paths:
        add("identify", f"--out {o}", fx["good"], "--out", fx[o], "--method", "integral", "--no-plots")
    for k in bad_csvs:  # --validate: a bad flight to validate on is refused before the fit
        add("identify", f"--validate {k}", fx["good"], "--out", out(), "--method", "integral", "--no-plots",
            "--validate", fx[k])
    add("identify", "--validate the fitted flight", fx["good"], "--out", out(), "--method", "integral", "--no-plots",
        "--validate", fx["good"])
    add("identify", "--validate a 50 Hz flight", fx["good"], "--out", out(), "--method", "integral", "--no-plots",
        "--validate", fx["good_50hz"])
    add("identify", "--validate twice the same", fx["good"], "--out", out(), "--method", "integral", "--no-plots",
        "--validate", fx["good2"], fx["good2"])
    add("identify", "--validate, figures", fx["good"], "--out", out(), "--method", "integral", "--validate",
        fx["good2"], fx["zero_sticks"])
    add("identify", "--validate (ml)", fx["good"], "--out", out(), "--no-plots", "--no-disturbances", "--validate",
        fx["good2"], fx["constant_stick"])
    for m in ("flipped_trace", "truncated_model", "no_manifest", "model_json_dir"):
        # into a copy: writing into the shared corrupt folder repaired it for every later case that reads it
        add("identify", f"--out into model {m}", fx["good2"], "--out", model_copy(fx[f"model_{m}"]), "--method",
            "integral", "--no-plots")

    # diagnose
    for k in ("empty", "binary", "utf16", "truncated", "nan", "ms_time", "deg_rates", "constant_stick", "dir",
              "missing", "short_flight", "gap"):
        add("diagnose", f"flight {k}", fx[k], "--model", fx["model"], "--out", out(), "--method", "integral",
            "--no-plots")
    for m in ("flipped_trace", "truncated_model", "no_manifest", "nan_param", "empty_dir", "missing", "is_file",
              "string_param"):
        add("diagnose", f"--model {m}", fx["good"], "--model", fx[f"model_{m}"], "--out", out(), "--method",
            "integral", "--no-plots")
    for opt, values in {"--folds": ("0", "1", "1e9", "100000", "-3"), "--window": ("0", "nan", "1e300", "-1"),
                        "--alpha": ("0", "1", "nan"), "--min-gain": ("2", "-1"), "--min-lr": ("-1", "inf")}.items():
        for v in values:
            add("diagnose", f"{opt} {v!r}", fx["good"], "--model", fx["model"], "--out", out(), "--method",
                "integral", "--no-plots", opt, v)
    for o in out_paths:
        add("diagnose", f"--out {o}", fx["good"], "--model", fx["model"], "--out", fx[o], "--method", "integral",
            "--no-plots")

    # refresh: on copies of the model (it writes into the folder)
    for k in ("empty", "binary", "utf16", "truncated", "nan", "ms_time", "constant_stick", "dir", "missing", "good"):
        add("refresh", f"flight {k}", model_copy(fx["model"]), fx[k], "--no-plots", "--bootstrap", 20)
    for m in ("flipped_trace", "truncated_model", "no_manifest", "truncated_trace", "no_library", "nan_param",
              "empty_dir", "model_list"):
        add("refresh", f"model {m}", model_copy(fx[f"model_{m}"]), fx["good2"], "--no-plots", "--bootstrap", 20)
    add("refresh", "model missing", fx["model_missing"], fx["good2"], "--no-plots")
    add("refresh", "model is a file", fx["good"], fx["good2"], "--no-plots")
    for opt, values in {"--bootstrap": ("0", "1", "1e9", "100000000"), "--block": ("0", "1e9", "100000"),
                        "--alpha": ("0", "1", "nan"), "--min-change": ("-1", "inf"), "--seed": ("-1",),
                        "--workers": ("0",)}.items():
        for v in values:
            add("refresh", f"{opt} {v!r}", model_copy(fx["model"]), fx["good2"], "--no-plots", opt, v)
    add("refresh", "--previous-flights missing", model_copy(fx["model"]), fx["good2"], "--no-plots",
        "--bootstrap", 20, "--previous-flights", fx["missing"])
    add("refresh", "--previous-flights binary", model_copy(fx["model"]), fx["good2"], "--no-plots",
        "--bootstrap", 20, "--previous-flights", fx["binary"])

    # check
    for m in ("flipped_trace", "truncated_model", "empty_model", "no_model_json", "no_manifest", "truncated_manifest",
              "no_traces", "truncated_trace", "no_library", "nan_param", "empty_dir", "missing", "is_file",
              "model_json_dir", "string_param", "huge_param", "model_list", "model_empty_obj"):
        add("check", f"model {m}", model_copy(fx[f"model_{m}"]) if Path(fx[f"model_{m}"]).is_dir()
            else fx[f"model_{m}"])
    add("check", "model folder", model_copy(fx["model"]))

    # compare-methods (--quick): inputs and outputs
    for k in ("empty", "binary", "utf16", "truncated", "nan", "ms_time", "deg_rates", "constant_stick", "dir",
              "missing", "short_flight"):
        add("compare-methods", f"flight {k}", fx[k], "--quick", "--out", out())
    for k in ("binary", "missing", "ms_time"):
        add("compare-methods", f"--validate {k}", fx["good"], "--quick", "--out", out(), "--validate", fx[k])
    for o in out_paths:
        add("compare-methods", f"--out {o}", fx["good"], "--quick", "--out", fx[o])

    # design
    for opt, values in {"--phase-margin": ("0", "180", "-1", "nan", "1e300"),
                        "--bandwidth": ("0", "-1", "nan", "1e300", "1,2", "1,2,3,4", "x", "1e-300"),
                        "--dt": ("0", "1", "nan", "1e-300", "-0.01")}.items():
        for v in values:
            add("design", f"{opt} {v!r}", "--model", fx["model"], "--out", out(), "--no-plots", opt, v)
    for v in ("0", "-1", "nan", "inf", "1e300", "1e-300", "1,2", "1,2,3,4", "x", "", "auto,off", "off,1,2", "1000",
              "0.001", "off", "auto", "5,off,5"):
        add("design", f"--d-filter-hz {v!r}", "--model", fx["model"], "--out", out(), "--no-plots", "--d-filter-hz", v)
    for v in ("1000", "0.001", "off"):  # flown for the servo activity too
        add("design", f"--d-filter-hz {v!r} (flown)", "--model", fx["model"], "--out", out(), "--d-filter-hz", v)
    for m in ("truncated_model", "nan_param", "huge_param", "empty_dir", "missing", "is_file", "string_param",
              "no_library", "unusable", "bad_verdict"):
        add("design", f"--model {m}", "--model", fx[f"model_{m}"], "--out", out(), "--no-plots")
    add("design", "--model unusable --accept-unusable-model", "--model", fx["model_unusable"], "--out", out(),
        "--no-plots", "--accept-unusable-model")
    for m in ("model_short", "model_50hz"):  # the servo activity's episode does not fit / another period
        add("design", f"--model {m}", "--model", fx[m], "--out", out())
        add("design", f"--model {m} --dt 0.01", "--model", fx[m], "--out", out(), "--dt", "0.01")
        add("design", f"--model {m} --dt 0.03", "--model", fx[m], "--out", out(), "--dt", "0.03")
    for o in out_paths:
        add("design", f"--out {o}", "--model", fx["model"], "--out", fx[o], "--no-plots")

    # sweep
    base = ("--model", fx["model"], "--duration", 2, "--windows", 2)
    for kp, kd in (("1:2:0", "0:1:2"), ("1:2:-3", "0:1:2"), ("nan:2:2", "0:1:2"), ("1:inf:2", "0:1:2"),
                   ("1:2:100000", "0:1:100000"), ("1:2:1e9", "0:1:2"), ("2:1:3", "0:1:2"), ("x", "0"),
                   ("1:2:2:2", "0:1:2"), ("1e300:1e301:2", "0:1:2"), ("-5:-1:2", "0:1:2"), ("", ""),
                   ("1:2:2.5", "0:1:2")):
        add("sweep", f"--kp {kp!r} --kd {kd!r}", *base, "--kp", kp, "--kd", kd, "--out", out())
    for opt, values in {"--duration": ("0", "nan", "1e300", "1e9", "1e-9"), "--dt": ("0", "nan", "1", "1e-9", "100"),
                        "--windows": ("0", "1e9", "100000000"), "--flights": ("-1", "1e9", "100000000"),
                        "--workers": ("0", "100000")}.items():
        for v in values:
            args = list(base)
            if opt in ("--duration", "--windows"):
                i = args.index(opt)
                del args[i:i + 2]
            add("sweep", f"{opt} {v!r}", *args, "--kp", "1:2:2", "--kd", "0.1:0.2:2", opt, v, "--out", out())
    for m in ("flipped_trace", "truncated_model", "no_library", "nan_param", "empty_dir", "is_file", "missing",
              "truncated_trace"):
        add("sweep", f"--model {m}", "--model", fx[f"model_{m}"], "--kp", "1:2:2", "--kd", "0.1:0.2:2", "--duration",
            2, "--windows", 2, "--out", out())
    for o in out_paths:
        add("sweep", f"--out {o}", *base, "--kp", "1:2:2", "--kd", "0.1:0.2:2", "--out", fx[o])
    add("sweep", "--backend local", *base, "--kp", "1:2:2", "--kd", "0.1:0.2:2", "--backend", "local",
        "--workers", "2", "--out", out())

    # train (tiny)
    tiny = ("--algo", "ppo", "--model", fx["model"], "--eval-freq", 0, "--checkpoint-freq", 0, "--n-envs", 1,
            "--episode-seconds", 1)
    for opt, values in {"--timesteps": ("0", "-1", "1e9", "x"), "--n-envs": ("0", "1e9", "100000000"),
                        "--minutes": ("0", "nan", "-1"), "--episode-seconds": ("0", "nan", "1e300", "1e9"),
                        "--held-out-fraction": ("0", "1", "nan"), "--seeds": ("", "a,b", "-1", "1,,2"),
                        "--residual-scale": ("0", "3", "nan"), "--eval-episodes": ("0",)}.items():
        for v in values:
            args = list(tiny)
            if opt in args:
                i = args.index(opt)
                del args[i:i + 2]
            add("train", f"{opt} {v!r}", *args, "--timesteps", 64 if opt != "--timesteps" else v,
                *((opt, v) if opt != "--timesteps" else ()), "--out", out())
    for k in ("agent_empty_json", "agent_garbage_json", "agent_csv", "agent_missing", "agent_pd_nan"):
        add("train", f"--residual {k}", *tiny, "--timesteps", 64, "--residual", fx[k], "--out", out())
    for m in ("truncated_model", "no_library", "nan_param", "empty_dir", "missing", "flipped_trace"):
        add("train", f"--model {m}", "--algo", "ppo", "--model", fx[f"model_{m}"], "--timesteps", 64, "--n-envs", 1,
            "--eval-freq", 0, "--checkpoint-freq", 0, "--out", out())
    for o in ("out_under_file", "out_ro", "out_proc", "out_dir"):
        add("train", f"--out {o}", *tiny, "--timesteps", 64, "--out", fx[o])

    # evaluate
    ev = ("--model", fx["model"], "--episodes-per-trace", 1, "--episode-seconds", 2)
    for k in [k for k in fx if k.startswith("agent_")]:
        add("evaluate", f"agent {k}", fx[k], *ev, "--out", out())
    for opt, values in {"--episodes-per-trace": ("0", "1e9", "100000000"),
                        "--episode-seconds": ("0", "nan", "1e300", "1e9", "1e-9"), "--seed": ("-1",)}.items():
        for v in values:
            args = list(ev)
            i = args.index(opt) if opt in args else None
            if i is not None:
                del args[i:i + 2]
            add("evaluate", f"{opt} {v!r}", fx["pd"], *args, opt, v, "--out", out())
    for m in ("truncated_model", "no_library", "nan_param", "empty_dir", "missing", "flipped_trace", "truncated_trace"):
        add("evaluate", f"--model {m}", fx["pd"], "--model", fx[f"model_{m}"], "--episodes-per-trace", 1,
            "--episode-seconds", 2, "--out", out())
    for o in out_paths:
        add("evaluate", f"--out {o}", fx["pd"], *ev, "--out", fx[o])
    # no --episode-seconds: the default 30 s does not fit a short flight's traces
    for agent, m in (("pd", "model"), ("pd", "model_short"), ("pd", "model_50hz"), ("pd_50hz", "model_50hz"),
                     ("pd_50hz", "model"), ("pd", "model_unusable")):
        add("evaluate", f"{agent} on {m}, default episode", fx[agent], "--model", fx[m], "--episodes-per-trace", 1,
            "--no-plots", "--out", out())
    for traces in ("all", "train"):
        add("evaluate", f"--traces {traces}, default episode", fx["pd"], "--model", fx["model_short"],
            "--episodes-per-trace", 1, "--no-plots", "--traces", traces, "--out", out())
    add("evaluate", "default episode, figures", fx["pd"], "--model", fx["model"], "--episodes-per-trace", 1,
        "--out", out())
    add("evaluate", "unusable --accept-unusable-model", fx["pd"], "--model", fx["model_unusable"],
        "--episodes-per-trace", 1, "--no-plots", "--accept-unusable-model", "--out", out())

    # tune: its flight, its parameter files, its options (on the integral model: no identification inside)
    tn = ("--firmware", "ardupilot", "--model", fx["model"], "--window", 5, "--candidates", 1, "--no-plots")
    add("tune", "csv with --params", fx["good"], *tn, "--params", fx["params_ap_param"], "--out", out())
    add("tune", "csv without --params", fx["good"], *tn, "--out", out())
    add("tune", "rotorflight --params", fx["good"], "--firmware", "rotorflight", "--model", fx["model"], "--window", 5,
        "--candidates", 1, "--no-plots", "--params", fx["params_rf_txt"], "--out", out())
    for k in [k for k in fx if k.startswith("params_")]:
        add("tune", f"--params {k}", fx["good"], *tn, "--params", fx[k], "--out", out())
    for k in ("params_rf_garbage_txt", "params_rf_nan_txt", "params_ap_param"):
        add("tune", f"rotorflight --params {k}", fx["good"], "--firmware", "rotorflight", "--model", fx["model"],
            "--window", 5, "--candidates", 1, "--no-plots", "--params", fx[k], "--out", out())
    for k in ("empty", "binary", "utf16", "truncated", "nan", "ms_time", "dir", "missing", "short_flight",
              "garbage_bin", "garbage_bbl", "bbl_header_only"):
        add("tune", f"flight {k}", fx[k], *tn, "--params", fx["params_ap_param"], "--out", out())
    for m in ("truncated_model", "nan_param", "huge_param", "empty_dir", "missing", "is_file", "no_library",
              "flipped_trace", "unusable", "short", "50hz"):
        add("tune", f"--model {m}", fx["good"], "--firmware", "ardupilot", "--model", fx[f"model_{m}"], "--window", 5,
            "--candidates", 1, "--no-plots", "--params", fx["params_ap_param"], "--out", out())
    add("tune", "--model unusable --accept-unusable-model", fx["good"], *tn[:2], "--model", fx["model_unusable"],
        "--window", 5, "--candidates", 1, "--no-plots", "--params", fx["params_ap_param"], "--accept-unusable-model",
        "--out", out())
    for opt, values in {"--scale": ("0", "-1", "nan", "inf", "1e300", "1e-300", "1,2", "x", ""),
                        "--delay": ("-1", "3", "nan", "x", ""), "--window": BAD_FLOATS + ("1e9", "0.001"),
                        "--candidates": ("0", "-1", "1e9", "100000", "x"), "--seed": ("-1", "1.5", "1e30"),
                        "--firmware": ("px4", "")}.items():
        for v in values:
            args = list(tn)
            if opt in args:
                i = args.index(opt)
                del args[i:i + 2]
            add("tune", f"{opt} {v!r}", fx["good"], *args, "--params", fx["params_ap_param"], opt, v, "--out", out())
    add("tune", "no --model (identify inside)", fx["good"], "--firmware", "ardupilot", "--window", 5, "--candidates", 1,
        "--no-plots", "--params", fx["params_ap_param"], "--delay", "none", "--out", out())
    add("tune", "figures", fx["good"], *tn[:-1], "--params", fx["params_ap_param"], "--out", out())
    for o in out_paths + ("out_dir",):
        add("tune", f"--out {o}", fx["good"], *tn, "--params", fx["params_ap_param"], "--out", fx[o])
    return cases


# --------------------------------------------------------------------- run
def classify(code, stderr: str, timed_out: bool) -> dict:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    first = next((i for i, ln in enumerate(lines) if re.match(r"^heli[\w -]*: (error|unexpected error)", ln)), None)
    error_lines = lines[first:] if first is not None else []
    if code not in (0, None) and first is None and not timed_out:
        error_lines = lines[-3:]  # an error that is not in heli's form at all
    return {"code": code, "traceback": "Traceback (most recent call last)" in stderr,
            "unexpected": any("unexpected error" in ln for ln in lines), "timeout": timed_out,
            "multiline": code not in (0, 1, None) and len(error_lines) != 1,
            "message": error_lines[0] if error_lines else (lines[-1] if lines else "")}


def run_case(case: Case, tmp: Path, timeout: float) -> Case:
    t0 = time.monotonic()
    p = subprocess.Popen(case.argv(), cwd=tmp, env=run_env(), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, errors="replace", preexec_fn=_cap_memory)
    try:
        _, err = p.communicate(timeout=timeout)
        timed_out = False
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, 9)
        _, err = p.communicate()
        timed_out = True
    case.result = {**classify(None if timed_out else p.returncode, err, timed_out),
                   "seconds": time.monotonic() - t0, "stderr": err}
    return case


def bad(case: Case) -> bool:
    r = case.result
    return r["code"] not in (0, 2) or r["traceback"] or r["unexpected"] or r["timeout"] or r["multiline"]


def report(cases: list[Case]) -> str:
    rows = ["| command | cases | exit 0 | exit 2 clean | exit 1 unexpected | other exit | tracebacks | multi-line "
            "errors | timeouts |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    totals = np.zeros(8, int)
    for command in COMMANDS:
        cs = [c for c in cases if c.command == command]
        if not cs:
            continue
        r = [c.result for c in cs]
        v = np.array([len(cs), sum(x["code"] == 0 for x in r),
                      sum(x["code"] == 2 and not x["traceback"] and not x["multiline"] for x in r),
                      sum(x["code"] == 1 for x in r), sum(x["code"] not in (0, 1, 2, None) for x in r),
                      sum(x["traceback"] for x in r), sum(x["multiline"] for x in r), sum(x["timeout"] for x in r)])
        totals += v
        rows.append(f"| {command} | " + " | ".join(str(x) for x in v) + " |")
    rows.append("| **total** | " + " | ".join(f"**{x}**" for x in totals) + " |")
    out = ["\n".join(rows)]
    failing = [c for c in cases if bad(c)]
    out.append(f"\n{len(failing)} case(s) ended in exit 1, a traceback, a multi-line error, another exit status "
               "or the timeout" + (":" if failing else "."))
    for c in failing:
        r = c.result
        what = "timeout" if r["timeout"] else f"exit {r['code']}" + (", traceback" if r["traceback"] else "") + (
            ", multi-line" if r["multiline"] else "")
        out.append(f"- [{c.command}] {c.name} ({what}, {r['seconds']:.1f} s): `{c.line()}`\n  -> {r['message'][:300]}")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--jobs", type=int, default=2, help="cases run at once (default 2)")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per case (default 120)")
    ap.add_argument("--only", default=None, help="comma-separated commands to run (default all)")
    ap.add_argument("--match", default=None, help="only cases whose name matches this regular expression "
                    "(e.g. 'nan_param|truncated')")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder and print its path")
    ap.add_argument("--verbose", action="store_true", help="print each case as it ends")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="heli-hostile-"))
    try:
        t0 = time.monotonic()
        fx = make_fixtures(tmp)
        cases = make_cases(fx, tmp)
        if args.only:
            keep = set(args.only.split(","))
            cases = [c for c in cases if c.command in keep]
        if args.match:
            cases = [c for c in cases if re.search(args.match, c.name)]
        print(f"{len(cases)} hostile cases over {len({c.command for c in cases})} commands "
              f"(fixtures in {time.monotonic() - t0:.0f} s), {args.jobs} at a time, timeout {args.timeout:g} s",
              file=sys.stderr)
        done = 0
        with ThreadPoolExecutor(args.jobs) as pool:
            for c in pool.map(lambda c: run_case(c, tmp, args.timeout), cases):
                done += 1
                if args.verbose or bad(c):
                    r = c.result
                    print(f"[{done}/{len(cases)}] {c.command} {c.name}: exit {r['code']} {r['seconds']:.1f} s"
                          f"{' TRACEBACK' if r['traceback'] else ''}{' TIMEOUT' if r['timeout'] else ''}"
                          f"{' MULTILINE' if r['multiline'] else ''} | {r['message'][:160]}", file=sys.stderr)
        print(report(cases))
        print(f"\n{len(cases)} cases in {time.monotonic() - t0:.0f} s")
        return 1 if any(bad(c) for c in cases) else 0
    finally:
        ro = tmp / "out" / "ro"
        if ro.exists():
            os.chmod(ro, 0o755)
        if args.keep:
            print(f"inputs kept in {tmp}", file=sys.stderr)
        else:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
