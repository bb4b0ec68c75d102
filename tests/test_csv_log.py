"""Tests of :mod:`identification.io.csv_log`: the canonical CSV and servo logs (eqs. 65-67).

One ``pytest.raises(FlightLogError, match=...)`` per bad input class; each match
checks that the message names what was expected and what came.
"""

from __future__ import annotations

import hashlib
import json
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from heli_core.params import ModelParams
from heli_core.physics import QUAT, simulate
from heli_core.quaternion import euler_from_quaternion
from identification.errors import FlightLogError, UnitError
from identification.flight import CSV_COLUMNS, make_flight
from identification.io import read_csv_flight, read_flight, read_servo_csv, sticks_from_servos, write_csv_flight

HEADER = ",".join(CSV_COLUMNS)

# A CCPM-like mixing of eq. (66): pulse widths [ms] per unit stick, columns (lon, lat, col, ped).
G_MIX = np.array([
    [0.30, -0.25, 0.35, 0.00],   # U_AILE
    [0.00, 0.00, 0.00, 0.40],    # U_AUX  (here: tail servo on AUX)
    [-0.30, -0.25, 0.35, 0.05],  # U_ELEV
    [0.00, 0.45, 0.30, 0.00],    # U_RUDD
])
U_TRIM = np.array([1.52, 1.50, 1.48, 1.51])


def _wrap(a):
    return np.angle(np.exp(1j * a))


@pytest.fixture(scope="module")
def simulated():
    """A 10 s coupled-model flight at 300 Hz whose clock starts at 1234.5 s (as logger clocks do)."""
    params = ModelParams(k1=-0.05, k2=8.0, k3=3.0, k4=0.5, kd1=0.1, k5=0.05, k6=6.0, k7=3.0, k8=0.4,
                         k10=10.0, k11=4.0, k12=1.0, tau_roll=0.05, tau_pitch=0.05)
    t = 1234.5 + np.arange(3000) / 300.0
    s = t - t[0]
    sticks = np.array([
        0.3 * np.sin(2 * np.pi * 0.4 * s) + 0.1 * np.sin(2 * np.pi * 1.3 * s),
        0.3 * np.sin(2 * np.pi * 0.3 * s + 1.0),
        0.2 * np.sin(2 * np.pi * 0.2 * s),
        0.3 * np.sin(2 * np.pi * 0.5 * s + 2.0),
    ])
    x = simulate(params, t, sticks)
    return t, x[:3], sticks, euler_from_quaternion(x[QUAT])


def _write(path, header, rows):
    """Write a CSV by hand: ``rows`` is a 2-D array (n, columns) or a list of row strings."""
    if isinstance(rows, np.ndarray):
        rows = [",".join(repr(float(v)) for v in row) for row in rows]
    path.write_text(header + "\n" + "".join(r + "\n" for r in rows), encoding="utf-8")
    return path


def _canonical(n=100, dt=0.01):
    """Rows (n, 11) of a valid canonical log: time, p, q, r, phi, theta, psi, lat, lon, col, ped."""
    t = dt * np.arange(n)
    data = np.zeros((n, 11))
    data[:, 0] = t
    data[:, 1] = 0.05 * np.sin(t)
    data[:, 7] = 0.2 * np.sin(3 * t)
    return data


# ---------------------------------------------------------------------------------------- round trip


