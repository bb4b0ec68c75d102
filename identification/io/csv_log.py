"""The canonical CSV flight log, and raw servo logs converted with eqs. (65)-(67).

Canonical CSV (one header line, comma separated, SI units)::

    time,p,q,r,phi,theta,psi,lat,lon,col,ped

``time`` [s]; ``p, q, r`` body rates [rad/s]; ``phi, theta, psi`` Euler angles
[rad] (optional: reconstructed from the rates with eqs. 25-29 when absent);
``lat, lon, col, ped`` sticks normalised to [-1, 1] (lat drives roll, lon pitch,
ped yaw, col is collective). Any further column is kept as an extra column.
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np

from heli_core.files import atomic_path, sha256_of

from ..errors import FlightLogError
from ..flight import (
    ATTITUDE_COLUMNS, CSV_COLUMNS, RATE_COLUMNS, REQUIRED_COLUMNS, STICK_COLUMNS, Flight, _check_finite,
    check_time_base, make_flight,
)
from .csv_timing import regular_columns, rows_of_the_rates

SERVO_COLUMNS = ("u_aile", "u_aux", "u_elev", "u_rudd")
"""Servo pulse widths of eq. (65), in the order of its left-hand side."""
SERVO_STICK_ORDER = ("lon", "lat", "col", "ped")
"""Order of the stick vector delta in eqs. (65)-(67)."""


def _read_table(path: Path) -> tuple[list[str], np.ndarray, dict | None]:
    """The header, the columns (k, n) and, where fields were empty, which rows of each column were (None if none)."""
    if not path.exists():
        raise FlightLogError(f"flight log {str(path)!r} does not exist")
    if not path.is_file():  # a folder, or a pipe that reading would block on for ever
        raise FlightLogError(f"flight log {str(path)!r} is {'a folder' if path.is_dir() else 'not a regular file'}; "
                             "expected a CSV file")
    header, source = csv_header(path)
    if not header or header == [""]:
        raise FlightLogError(f"{path}: empty file; expected a header line {','.join(CSV_COLUMNS)}")
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise FlightLogError(f"{path}: duplicated column(s) {dup} in the header")
    blank = None
    try:
        data = np.loadtxt(source, delimiter=",", skiprows=1, ndmin=2, dtype=float)
    except ValueError as e:  # an empty field is a value not logged on that row (a slower stream); else refused
        data, blank = _read_with_blanks(path, source, len(header), e)
    if data.shape[0] == 0:
        raise FlightLogError(f"{path}: header but no data rows")
    if data.shape[1] != len(header):
        raise FlightLogError(f"{path}: header names {len(header)} columns but rows have {data.shape[1]}")
    return header, data.T, (None if blank is None else dict(zip(header, blank.T)))


def csv_header(path) -> tuple[list[str], object]:
    """A CSV's column names, the canonical ones in their own case (``Time`` is ``time``), and what ``np.loadtxt``
    reads its table from (:func:`_comma_separated`)."""
    path = Path(path)
    with open(path, encoding="utf-8-sig", errors="replace") as fh:  # -sig: drop a spreadsheet BOM
        header_line = fh.readline()
    source, delimiter = _comma_separated(path, header_line)
    known = {c.lower(): c for c in (*CSV_COLUMNS, *SERVO_COLUMNS)}
    return [known.get(h.strip().lower(), h.strip()) for h in header_line.strip().split(delimiter)], source


def _comma_separated(path: Path, header_line: str):
    """What ``np.loadtxt`` reads the table from, comma separated, and the file's own separator: the path itself
    for a comma-separated file; for one separated by ``;`` (a spreadsheet's export where the decimal mark is a
    comma, which is then read as a point) or by tabs, its text so rewritten."""
    if "," in header_line or not any(d in header_line for d in ";\t"):
        return path, ","
    delimiter = ";" if ";" in header_line else "\t"
    text = path.read_text(encoding="utf-8-sig", errors="replace")
    if delimiter == ";":
        text = text.replace(",", ".")
    return io.StringIO(text.replace(delimiter, ",")), delimiter


def _read_with_blanks(path: Path, source, width: int, error: ValueError) -> tuple[np.ndarray, np.ndarray]:
    """The table of a CSV (read from ``source``: :func:`_comma_separated`) some of whose fields are empty (NaN
    there) and which fields are, (n, width) each; ``error`` (numpy's) re-raised as :class:`FlightLogError` where
    a field is neither a number nor empty."""
    rows, blank = [], []
    if isinstance(source, io.StringIO):
        source.seek(0)
    with (open(source, encoding="utf-8-sig", errors="replace") if isinstance(source, Path)
          else contextlib.nullcontext(source)) as fh:
        fh.readline()
        for number, line in enumerate(fh, start=1):
            if not line.strip():
                continue
            fields = [f.strip() for f in line.rstrip("\r\n").split(",")]
            if len(fields) != width:
                raise FlightLogError(f"{path}: header names {width} columns but row {number} has {len(fields)}")
            try:
                rows.append([float(f) if f else np.nan for f in fields])
            except ValueError:
                raise FlightLogError(f"{path}: expected numbers in every field after the header: {error}") from error
            blank.append([not f for f in fields])
    return np.array(rows, dtype=float).reshape(-1, width), np.array(blank, dtype=bool).reshape(-1, width)


def _attitude_columns(path: Path, header: list[str], get: dict) -> np.ndarray | None:
    """The (3, n) attitude if the log has phi, theta, psi; None if it has none of them."""
    att_present = [c for c in ATTITUDE_COLUMNS if c in header]
    if att_present and len(att_present) != 3:
        raise FlightLogError(f"{path}: attitude columns must be all of phi,theta,psi or none; found {att_present}")
    return np.array([get[c] for c in ATTITUDE_COLUMNS]) if att_present else None


def _on_uniform_clock(path: Path, get: dict, segment, blank: dict | None = None) -> tuple[dict, dict]:
    """The columns ``get`` with their time checked and made uniform (:func:`.csv_timing.regular_columns`), and
    the metadata that says how: ``resampling``, and ``import_warnings`` where samples were interpolated. Where
    fields were empty (``blank``: name -> rows), the rows of the rates are read first, the other columns
    interpolated onto them (:func:`.csv_timing.rows_of_the_rates`)."""
    warnings = []
    try:
        check_time_base(get["time"])  # (the rows of the rates below are some of its rows: their time holds too)
    except FlightLogError as e:
        raise type(e)(f"{path}: {e}") from None
    if blank is not None:
        get, note = rows_of_the_rates(path, get, blank, RATE_COLUMNS,
                                      STICK_COLUMNS + ATTITUDE_COLUMNS + SERVO_COLUMNS, ATTITUDE_COLUMNS)
        warnings.append(note)
    try:
        for name in (*CSV_COLUMNS[1:], *SERVO_COLUMNS):  # before any is interpolated: rows as in the file
            if name in get:
                _check_finite(name, get[name], get["time"])
    except FlightLogError as e:
        raise type(e)(f"{path}: {e}") from None
    get, resampling, stretch = regular_columns(path, get, ATTITUDE_COLUMNS, segment)
    meta = {} if stretch is None else {"segment": stretch}  # one stretch of several
    if resampling is not None:
        meta["resampling"] = resampling
        if "note" in resampling:
            warnings.append(resampling["note"])
    if warnings:
        meta["import_warnings"] = warnings
    return get, meta


def read_csv_flight(path, segment=None) -> Flight:
    """Read a canonical CSV flight log into a validated :class:`Flight`.

    The time column is made uniform first where it is not (a clock rounded to a millisecond, jitter, missing
    samples: :mod:`identification.io.csv_timing`; recorded in ``metadata["resampling"]``).

    Parameters
    ----------
    path : str or Path
    segment : None, "all" or (t0, t1)
        Where the logging stopped during the flight: the stretch to read (``"all"`` the longest); otherwise
        unused (the caller cuts the flight).

    Raises
    ------
    FlightLogError
        Missing required columns, non-numeric fields, and everything
        :func:`identification.flight.make_flight` checks.
    SegmentError
        The logging stopped during the flight and ``segment`` does not choose one stretch.
    """
    path = Path(path)
    header, cols, blank = _read_table(path)
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise FlightLogError(
            f"{path}: missing required column(s) {missing}; expected at least "
            f"{','.join(REQUIRED_COLUMNS)}, found {','.join(header)}"
        )
    get, clock_meta = _on_uniform_clock(path, {name: cols[i] for i, name in enumerate(header)}, segment, blank)
    attitude = _attitude_columns(path, header, get)
    extra = {k: v for k, v in get.items() if k not in CSV_COLUMNS}
    meta = {"source": path.name, "sha256": sha256_of(path), "format": "csv", **clock_meta}
    try:
        return make_flight(
            get["time"], np.array([get[c] for c in RATE_COLUMNS]), np.array([get[c] for c in STICK_COLUMNS]),
            attitude=attitude, metadata=meta, extra=extra,
        )
    except FlightLogError as e:
        raise type(e)(f"{path}: {e}") from None


def write_csv_flight(flight: Flight, path, extra: bool = True) -> Path:
    """Write a flight as a canonical CSV (atomically). Extra columns follow the canonical ones."""
    names = list(CSV_COLUMNS)
    cols = [flight.time, *flight.rates, *flight.attitude, *flight.sticks]
    if extra:
        for k, v in flight.extra.items():
            names.append(k)
            cols.append(np.asarray(v, dtype=float))
    with atomic_path(path) as tmp:
        np.savetxt(tmp, np.column_stack(cols), delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return Path(path)


def sticks_from_servos(servos, gain, trim) -> np.ndarray:
    """Convert servo pulse widths to sticks, eq. (67): ``delta = G'^-1 (U - U_trim)``.

    Parameters
    ----------
    servos : ndarray, shape (4, n)
        Pulse widths U_AILE, U_AUX, U_ELEV, U_RUDD (any unit, the same as the calibration).
    gain : ndarray, shape (4, 4)
        Mixing gain G' of eq. (66), mapping (lon, lat, col, ped) to pulse widths.
    trim : ndarray, shape (4,)
        Pulse widths U_trim at centred sticks, eq. (66).

    Returns
    -------
    ndarray, shape (4, n)
        Sticks in the canonical order lat, lon, col, ped.
    """
    try:
        G = np.asarray(gain, dtype=float)
        trim = np.asarray(trim, dtype=float)
    except (TypeError, ValueError) as e:  # strings, nested dicts, ragged lists
        raise FlightLogError(f"servo calibration: G' (4x4) and U_trim (4) must be numbers: {e}") from None
    if G.shape != (4, 4):
        raise FlightLogError(f"servo mixing gain G' must be 4x4, got shape {G.shape}")
    cond = np.linalg.cond(G)
    if not np.isfinite(cond) or cond > 1e8:
        raise FlightLogError(f"servo mixing gain G' is singular (condition number {cond:.3g}); cannot invert eq. (67)")
    if trim.size != 4:
        raise FlightLogError(f"servo trim U_trim must have 4 values, got shape {trim.shape}")
    if not np.isfinite(trim).all():
        raise FlightLogError(f"servo trim U_trim must be finite numbers, got {trim.tolist()}")
    trim = trim.reshape(4, 1)
    delta = np.linalg.solve(G, np.asarray(servos, dtype=float) - trim)  # (lon, lat, col, ped)
    order = [SERVO_STICK_ORDER.index(s) for s in STICK_COLUMNS]
    return delta[order]


def read_servo_csv(path, calibration, segment=None) -> Flight:
    """Read a raw servo log and convert it to sticks with eqs. (65)-(67).

    Parameters
    ----------
    path : str or Path
        CSV with ``time,p,q,r`` (optionally ``phi,theta,psi``) and the four servo
        pulse-width columns ``u_aile,u_aux,u_elev,u_rudd``.
    calibration : dict or str or Path
        ``{"G": 4x4 list, "U_trim": 4 list}`` or a JSON file holding it.
    segment : None, "all" or (t0, t1)
        As for :func:`read_csv_flight`: the stretch to read where the logging stopped during the flight.
    """
    path = Path(path)
    if not isinstance(calibration, dict):
        cal_path = Path(calibration)
        try:
            calibration = json.loads(cal_path.read_text())
        except (OSError, ValueError) as e:  # ValueError: not JSON, or not text (UnicodeDecodeError)
            raise FlightLogError(f"servo calibration {str(cal_path)!r} is not a readable JSON file: {e}") from e
    if not isinstance(calibration, dict):
        raise FlightLogError(f"servo calibration must be a JSON object with keys 'G' (4x4) and 'U_trim' (4), got "
                             f"a {type(calibration).__name__}")
    for key in ("G", "U_trim"):
        if key not in calibration:
            raise FlightLogError(f"servo calibration lacks {key!r}; expected keys 'G' (4x4) and 'U_trim' (4)")
    header, cols, blank = _read_table(path)
    need = ("time",) + RATE_COLUMNS + SERVO_COLUMNS
    missing = [c for c in need if c not in header]
    if missing:
        raise FlightLogError(f"{path}: missing column(s) {missing}; a servo log needs {','.join(need)}")
    get, clock_meta = _on_uniform_clock(path, {name: cols[i] for i, name in enumerate(header)}, segment, blank)
    servos = np.array([get[c] for c in SERVO_COLUMNS])
    sticks = sticks_from_servos(servos, calibration["G"], calibration["U_trim"])
    att = _attitude_columns(path, header, get)
    meta = {"source": path.name, "sha256": sha256_of(path), "format": "servo-csv",
            "input_source": "servos (eq. 67)", "servo_calibration": calibration, **clock_meta}
    extra = {k: v for k, v in get.items() if k not in need and k not in ATTITUDE_COLUMNS}
    try:
        return make_flight(get["time"], np.array([get[c] for c in RATE_COLUMNS]), sticks, attitude=att,
                           metadata=meta, extra=extra)
    except FlightLogError as e:
        raise type(e)(f"{path}: {e}") from None
