"""The in-memory flight every loader produces and every algorithm consumes.

A :class:`Flight` is built once at the edge (CSV reader, log importers, the
synthetic generator) by :func:`make_flight`, which validates everything and
raises :class:`~identification.errors.FlightLogError` with a message naming the
column, row and time of the problem. Past that point the code trusts the arrays.

Units are checked by physics, not trusted (:class:`~identification.errors.UnitError`
names the suspected unit and the conversion):

* **time** -- a median sample interval beyond :data:`MAX_SAMPLE_INTERVAL_S` cannot
  resolve attitude dynamics; read as ms, us or ns it gives a logging rate.
* **rates against the attitude** -- the Euler-angle rates implied by p, q, r
  (ZYX kinematics) are integrated and compared with the logged angles, both
  band-passed (:data:`RATIO_BAND_HZ`: the high-pass removes the integrated gyro
  bias, the low-pass the sensor noise). For rad/s and rad the ratio is 1; deg/s
  gives 57.3, angles in degrees 1/57.3, time in ms 1000. Axes that barely move
  or correlate below :data:`RATIO_MIN_CORRELATION` do not count, and a ratio far
  from 1 refuses the flight only at a decisive correlation
  (:data:`RATIO_DECISIVE_CORRELATION`). This holds for noisy flights, where the
  derivative of the attitude does not (correlations of 0.07-0.18 on our own).
* **rates without a usable attitude** -- beyond any gyro's range
  (:data:`MAX_PLAUSIBLE_RATE`), or, for data whose units no format declares (a
  CSV), an RMS of the low-passed roll and pitch rates above
  :data:`HOVER_RATE_RMS_MAX` (a hovering helicopter stays far below it; the same
  flight in deg/s lies far above).
* **attitude** -- ZYX pitch lies within +-pi/2 rad.
* **sticks** -- values outside [-1, 1] are named by their likely unit (PWM us,
  +-500 rcCommand, percent, +-1000 mixer units).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType

import numpy as np

from heli_core.quaternion import euler_rates
from heli_core.sampling import is_uniform

from .errors import FlightLogError, UnitError

RATE_COLUMNS = ("p", "q", "r")
ATTITUDE_COLUMNS = ("phi", "theta", "psi")
STICK_COLUMNS = ("lat", "lon", "col", "ped")
REQUIRED_COLUMNS = ("time",) + RATE_COLUMNS + STICK_COLUMNS
CSV_COLUMNS = ("time",) + RATE_COLUMNS + ATTITUDE_COLUMNS + STICK_COLUMNS
"""Canonical CSV header: time,p,q,r,phi,theta,psi,lat,lon,col,ped (SI units, sticks in [-1, 1])."""

MAX_PLAUSIBLE_RATE = 35.0
"""rad/s (~2000 deg/s): beyond any MEMS gyro range, so larger values mean deg/s were logged."""
HOVER_RATE_RMS_MAX = 1.0
"""rad/s (57 deg/s): RMS of the low-passed roll and pitch rates no hovering helicopter reaches over a flight
(our aggressive synthetic pilot: 0.08; a 5-inch racing quad flown hard: 0.7). The same flights in deg/s: 2-5."""
HOVER_LOWPASS_HZ = 5.0
"""Hz: the rates are low-passed here before their RMS is taken (vibration and noise out)."""
RATIO_BAND_HZ = (0.1, 2.0)
"""Hz: band of the integrated-rate vs attitude comparison (the low edge at least 1/duration, the high edge at
most 0.4x the sample rate)."""
RATIO_MIN_CORRELATION = 0.5
"""An axis counts in the ratio when its band-passed integrated rate and angle correlate at least this well."""
RATIO_MIN_MOTION_RAD = np.radians(0.2)
"""rad: an axis counts when its band-passed angle moves at least this much (standard deviation)."""
RATIO_TOLERANCE = 3.0
"""A ratio within this factor of 1 passes."""
RATIO_UNIT_TOLERANCE = 2.0
"""A ratio within this factor of 57.3 (or 1/57.3, 1000, ...) names the unit, if the correlation is decisive."""
RATIO_DECISIVE_CORRELATION = 0.8
"""Least correlation (over the axes that count) for a ratio far from 1 to refuse the flight; below it the
comparison is inconclusive (an estimator still aligning on the ground, a bench log) and other checks decide."""
MAX_SAMPLE_INTERVAL_S = 0.5
"""s: a median sample interval longer than this (below 2 Hz) cannot describe attitude dynamics."""
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
        """Pickle (to worker processes, :mod:`heli_core.backends`) with the read-only mappings as dicts."""
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


def check_time_base(time: np.ndarray) -> None:
    """Refuse a time column that is not finite, has fewer than 2 samples, does not strictly increase or is not in
    seconds (:class:`FlightLogError`, :class:`UnitError`); whether it is uniform is checked apart (a CSV's
    clock is settled in between: :mod:`identification.io.csv_timing`)."""
    _check_finite("time", time, None)
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
    _check_time_units(time, dt)


def _check_time(time: np.ndarray) -> None:
    check_time_base(time)
    dt = np.diff(time)
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
    if not is_uniform(time):
        raise FlightLogError(
            f"time is not uniformly sampled: intervals range {dt.min() * 1e3:.6g}..{dt.max() * 1e3:.6g} ms around "
            f"the median {med * 1e3:.6g} ms; expected uniform sampling (a CSV read by read_log or read_csv_flight "
            "has its clock settled first: identification.io.csv_timing)"
        )


_TIME_UNITS = (("milliseconds", 1e-3, "divide by 1000"), ("microseconds", 1e-6, "divide by 1e6"),
               ("nanoseconds", 1e-9, "divide by 1e9"))


def _check_time_units(time: np.ndarray, dt: np.ndarray) -> None:
    med = float(np.median(dt))
    if med <= MAX_SAMPLE_INTERVAL_S:
        return
    rate = 1.0 / med
    for unit, factor, fix in _TIME_UNITS:
        if 1.0 / MAX_SAMPLE_INTERVAL_S <= 1.0 / (med * factor) <= 1e5:
            raise UnitError(
                f"time: the median sample interval is {med:g} ({rate:.3g} Hz if in seconds), too slow for attitude "
                f"dynamics; it looks like {unit} (a {1.0 / (med * factor):.4g} Hz log); expected seconds: {fix}"
            )
    raise UnitError(f"time: the median sample interval is {med:g} s ({rate:.3g} Hz), too slow for attitude dynamics "
                    f"(expected at most {MAX_SAMPLE_INTERVAL_S} s) and no unit (ms, us, ns) makes it a logging rate; "
                    "expected time in seconds")


_RATIO_UNITS = (
    (180.0 / np.pi, "the rates look like deg/s (57.3x the rate of change of the attitude); expected rad/s: "
                    "multiply p, q, r by pi/180"),
    (np.pi / 180.0, "the attitude looks like degrees (the rates are 1/57.3 of its rate of change); expected rad: "
                    "multiply phi, theta, psi by pi/180"),
    (1e3, "the time looks like milliseconds (the rates integrate to 1000x the attitude change); expected "
          "seconds: divide time by 1000"),
    (1e6, "the time looks like microseconds; expected seconds: divide time by 1e6"),
    (180.0 / np.pi * 1e3, "the rates look like deg/s and the time like milliseconds; expected rad/s and s"),
)


def rate_attitude_ratio(time: np.ndarray, rates: np.ndarray, attitude: np.ndarray) -> dict | None:
    """How the integrated body rates compare with the logged attitude: 1 for rad/s and rad (module docstring).

    The Euler-angle rates implied by p, q, r (ZYX: ``phi' = p + (q sin phi + r cos phi) tan theta``,
    ``theta' = q cos phi - r sin phi``, ``psi' = (q sin phi + r cos phi) / cos theta``) are integrated
    (trapezoids) and regressed on the unwrapped angles after both are band-passed.

    Parameters
    ----------
    time : ndarray, shape (n,)
        [s], strictly increasing.
    rates : ndarray, shape (3, n)
    attitude : ndarray, shape (3, n)

    Returns
    -------
    dict or None
        ``{"ratio": combined ratio over the axes that count, "correlation": their combined correlation,
        "axes": {axis: {"ratio", "correlation"}}, "counted": [axes]}``; None when the flight is too short or
        slow for the band, or no axis counts.
    """
    from scipy import signal

    n = time.size
    duration = float(time[-1] - time[0])
    fs = (n - 1) / duration if duration > 0 else 0.0
    low, high = max(RATIO_BAND_HZ[0], 1.0 / max(duration, 1e-9)), min(RATIO_BAND_HZ[1], 0.4 * fs)
    if not (low < high) or n < 60:
        return None
    phi, theta, psi = np.unwrap(attitude, axis=1)
    p, q, r = rates
    with np.errstate(all="ignore"):
        angle_rates = euler_rates(phi, theta, p, q, r)
    if not np.isfinite(angle_rates).all():
        return None
    steps = 0.5 * (angle_rates[:, 1:] + angle_rates[:, :-1]) * np.diff(time)
    integrated = np.concatenate([np.zeros((3, 1)), np.cumsum(steps, axis=1)], axis=1)
    sos = signal.butter(2, [low, high], btype="band", fs=fs, output="sos")
    a = signal.sosfiltfilt(sos, np.array([phi, theta, psi]), axis=1)
    b = signal.sosfiltfilt(sos, integrated, axis=1)
    axes, num, den, other, counted = {}, 0.0, 0.0, 0.0, []
    for i, axis in enumerate(("roll", "pitch", "yaw")):
        sa, sb = float(np.std(a[i])), float(np.std(b[i]))
        if sa < 1e-12 or sb < 1e-12:
            continue
        corr = float(np.mean((a[i] - a[i].mean()) * (b[i] - b[i].mean())) / (sa * sb))
        ratio = float(a[i] @ b[i]) / float(a[i] @ a[i])
        axes[axis] = {"ratio": round(ratio, 4), "correlation": round(corr, 4)}
        if corr >= RATIO_MIN_CORRELATION and sa >= RATIO_MIN_MOTION_RAD:
            num += float(a[i] @ b[i])
            den += float(a[i] @ a[i])
            other += float(b[i] @ b[i])
            counted.append(axis)
    if not counted:
        return None
    return {"ratio": num / den, "correlation": num / np.sqrt(den * other), "axes": axes, "counted": counted}


def _check_rates_units(rates: np.ndarray, attitude: np.ndarray | None, time: np.ndarray,
                       units_from: str | None) -> dict:
    """Check p, q, r are rad/s (and the attitude rad); return what was checked (for the metadata)."""
    peak = np.abs(rates).max(axis=1)
    for i, name in enumerate(RATE_COLUMNS):
        if peak[i] > MAX_PLAUSIBLE_RATE:
            if units_from:
                raise UnitError(
                    f"column {name!r} reaches {peak[i]:.4g} rad/s as read from the {units_from}, beyond any gyro's "
                    f"range ({MAX_PLAUSIBLE_RATE} rad/s, {np.degrees(MAX_PLAUSIBLE_RATE):.0f} deg/s): the gyro data "
                    "is corrupt or the log's gyro scale is wrong"
                )
            raise UnitError(
                f"column {name!r} reaches {peak[i]:.1f}, beyond {MAX_PLAUSIBLE_RATE} rad/s "
                f"({np.degrees(MAX_PLAUSIBLE_RATE):.0f} deg/s): it looks like deg/s; "
                "expected rad/s (multiply by pi/180)"
            )
    if attitude is not None:
        theta_peak = float(np.abs(attitude[1]).max())
        if theta_peak > np.pi / 2 + 1e-3 and units_from:
            raise UnitError(f"column 'theta' reaches {theta_peak:.4g} rad as read from the {units_from}, beyond "
                            "pi/2 where no ZYX pitch angle lies: the attitude data is corrupt")
        if theta_peak > np.pi / 2 + 1e-3:
            raise UnitError(
                f"column 'theta' reaches {theta_peak:.4g}, beyond pi/2: a ZYX pitch angle in rad lies within "
                "+-1.571; it looks like degrees; expected rad (multiply phi, theta, psi by pi/180)"
            )
        found = rate_attitude_ratio(time, rates, attitude)
        if found is not None:
            ratio, corr = found["ratio"], found["correlation"]
            detail = ", ".join(f"{a} {found['axes'][a]['ratio']:.3g}" for a in found["counted"])
            record = {"ratio": round(ratio, 4), "correlation": round(corr, 4), "axes": found["axes"]}
            if ratio > 0 and abs(np.log(ratio)) <= np.log(RATIO_TOLERANCE):
                return {"rates": "rad/s: integrated rates match the attitude", **record}
            if corr >= RATIO_DECISIVE_CORRELATION and ratio != 0:
                unit = min(_RATIO_UNITS, key=lambda u: abs(np.log(abs(ratio) / u[0])))
                if ratio > 0 and abs(np.log(ratio / unit[0])) <= np.log(RATIO_UNIT_TOLERANCE):
                    raise UnitError(f"the integrated rates are {ratio:.4g}x the change of the attitude ({detail}; "
                                    f"correlation {corr:.2f}): {unit[1]}")
                if not units_from:
                    raise UnitError(
                        f"the integrated rates are {ratio:.4g}x the change of the attitude ({detail}, band-passed "
                        f"{RATIO_BAND_HZ[0]}-{RATIO_BAND_HZ[1]} Hz, correlation {corr:.2f}; 1 for rad/s and rad): "
                        "rates and attitude disagree on units or signs; expected p, q, r in rad/s and phi, theta, "
                        "psi in rad of the same body axes"
                    )
            if units_from:
                return {"rates": f"rad/s as declared by the {units_from}; the comparison with the attitude is "
                                 "inconclusive", **record}
    if units_from:
        return {"rates": f"rad/s as declared by the {units_from} (no attitude to check against)"}
    return _check_hover_range(rates, time)


def _check_hover_range(rates: np.ndarray, time: np.ndarray) -> dict:
    """Rates without a usable attitude and without declared units: the physical range of a hovering helicopter."""
    from scipy import signal

    n = time.size
    duration = float(time[-1] - time[0])
    fs = (n - 1) / duration if duration > 0 else 0.0
    cutoff = min(HOVER_LOWPASS_HZ, 0.4 * fs)
    pq = rates[:2]
    if n > 30 and cutoff > 0:
        sos = signal.butter(2, cutoff, fs=fs, output="sos")
        pq = signal.sosfiltfilt(sos, pq, axis=1)
    rms = float(np.sqrt(np.mean(pq * pq)))
    if rms > HOVER_RATE_RMS_MAX:
        raise UnitError(
            f"columns 'p' and 'q' have an RMS of {rms:.3g} (low-passed at {cutoff:.3g} Hz): a hovering helicopter's "
            f"roll and pitch rates stay well below {HOVER_RATE_RMS_MAX} rad/s "
            f"({np.degrees(HOVER_RATE_RMS_MAX):.0f} deg/s) RMS; they look like deg/s; expected rad/s (multiply "
            "p, q, r by pi/180). If the flight really is this aggressive, add the columns phi, theta, psi: the rates "
            "are then checked against the attitude instead"
        )
    return {"rates": "rad/s: within a hovering helicopter's range (no attitude to check against)",
            "roll_pitch_rms_rad_s": round(rms, 4)}


def _stick_unit(values: np.ndarray) -> str:
    """The unit sticks outside [-1, 1] seem to be in, with the conversion, or '' when none fits."""
    lo, hi = float(values.min()), float(values.max())
    peak = max(abs(lo), abs(hi))
    if lo >= 700.0 and hi <= 2300.0:
        return ("they look like PWM pulse widths in us (1000..2000, centre 1500): normalise as (x - 1500) / 500 "
                "(or use the servo columns u_aile, u_aux, u_elev, u_rudd with --inputs servos)")
    if peak <= 1.5:
        return ""
    if peak <= 100.0:
        return "they look like percent (+-100): divide by 100"
    if peak <= 520.0:
        return "they look like Betaflight rcCommand units (+-500): divide by 500"
    if peak <= 1050.0:
        return "they look like mixer units (+-1000) or per mille (0..1000): divide by 1000, or x / 500 - 1"
    return ""


def _check_sticks(s: np.ndarray, time: np.ndarray) -> None:
    for i, name in enumerate(STICK_COLUMNS):
        out = np.abs(s[i]) > 1.0 + STICK_TOLERANCE
        if out.any():
            first = int(np.argmax(out))
            unit = _stick_unit(s[i])
            error = UnitError if unit else FlightLogError
            raise error(
                f"stick column {name!r} has {int(out.sum())} values outside [-1, 1] "
                f"(range {s[i].min():.3f}..{s[i].max():.3f}), first at row {first} (t={time[first]:.2f} s); "
                + (f"{unit}; " if unit else "") + "expected sticks normalised to [-1, 1]"
            )


def make_flight(time, rates, sticks, attitude=None, metadata=None, extra=None, units_from: str | None = None) -> Flight:
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
    units_from : str, optional
        The format that declares the units (an importer: ``"px4-ulog log"``). The
        rates are still checked against the attitude and the gyro range, but not
        against the hover range that guards files of undeclared units (a CSV).

    Raises
    ------
    UnitError
        Time, rates, attitude or sticks in another unit (module docstring); the
        message names it and the conversion.
    FlightLogError
        Shapes, non-finite values, a time base that is not strictly increasing
        or has gaps, sticks outside [-1, 1].
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
    checked = _check_rates_units(conv["rates"], conv.get("attitude"), time, units_from)
    s = conv["sticks"]
    _check_sticks(s, time)
    meta = dict(metadata or {})
    meta["units_check"] = checked
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