def test_round_trip_preserves_data_and_extra_columns(tmp_path, simulated):
    t, rates, sticks, att = simulated
    extra = {"rpm": 1500.0 + 10 * np.sin(t), "vbat": np.linspace(12.6, 11.9, t.size)}
    f = make_flight(t, rates, sticks, attitude=att, extra=extra)
    path = write_csv_flight(f, tmp_path / "out" / "flight.csv")  # the folder is created
    g = read_csv_flight(path)
    assert path.read_text().splitlines()[0] == HEADER + ",rpm,vbat"
    # 1e-8 absolute: the time stamps near 1234 s at 300 Hz must keep sub-microsecond resolution
    for a, b in ((g.time, f.time), (g.rates, f.rates), (g.attitude, f.attitude), (g.sticks, f.sticks)):
        assert_allclose(a, b, rtol=0, atol=1e-8)
    assert list(g.extra) == ["rpm", "vbat"]
    for k in extra:
        assert_allclose(g.extra[k], extra[k], rtol=0, atol=1e-8)
    assert g.metadata["attitude_source"] == "measured"
    assert g.metadata["format"] == "csv"
    assert g.metadata["source"] == "flight.csv"
    assert g.metadata["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert read_flight(path).metadata["sha256"] == g.metadata["sha256"]

    write_csv_flight(f, path, extra=False)
    assert read_csv_flight(path).extra == {}


def test_missing_attitude_columns_are_reconstructed(tmp_path, simulated):
    """A log with only rates and sticks gets the attitude of eqs. (25)-(29) (within 1e-4 rad at 300 Hz)."""
    t, rates, sticks, truth = simulated
    path = _write(tmp_path / "noatt.csv", "time,p,q,r,lat,lon,col,ped", np.column_stack([t, *rates, *sticks]))
    f = read_csv_flight(path)
    assert f.metadata["attitude_source"] == "reconstructed"
    assert np.abs(truth).max() > 0.5
    assert_allclose(_wrap(f.attitude - truth), 0.0, atol=1e-4)


def test_columns_may_come_in_any_order_and_with_a_spreadsheet_bom(tmp_path):
    data = _canonical()
    order = [10, 9, 0, 3, 2, 1, 8, 7, 6, 5, 4]
    header = ",".join(CSV_COLUMNS[i] for i in order)
    path = _write(tmp_path / "perm.csv", header, data[:, order])
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())  # Excel's UTF-8 byte-order mark
    f = read_csv_flight(path)
    assert_array_equal(f.time, data[:, 0])
    assert_array_equal(f.rates, data[:, 1:4].T)
    assert_array_equal(f.sticks, data[:, 7:].T)
    assert f.extra == {}


def test_segment_of_a_read_flight(tmp_path):
    data = _canonical()
    path = _write(tmp_path / "seg.csv", HEADER + ",rpm", np.column_stack([data, np.arange(100.0)]))
    s = read_csv_flight(path).segment(0.2, 0.295)
    assert_allclose(s.time, data[20:30, 0], rtol=0, atol=1e-12)
    assert_array_equal(s.extra["rpm"], np.arange(20.0, 30.0))
    assert s.metadata["segment"] == [0.2, 0.295]
    assert s.metadata["source"] == "seg.csv"


# ----------------------------------------------------------------------------- atomic writing


def _a_flight_and_a_file_it_replaces(folder):
    """A 50-sample flight and ``folder/flight.csv`` holding "previous content"."""
    dest = folder / "flight.csv"
    dest.write_text("previous content\n")
    return make_flight(0.01 * np.arange(50), np.zeros((3, 50)), np.zeros((4, 50))), dest


def test_write_is_atomic_when_the_writer_fails_midway(tmp_path, monkeypatch):
    f, dest = _a_flight_and_a_file_it_replaces(tmp_path)

    def failing_savetxt(fname, X, *args, **kwargs):
        with open(fname, "w") as fh:  # half a file, then the crash
            fh.write(HEADER + "\n0,0,0\n")
        raise OSError("disk full")

    monkeypatch.setattr(np, "savetxt", failing_savetxt)
    with pytest.raises(OSError, match="disk full"):
        write_csv_flight(f, dest)
    assert dest.read_text() == "previous content\n"
    assert [p.name for p in tmp_path.iterdir()] == ["flight.csv"]  # no stray temporary file

    monkeypatch.undo()
    write_csv_flight(f, dest)
    assert dest.read_text().startswith(HEADER + "\n")
    assert [p.name for p in tmp_path.iterdir()] == ["flight.csv"]


def test_a_full_disk_met_on_the_temporary_file_names_the_destination(tmp_path, monkeypatch):
    f, dest = _a_flight_and_a_file_it_replaces(tmp_path)

    def full_disk(fname, X, *args, **kwargs):
        raise OSError(28, "No space left on device", str(fname))  # what the kernel says, naming the file it wrote

    monkeypatch.setattr(np, "savetxt", full_disk)
    with pytest.raises(OSError, match="No space left on device") as raised:
        write_csv_flight(f, dest)
    assert raised.value.filename == str(dest) and raised.value.errno == 28
    assert [p.read_text() for p in tmp_path.iterdir()] == ["previous content\n"]


