"""The in-memory flight every loader produces and every algorithm consumes.

A :class:`Flight` is built once at the edge (CSV reader, log importers, the
synthetic generator) by :func:`make_flight`, which validates everything and
raises :class:`~identification.errors.FlightLogError` with a message naming the
column, row and time of the problem. Past that point the code trusts the arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType

import numpy as np

from .errors import FlightLogError

RATE_COLUMNS = ("p", "q", "r")
ATTITUDE_COLUMNS = ("phi", "theta", "psi")
STICK_COLUMNS = ("lat", "lon", "col", "ped")
REQUIRED_COLUMNS = ("time",) + RATE_COLUMNS + STICK_COLUMNS
CSV_COLUMNS = ("time",) + RATE_COLUMNS + ATTITUDE_COLUMNS + STICK_COLUMNS
"""Canonical CSV header: time,p,q,r,phi,theta,psi,lat,lon,col,ped (SI units, sticks in [-1, 1])."""

MAX_PLAUSIBLE_RATE = 35.0
"""rad/s (~2000 deg/s): beyond any MEMS gyro range, so larger values mean deg/s were logged."""
GAP_FACTOR = 1.5
"""A sample interval longer than this many median intervals is a gap."""
STICK_TOLERANCE = 1e-6


@dataclass(frozen=True, eq=False)
class Flight:
    """One flight: time, body rates, attitude, sticks and metadata.

    Use :func:`make_flight` (or a loader) to build one; it validates the arrays.

    Attributes
    ----------
    time : ndarray, shape (n,)
        Sample times [s], strictly increasing, uniformly sampled.
    rates : ndarray, shape (3, n)
        Body rates p, q, r [rad/s].
    attitude : ndarray, shape (3, n)
        Euler angles phi, theta, psi [rad] (measured, or reconstructed from the
        rates with eqs. 25-29 when the log has none; see ``metadata``).
    sticks : ndarray, shape (4, n)
        lat, lon, col, ped in [-1, 1]; lat drives roll, lon pitch, ped yaw.
    metadata : mapping
        Free-form provenance: source file, SHA-256, units, input source,
        ``attitude_source`` ("measured" or "reconstructed") ...
    extra : mapping of str to ndarray (n,)
        Extra columns of the log, kept as they came.
    """

    time: np.ndarray
    rates: np.ndarray
    attitude: np.ndarray
    sticks: np.ndarray
    metadata: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    extra: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))

    # Named views -------------------------------------------------------------
    p = property(lambda self: self.rates[0], doc="Roll rate [rad/s].")
    q = property(lambda self: self.rates[1], doc="Pitch rate [rad/s].")
    r = property(lambda self: self.rates[2], doc="Yaw rate [rad/s].")
    phi = property(lambda self: self.attitude[0], doc="Roll angle [rad].")
    theta = property(lambda self: self.attitude[1], doc="Pitch angle [rad].")
    psi = property(lambda self: self.attitude[2], doc="Yaw angle [rad].")
    lat = property(lambda self: self.sticks[0], doc="Lateral cyclic stick [-1, 1].")
    lon = property(lambda self: self.sticks[1], doc="Longitudinal cyclic stick [-1, 1].")
    col = property(lambda self: self.sticks[2], doc="Collective stick [-1, 1].")
    ped = property(lambda self: self.sticks[3], doc="Pedal stick [-1, 1].")

    @property
    def n(self) -> int:
        """Number of samples."""
        return self.time.size

    @cached_property
    def dt(self) -> float:
        """Sample interval [s] (median; computed once)."""
        return float(np.median(np.diff(self.time)))

    @property
    def sample_rate(self) -> float:
        """Sample rate [Hz]."""
        return 1.0 / self.dt

    @property
    def duration(self) -> float:
        """Time span [s]."""
        return float(self.time[-1] - self.time[0])

    def column(self, name: str) -> np.ndarray:
        """A canonical or extra column by name."""
        if name == "time":
            return self.time
        if name in RATE_COLUMNS:
            return self.rates[RATE_COLUMNS.index(name)]
        if name in ATTITUDE_COLUMNS:
            return self.attitude[ATTITUDE_COLUMNS.index(name)]
        if name in STICK_COLUMNS:
            return self.sticks[STICK_COLUMNS.index(name)]
        if name in self.extra:
            return self.extra[name]
        raise KeyError(f"flight has no column {name!r}")

    def segment(self, t0: float, t1: float) -> "Flight":
        """The part of the flight with ``t0 <= time <= t1`` (time kept as is)."""
        m = (self.time >= t0) & (self.time <= t1)
        if m.sum() < 2:
            raise FlightLogError(
                f"segment [{t0}, {t1}] s holds {int(m.sum())} samples; the flight spans "
                f"[{self.time[0]:.3f}, {self.time[-1]:.3f}] s"
            )
        return Flight(
            self.time[m], self.rates[:, m], self.attitude[:, m], self.sticks[:, m],
            MappingProxyType({**self.metadata, "segment": [float(t0), float(t1)]}),
            MappingProxyType({k: v[m] for k, v in self.extra.items()}),
        )

    def __reduce__(self):
        """Pickle (to worker processes, :mod:`identification.backends`) with the read-only mappings as dicts."""
        return _unpickle_flight, (self.time, self.rates, self.attitude, self.sticks, dict(self.metadata),
                                  dict(self.extra))

    def with_metadata(self, **items) -> "Flight":
        """A copy with metadata items added or replaced."""
        return Flight(self.time, self.rates, self.attitude, self.sticks,
                      MappingProxyType({**self.metadata, **items}), self.extra)


def _unpickle_flight(time, rates, attitude, sticks, metadata, extra) -> Flight:
    return Flight(time, rates, attitude, sticks, MappingProxyType(metadata), MappingProxyType(extra))


def _check_finite(name: str, values: np.ndarray, time: np.ndarray | None) -> None:
    bad = ~np.isfinite(values)
    if bad.any():
        first = int(np.argmax(bad))
        kind = "NaN" if np.isnan(values[first]) else "inf"
        when = f" (t={time[first]:.2f} s)" if time is not None and np.isfinite(time[first]) else ""
        raise FlightLogError(
            f"column {name!r} has {int(bad.sum())} non-finite values ({kind} first), "
            f"first at row {first}{when}; expected finite numbers"
        )


def _check_time(time: np.ndarray) -> None:
    if time.size < 2:
        raise FlightLogError(f"a flight needs at least 2 samples, got {time.size}")
    dt = np.diff(time)
    bad = dt <= 0
    if bad.any():
        i = int(np.argmax(bad))
        what = "duplicated" if dt[i] == 0 else "decreasing"
        raise FlightLogError(
            f"time must be strictly increasing; it is {what} at row {i + 1} "
            f"(t={time[i]:.4f} s then t={time[i + 1]:.4f} s)"
        )
    med = float(np.median(dt))
    gaps = dt > GAP_FACTOR * med
    if gaps.any():
        i = int(np.argmax(gaps))
        raise FlightLogError(
            f"sampling gap: {int(gaps.sum())} interval(s) longer than {GAP_FACTOR}x the median "
            f"{med * 1e3:.2f} ms; the first is {dt[i] * 1e3:.2f} ms between rows {i} and {i + 1} "
            f"(t={time[i]:.3f} s to {time[i + 1]:.3f} s). "
            "Expected uniform sampling: cut the flight into segments or resample it"
        )


def _check_rates_units(rates: np.ndarray, attitude: np.ndarray | None, time: np.ndarray) -> None:
    peak = np.abs(rates).max(axis=1)
    for i, name in enumerate(RATE_COLUMNS):
        if peak[i] > MAX_PLAUSIBLE_RATE:
            raise FlightLogError(
                f"column {name!r} reaches {peak[i]:.1f}, beyond {MAX_PLAUSIBLE_RATE} rad/s "
                f"({np.degrees(MAX_PLAUSIBLE_RATE):.0f} deg/s): it looks like deg/s; "
                "expected rad/s (multiply by pi/180)"
            )
    if attitude is None:
        return
    # With attitude present: the Euler-angle derivative and the body rate agree for
    # small angles. A ratio near pi/180 between them means the rates are in deg/s.
    for i, name in enumerate(RATE_COLUMNS[:2]):
        ang = np.unwrap(attitude[i])
        dang = np.gradient(ang, time)
        w = rates[i]
        denom = float(w @ w)
        if denom <= 0 or np.std(dang) < 1e-3 or np.ptp(w) == 0.0:  # constant w: no correlation to test
            continue
        slope = float(dang @ w) / denom
        corr = float(np.corrcoef(dang, w)[0, 1])
        if corr > 0.8 and 0.3 / 57.3 < slope < 3.0 / 57.3:
            raise FlightLogError(
                f"column {name!r} is about 57x the rate of change of "
                f"{ATTITUDE_COLUMNS[i]!r} (slope {slope:.4f}, correlation {corr:.2f}): it looks like deg/s; "
                "expected rad/s"
            )


def make_flight(time, rates, sticks, attitude=None, metadata=None, extra=None) -> Flight:
    """Validate arrays and build a :class:`Flight`.

    Parameters
    ----------
    time : array_like, shape (n,)
        Sample times [s].
    rates : array_like, shape (3, n)
        p, q, r [rad/s].
    sticks : array_like, shape (4, n)
        lat, lon, col, ped in [-1, 1].
    attitude : array_like, shape (3, n), optional
        phi, theta, psi [rad]. When absent it is reconstructed from the rates
        with the quaternion equations (25)-(29), starting level.
    metadata : dict, optional
    extra : dict of str to array_like (n,), optional
        Extra columns, kept as metadata.

    Raises
    ------
    FlightLogError
        Shapes, non-finite values, a time base that is not strictly increasing
        or has gaps, rates that look like deg/s, sticks outside [-1, 1].
    """
    # np.array copies: the Flight owns its arrays and the caller's are left writable.
    time = np.array(time, dtype=float)
    if time.ndim != 1:
        raise FlightLogError(f"time must be 1-D, got shape {time.shape}")
    n = time.size
    arrays = {"rates": (rates, 3), "sticks": (sticks, 4)}
    if attitude is not None:
        arrays["attitude"] = (attitude, 3)
    conv = {}
    for key, (arr, rows) in arrays.items():
        a = np.array(arr, dtype=float)
        if a.shape != (rows, n):
            raise FlightLogError(f"{key} must have shape ({rows}, {n}) to match time, got {a.shape}")
        conv[key] = a
    _check_finite("time", time, None)
    names = {"rates": RATE_COLUMNS, "sticks": STICK_COLUMNS, "attitude": ATTITUDE_COLUMNS}
    for key, a in conv.items():
        for i, name in enumerate(names[key]):
            _check_finite(name, a[i], time)
    _check_time(time)
    _check_rates_units(conv["rates"], conv.get("attitude"), time)
    s = conv["sticks"]
    for i, name in enumerate(STICK_COLUMNS):
        out = np.abs(s[i]) > 1.0 + STICK_TOLERANCE
        if out.any():
            first = int(np.argmax(out))
            raise FlightLogError(
                f"stick column {name!r} has {int(out.sum())} values outside [-1, 1] "
                f"(range {s[i].min():.3f}..{s[i].max():.3f}), first at row {first} (t={time[first]:.2f} s); "
                "expected sticks normalised to [-1, 1]"
            )
    meta = dict(metadata or {})
    if "attitude" in conv:
        att = conv["attitude"]
        meta.setdefault("attitude_source", "measured")
    else:
        from .attitude import attitude_from_rates

        att = attitude_from_rates(time, conv["rates"])
        meta["attitude_source"] = "reconstructed"
    ex = {}
    for k, v in (extra or {}).items():
        v = np.array(v)
        if v.shape != (n,):
            raise FlightLogError(f"extra column {k!r} must have {n} values, got shape {v.shape}")
        ex[k] = v
    for a in (time, conv["rates"], att, s, *ex.values()):
        a.setflags(write=False)
    return Flight(time, conv["rates"], att, s, MappingProxyType(meta), MappingProxyType(ex))