# ------------------------------------------------------------------------ bad files, one per class


def test_nonexistent_file(tmp_path):
    path = tmp_path / "nope.csv"
    with pytest.raises(FlightLogError, match=rf"flight log '{re.escape(str(path))}' does not exist"):
        read_csv_flight(path)


@pytest.mark.filterwarnings("ignore:loadtxt. input contained no data:UserWarning")
@pytest.mark.parametrize(
    "text, message",
    [("", rf"empty file; expected a header line {HEADER}"), (HEADER + "\n", "header but no data rows")],
    ids=["no-bytes", "header-only"],
)
def test_empty_file(tmp_path, text, message):
    path = tmp_path / "empty.csv"
    path.write_text(text)
    with pytest.raises(FlightLogError, match=rf"{re.escape(str(path))}: {message}"):
        read_csv_flight(path)


def test_missing_required_columns(tmp_path):
    data = _canonical()
    keep = [i for i, c in enumerate(CSV_COLUMNS) if c not in ("q", "ped")]
    header = ",".join(CSV_COLUMNS[i] for i in keep)
    path = _write(tmp_path / "missing.csv", header, data[:, keep])
    with pytest.raises(
        FlightLogError,
        match=r"missing required column\(s\) \['q', 'ped'\]; expected at least time,p,q,r,lat,lon,col,ped, "
              r"found time,p,r,phi,theta,psi,lat,lon,col",
    ):
        read_csv_flight(path)


def test_duplicated_column_names(tmp_path):
    data = _canonical()
    path = _write(tmp_path / "dup.csv", HEADER + ",p", np.column_stack([data, data[:, 1]]))
    with pytest.raises(FlightLogError, match=r"duplicated column\(s\) \['p'\] in the header"):
        read_csv_flight(path)


@pytest.mark.parametrize("reader", ["canonical", "servo"])
def test_attitude_partially_present(tmp_path, reader):
    data = _canonical()
    if reader == "canonical":
        header, cols = "time,p,q,r,phi,theta,lat,lon,col,ped", np.delete(data, 6, axis=1)
    else:
        servos = (G_MIX @ np.zeros((4, data.shape[0])) + U_TRIM[:, None]).T
        header, cols = "time,p,q,r,phi,theta,u_aile,u_aux,u_elev,u_rudd", np.column_stack([data[:, :6], servos])
    path = _write(tmp_path / "partial.csv", header, cols)
    with pytest.raises(
        FlightLogError, match=r"attitude columns must be all of phi,theta,psi or none; found \['phi', 'theta'\]"
    ):
        if reader == "canonical":
            read_csv_flight(path)
        else:
            read_servo_csv(path, {"G": G_MIX.tolist(), "U_trim": U_TRIM.tolist()})


def test_non_numeric_field(tmp_path):
    rows = [",".join(["0"] * 11), "0.01,0,abc,0,0,0,0,0,0,0,0", "0.02" + ",0" * 10]
    path = _write(tmp_path / "text.csv", HEADER, rows)
    with pytest.raises(FlightLogError, match=r"expected numbers in every field after the header: could not convert string 'abc'"):
        read_csv_flight(path)


@pytest.mark.parametrize("ncols", [10, 12])
def test_header_and_rows_disagree_on_column_count(tmp_path, ncols):
    rows = [",".join([f"{0.01 * k}"] + ["0"] * (ncols - 1)) for k in range(5)]
    path = _write(tmp_path / "count.csv", HEADER, rows)
    with pytest.raises(FlightLogError, match=rf"header names 11 columns but rows have {ncols}"):
        read_csv_flight(path)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d.__setitem__((40, 2), np.nan), r"column 'q' has 1 non-finite values \(NaN first\), first at row 40 \(t=0\.40 s\)"),
        (lambda d: d.__setitem__((41, 9), np.inf), r"column 'col' has 1 non-finite values \(inf first\), first at row 41 \(t=0\.41 s\)"),
        (lambda d: d.__setitem__((30, 0), d[29, 0]), r"time must be strictly increasing; it is duplicated at row 30"),
        (lambda d: d.__setitem__((slice(None), 1), 100 * d[:, 1] + 50), r"column 'p' reaches 54\.\d, beyond 35\.0 rad/s"),
        (lambda d: d.__setitem__((5, 8), -1.01), r"stick column 'lon' has 1 values outside \[-1, 1\]"),
    ],
    ids=["nan", "inf", "duplicated-time", "deg-per-s", "stick-range"],
)
def test_flight_checks_apply_to_files_and_name_the_file(tmp_path, edit, message):
    """make_flight's checks run on every file, with the file name in front (NaN/inf parse from 'nan'/'inf')."""
    data = _canonical()
    edit(data)
    path = _write(tmp_path / "bad.csv", HEADER, data)
    with pytest.raises(FlightLogError, match=rf"^{re.escape(str(path))}: {message}"):
        read_csv_flight(path)


# ------------------------------------------------------------------------------- servo logs


def _servo_log(tmp_path, n=200, dt=0.02):
    """A servo log built from known sticks with eq. (66); returns (path, sticks lat/lon/col/ped)."""
    t = dt * np.arange(n)
    sticks = np.array([0.6 * np.sin(t), 0.5 * np.cos(0.7 * t), 0.3 * np.sin(0.2 * t) - 0.2, -0.4 * np.sin(1.3 * t)])
    delta = sticks[[1, 0, 2, 3]]  # eq. (65) orders the stick vector lon, lat, col, ped
    servos = G_MIX @ delta + U_TRIM[:, None]  # eq. (66)
    rates = np.array([0.1 * np.sin(t), 0.05 * np.cos(t), 0.02 + 0 * t])
    cols = np.column_stack([t, *rates, *servos, np.full(n, 7.4)])
    path = _write(tmp_path / "servo.csv", "time,p,q,r,u_aile,u_aux,u_elev,u_rudd,vbat", cols)
    return path, sticks


def test_sticks_from_servos_inverts_eq_66():
    rng = np.random.default_rng(0)
    sticks = rng.uniform(-1, 1, size=(4, 50))  # lat, lon, col, ped
    servos = G_MIX @ sticks[[1, 0, 2, 3]] + U_TRIM[:, None]
    assert_allclose(sticks_from_servos(servos, G_MIX, U_TRIM), sticks, rtol=0, atol=1e-12)
    # centred sticks give the trim pulse widths back to zero
    assert_allclose(sticks_from_servos(U_TRIM[:, None], G_MIX, U_TRIM), 0.0, atol=1e-15)


@pytest.mark.parametrize("calibration_as", ["dict", "json-file"])
def test_read_servo_csv_returns_the_sticks_in_canonical_order(tmp_path, calibration_as):
    path, sticks = _servo_log(tmp_path)
    cal = {"G": G_MIX.tolist(), "U_trim": U_TRIM.tolist()}
    if calibration_as == "json-file":
        cal = tmp_path / "cal.json"
        cal.write_text(json.dumps({"G": G_MIX.tolist(), "U_trim": U_TRIM.tolist()}))
    f = read_servo_csv(path, cal)
    assert_allclose(f.sticks, sticks, rtol=0, atol=1e-12)  # lat, lon, col, ped
    assert_allclose(f.lat, sticks[0], rtol=0, atol=1e-12)
    assert_allclose(f.ped, sticks[3], rtol=0, atol=1e-12)
    assert f.metadata["input_source"] == "servos (eq. 67)"
    assert f.metadata["format"] == "servo-csv"
    assert f.metadata["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert f.metadata["attitude_source"] == "reconstructed"
    assert list(f.extra) == ["vbat"]  # servo columns are consumed, others kept


def test_singular_mixing_gain(tmp_path):
    path, _ = _servo_log(tmp_path)
    G = G_MIX.copy()
    G[3] = G[0]  # two servos that move identically: the sticks cannot be told apart
    with pytest.raises(FlightLogError, match=r"servo mixing gain G' is singular \(condition number .*\); cannot invert eq\. \(67\)"):
        read_servo_csv(path, {"G": G.tolist(), "U_trim": U_TRIM.tolist()})


@pytest.mark.parametrize(
    "calibration, message",
    [
        ({"G": np.eye(3).tolist(), "U_trim": [1.5] * 4}, r"servo mixing gain G' must be 4x4, got shape \(3, 3\)"),
        ({"G": G_MIX.tolist(), "U_trim": [1.5] * 3}, r"servo trim U_trim must have 4 values, got shape \(3,\)"),
        ({"G": G_MIX.tolist()}, r"servo calibration lacks 'U_trim'; expected keys 'G' \(4x4\) and 'U_trim' \(4\)"),
        ("missing.json", r"servo calibration '.*missing\.json' is not a readable JSON file"),
    ],
    ids=["G-shape", "trim-size", "missing-key", "no-file"],
)
def test_malformed_servo_calibration(tmp_path, calibration, message):
    path, _ = _servo_log(tmp_path)
    if isinstance(calibration, str):
        calibration = tmp_path / calibration
    with pytest.raises(FlightLogError, match=message):
        read_servo_csv(path, calibration)


def test_servo_log_problems_name_the_servo_column(tmp_path):
    path, _ = _servo_log(tmp_path)
    text = path.read_text().splitlines()
    row = text[1 + 17].split(",")
    row[6] = "nan"  # u_elev
    text[1 + 17] = ",".join(row)
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(FlightLogError, match=r"column 'u_elev' has 1 non-finite values \(NaN first\), first at row 17 \(t=0\.34 s\)"):
        read_servo_csv(path, {"G": G_MIX.tolist(), "U_trim": U_TRIM.tolist()})

    header = "time,p,q,r,u_aile,u_aux,u_elev"
    bad = _write(tmp_path / "three.csv", header, np.zeros((3, 7)))
    with pytest.raises(FlightLogError, match=r"missing column\(s\) \['u_rudd'\]; a servo log needs time,p,q,r,u_aile,u_aux,u_elev,u_rudd"):
        read_servo_csv(bad, {"G": G_MIX.tolist(), "U_trim": U_TRIM.tolist()})


# ------------------------------------------------------------------------------- units of a CSV


@pytest.fixture(scope="module")
def synthetic_csv_flight():
    """One of our own synthetic flights (60 s, seed 3)."""
    from identification.bench.synthetic import simulate_flight

    return simulate_flight(60.0, seed=3).flight


@pytest.mark.parametrize("with_attitude", [True, False], ids=["with-attitude", "without-attitude"])
def test_rates_in_deg_per_s_are_refused_naming_deg_per_s(tmp_path, synthetic_csv_flight, with_attitude):
    f = synthetic_csv_flight
    cols = [f.time, *np.degrees(f.rates)] + ([*f.attitude] if with_attitude else []) + [*f.sticks]
    header = HEADER if with_attitude else "time,p,q,r,lat,lon,col,ped"
    path = _write(tmp_path / "deg.csv", header, np.column_stack(cols))
    with pytest.raises(UnitError, match=rf"^{re.escape(str(path))}: .*look like deg/s.*expected rad/s"):
        read_csv_flight(path)


def test_heli_identify_refuses_a_deg_per_s_flight_with_exit_2(tmp_path, synthetic_csv_flight, capsys):
    from heli_cli.main import main

    f = synthetic_csv_flight
    path = _write(tmp_path / "deg.csv", HEADER, np.column_stack([f.time, *np.degrees(f.rates), *f.attitude,
                                                                 *f.sticks]))
    assert main(["identify", str(path), "--out", str(tmp_path / "model"), "--no-plots"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "UnitError" in err[0] and "deg/s" in err[0]
    assert not (tmp_path / "model").exists()


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.__setitem__((slice(None), 0), d[:, 0] * 1e3), r"it looks like milliseconds \(a 100 Hz log\)"),
    (lambda d: d.__setitem__((slice(None), 7), 1500 + 500 * d[:, 7]), r"they look like PWM pulse widths in us"),
    (lambda d: d.__setitem__((slice(None), 10), 500 * np.sin(d[:, 0])), r"Betaflight rcCommand units \(\+-500\)"),
], ids=["time-ms", "sticks-pwm", "sticks-rccommand"])
def test_other_units_in_a_csv_are_named(tmp_path, edit, message):
    data = _canonical()
    edit(data)
    path = _write(tmp_path / "units.csv", HEADER, data)
    with pytest.raises(UnitError, match=message):
        read_csv_flight(path)


# ------------------------------------------------------------------ hostile inputs (issue 15)
@pytest.mark.parametrize(
    "content, message",
    [
        (b"\x82\xff\x00binary", r"servo calibration '.*cal\.json' is not a readable JSON file: 'utf-8' codec"),
        (b"[1, 2, 3]", r"servo calibration must be a JSON object with keys 'G' \(4x4\) and 'U_trim' \(4\), got a list"),
        (b'{"G": "fast", "U_trim": [1, 2, 3, 4]}', r"servo calibration: G' \(4x4\) and U_trim \(4\) must be numbers"),
        (b'{"G": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "U_trim": [1.5, NaN, 1.5, 1.5]}',
         r"servo trim U_trim must be finite numbers, got \[1\.5, nan, 1\.5, 1\.5\]"),
    ],
    ids=["binary", "list", "strings", "nan-trim"],
)
def test_hostile_servo_calibration_files(tmp_path, content, message):
    path, _ = _servo_log(tmp_path)
    (tmp_path / "cal.json").write_bytes(content)
    with pytest.raises(FlightLogError, match=message):
        read_servo_csv(path, tmp_path / "cal.json")


def test_a_folder_or_a_pipe_is_refused_not_read(tmp_path):
    """A pipe given as the flight would block the reader for ever; a folder is named as one."""
    import os

    os.mkfifo(tmp_path / "pipe.csv")
    (tmp_path / "folder.csv").mkdir()
    with pytest.raises(FlightLogError, match=r"pipe\.csv: not a regular file \(a pipe, socket or device\)"):
        read_flight(tmp_path / "pipe.csv")
    with pytest.raises(FlightLogError, match=r"folder\.csv: a folder; expected a flight log file"):
        read_flight(tmp_path / "folder.csv")
    with pytest.raises(FlightLogError, match=r"'.*pipe\.csv' is not a regular file; expected a CSV file"):
        read_csv_flight(tmp_path / "pipe.csv")


@pytest.mark.parametrize("separator, decimal", [(";", ","), (";", "."), ("\t", ".")])
def test_a_spreadsheet_export_with_another_separator_reads_the_same(tmp_path, simulated, separator, decimal):
    """Spreadsheets in much of Europe write ``;`` between fields and a decimal comma; others write tabs."""
    t, rates, sticks, att = simulated
    comma = tmp_path / "flight.csv"
    _write(comma, HEADER, np.column_stack([t, *rates, *att, *sticks]))
    other = tmp_path / "export.csv"
    text = comma.read_text().replace(",", separator)
    other.write_text(text.replace(".", decimal))
    a, b = read_flight(comma), read_flight(other)
    assert_array_equal(b.time, a.time)
    assert_array_equal(b.rates, a.rates)
    assert_array_equal(b.sticks, a.sticks)


def test_column_names_are_read_in_any_case(tmp_path, simulated):
    t, rates, sticks, att = simulated
    rows = np.column_stack([t, *rates, *att, *sticks])
    _write(tmp_path / "a.csv", HEADER, rows)
    _write(tmp_path / "b.csv", ",".join(c.capitalize() for c in CSV_COLUMNS), rows)
    a, b = read_flight(tmp_path / "a.csv"), read_flight(tmp_path / "b.csv")
    assert_array_equal(b.rates, a.rates)
    assert_array_equal(b.attitude, a.attitude)
    _write(tmp_path / "c.csv", HEADER + ",P", np.column_stack([rows, rows[:, 1]]))
    with pytest.raises(FlightLogError, match=r"duplicated column\(s\) \['p'\]"):
        read_flight(tmp_path / "c.csv")
