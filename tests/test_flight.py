"""Tests of :mod:`identification.flight`: the Flight object and make_flight's validation.

One ``pytest.raises(FlightLogError, match=...)`` per bad input class; each match
checks that the message names what was expected and what came.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from heli_core.params import ModelParams
from heli_core.physics import QUAT, simulate
from heli_core.quaternion import euler_from_quaternion
from identification.bench.flight_config import MANOEUVRE_CONFIG
from identification.bench.synthetic import simulate_flight
from identification.errors import FlightLogError, UnitError
from identification.flight import HOVER_RATE_RMS_MAX, Flight, make_flight, rate_attitude_ratio

DT = 0.01
N = 400


def _wrap(a):
    """Angles wrapped to (-pi, pi]."""
    return np.angle(np.exp(1j * a))


def _arrays(n=N, dt=DT, t0=0.0):
    """Valid flight arrays: smooth small rates [rad/s], attitude consistent with them [rad], sticks in [-1, 1]."""
    t = t0 + dt * np.arange(n)
    w = 2 * np.pi * 0.5
    attitude = np.array([0.1 * np.sin(w * t), 0.08 * np.cos(w * t), 0.05 * t])
    rates = np.array([0.1 * w * np.cos(w * t), -0.08 * w * np.sin(w * t), 0.05 + 0.0 * t])
    sticks = np.array([0.5 * np.sin(w * t), 0.4 * np.cos(w * t), 0.1 + 0.0 * t, -0.3 * np.sin(2 * w * t)])
    return t, rates, sticks, attitude


@pytest.fixture(scope="module")
def simulated():
    """A 20 s flight of a coupled model with servo delays (truth: time, rates, Euler angles, sticks)."""
    params = ModelParams(k1=-0.05, k2=8.0, k3=3.0, k4=0.5, kd1=0.1, k5=0.05, k6=6.0, k7=3.0, k8=0.4, kd2=-0.05,
                         k9=0.01, k10=10.0, k11=4.0, k12=1.0, kd3=0.2, tau_roll=0.05, tau_pitch=0.05, tau_yaw=0.02)
    t = np.arange(0.0, 20.0, 0.005)
    sticks = np.array([
        0.3 * np.sin(2 * np.pi * 0.4 * t) + 0.1 * np.sin(2 * np.pi * 1.3 * t),
        0.3 * np.sin(2 * np.pi * 0.3 * t + 1.0),
        0.2 * np.sin(2 * np.pi * 0.2 * t),
        0.3 * np.sin(2 * np.pi * 0.5 * t + 2.0),
    ])
    x = simulate(params, t, sticks)
    return t, x[:3], sticks, euler_from_quaternion(x[QUAT])


# --------------------------------------------------------------------------------------- valid flights


def test_make_flight_keeps_arrays_and_names_views():
    t, rates, sticks, att = _arrays()
    f = make_flight(t, rates, sticks, attitude=att, metadata={"source": "unit"}, extra={"rpm": np.full(N, 1500.0)})
    assert isinstance(f, Flight)
    assert f.n == N
    assert_allclose(f.dt, DT, rtol=1e-12)
    assert_allclose(f.sample_rate, 1 / DT, rtol=1e-12)
    assert_allclose(f.duration, DT * (N - 1), rtol=1e-12)
    assert_array_equal(f.rates, rates)
    assert_array_equal(f.attitude, att)
    assert_array_equal(f.sticks, sticks)
    for i, name in enumerate(("p", "q", "r")):
        assert_array_equal(getattr(f, name), rates[i])
        assert_array_equal(f.column(name), rates[i])
    for i, name in enumerate(("phi", "theta", "psi")):
        assert_array_equal(getattr(f, name), att[i])
    for i, name in enumerate(("lat", "lon", "col", "ped")):
        assert_array_equal(getattr(f, name), sticks[i])
    assert_array_equal(f.column("rpm"), 1500.0)
    assert f.metadata["attitude_source"] == "measured"
    assert f.metadata["source"] == "unit"
    with pytest.raises(KeyError, match="no column 'nope'"):
        f.column("nope")


def test_flight_owns_read_only_copies_of_its_arrays():
    """The Flight's arrays are read-only, and the caller's arrays are neither aliased nor frozen."""
    t, rates, sticks, att = _arrays()
    rpm = np.full(N, 1500.0)
    f = make_flight(t, rates, sticks, attitude=att, extra={"rpm": rpm})
    for a in (f.time, f.rates, f.attitude, f.sticks, f.extra["rpm"]):
        assert not a.flags.writeable
    for a in (t, rates, sticks, att, rpm):
        assert a.flags.writeable
    rates[0, 0] = 123.0  # the caller may keep working on its arrays ...
    t[0] = -5.0
    assert f.rates[0, 0] != 123.0  # ... without changing the validated flight
    assert f.time[0] == 0.0
    with pytest.raises(TypeError):
        f.metadata["x"] = 1  # metadata is a read-only mapping


def test_with_metadata_adds_items_and_keeps_data():
    t, rates, sticks, att = _arrays()
    f = make_flight(t, rates, sticks, attitude=att, metadata={"a": 1})
    g = f.with_metadata(b=2, a=3)
    assert {k: v for k, v in g.metadata.items() if k != "units_check"} == {"a": 3, "b": 2,
                                                                          "attitude_source": "measured"}
    assert f.metadata["a"] == 1
    assert g.rates is f.rates


def test_missing_attitude_is_reconstructed_from_rates(simulated):
    """Eqs. (25)-(29) from the rates alone recover the simulated attitude (within 1e-4 rad at 200 Hz)."""
    t, rates, sticks, truth = simulated
    f = make_flight(t, rates, sticks)
    assert f.metadata["attitude_source"] == "reconstructed"
    assert np.abs(truth).max() > 0.5  # a flight with real attitude excursions, not a trivial one
    assert_allclose(_wrap(f.attitude - truth), 0.0, atol=1e-4)


def test_simulated_flight_with_measured_attitude_passes_the_units_check(simulated):
    """True rad/s with the matching attitude must not be mistaken for deg/s."""
    t, rates, sticks, truth = simulated
    f = make_flight(t, rates, sticks, attitude=truth)
    assert f.metadata["attitude_source"] == "measured"


@pytest.mark.filterwarnings("error")
def test_constant_rate_with_attitude_passes_the_units_check_silently():
    """A constant rate channel (e.g. a stuck gyro axis) has no correlation to test: no RuntimeWarning."""
    t, rates, sticks, att = _arrays()
    rates[0] = 0.1  # while phi keeps moving
    f = make_flight(t, rates, sticks, attitude=att)
    assert_array_equal(f.p, 0.1)


def test_segment_keeps_the_samples_in_the_window():
    t, rates, sticks, att = _arrays()
    rpm = np.arange(N, dtype=float)
    f = make_flight(t, rates, sticks, attitude=att, metadata={"source": "unit"}, extra={"rpm": rpm})
    s = f.segment(1.0, 2.0)
    m = (t >= 1.0) & (t <= 2.0)
    assert s.n == m.sum() == 101
    assert_array_equal(s.time, t[m])  # time kept as is, not shifted to 0
    assert_array_equal(s.rates, rates[:, m])
    assert_array_equal(s.attitude, att[:, m])
    assert_array_equal(s.sticks, sticks[:, m])
    assert_array_equal(s.extra["rpm"], rpm[m])
    assert s.metadata["segment"] == [1.0, 2.0]
    assert s.metadata["source"] == "unit"
    assert "segment" not in f.metadata
    with pytest.raises(FlightLogError, match=r"segment \[10\.0, 11\.0\] s holds 0 samples; the flight spans \[0\.000, 3\.990\] s"):
        f.segment(10.0, 11.0)


# ---------------------------------------------------------------------------- bad inputs, one per class


@pytest.mark.parametrize("value, kind", [(np.nan, "NaN"), (np.inf, "inf"), (-np.inf, "inf")])
def test_non_finite_value_names_column_row_and_time(value, kind):
    t, rates, sticks, att = _arrays()
    rates[1, [123, 300]] = value
    with pytest.raises(
        FlightLogError,
        match=rf"column 'q' has 2 non-finite values \({kind} first\), first at row 123 \(t=1\.23 s\); expected finite numbers",
    ):
        make_flight(t, rates, sticks, attitude=att)


def test_time_not_strictly_increasing():
    t, rates, sticks, att = _arrays()
    t[200] = t[198]
    with pytest.raises(
        FlightLogError,
        match=r"time must be strictly increasing; it is decreasing at row 200 \(t=1\.9900 s then t=1\.9800 s\)",
    ):
        make_flight(t, rates, sticks, attitude=att)


def test_duplicated_time():
    t, rates, sticks, att = _arrays()
    t[50] = t[49]
    with pytest.raises(
        FlightLogError,
        match=r"time must be strictly increasing; it is duplicated at row 50 \(t=0\.4900 s then t=0\.4900 s\)",
    ):
        make_flight(t, rates, sticks, attitude=att)


def test_sampling_gap():
    t, rates, sticks, att = _arrays()
    t[251:] += 0.05  # one 60 ms interval between rows 250 and 251 in a 10 ms log
    with pytest.raises(
        FlightLogError,
        match=(r"sampling gap: 1 interval\(s\) longer than 1\.5x the median 10\.00 ms; the first is 60\.00 ms "
               r"between rows 250 and 251 \(t=2\.500 s to 2\.560 s\)\. Expected uniform sampling"),
    ):
        make_flight(t, rates, sticks, attitude=att)


def test_rates_in_deg_per_s_beyond_any_gyro_range():
    """Magnitude rule: a rate above 35 rad/s (2005 deg/s) can only be deg/s."""
    t, rates, sticks, _ = _arrays()
    rates[2, 10] = 40.0
    with pytest.raises(
        FlightLogError,
        match=r"column 'r' reaches 40\.0, beyond 35\.0 rad/s \(2005 deg/s\): it looks like deg/s; expected rad/s",
    ):
        make_flight(t, rates, sticks)  # the rule holds without attitude too


def test_rates_in_deg_per_s_against_the_attitude():
    """Attitude rule: the integrated rates 57x the attitude change mean deg/s, even below the magnitude rule."""
    t, rates, sticks, att = _arrays()
    rates_deg = np.degrees(rates)
    assert np.abs(rates_deg).max() < 35.0
    with pytest.raises(
        UnitError,
        match=r"the integrated rates are 5\d\.\d+x the change of the attitude \(roll 5\d\.\d, pitch 5\d\.\d; "
              r"correlation 1\.00\): "
              r"the rates look like deg/s .*; expected rad/s: multiply p, q, r by pi/180",
    ):
        make_flight(t, rates_deg, sticks, attitude=att)


def test_sticks_outside_unit_range():
    t, rates, sticks, att = _arrays()
    sticks[3, 77] = 1.2
    sticks[3, 90] = -1.5
    with pytest.raises(
        FlightLogError,
        match=r"stick column 'ped' has 2 values outside \[-1, 1\] \(range -1\.500\.\.1\.200\), first at row 77 "
              r"\(t=0\.77 s\); expected sticks normalised to \[-1, 1\]",
    ):
        make_flight(t, rates, sticks, attitude=att)


# -------------------------------------------------------------------------------- units by physics


@pytest.fixture(scope="module")
def synthetic_flights():
    """Our own synthetic flights, gentle and aggressive (MANOEUVRE_CONFIG: ~60 deg/s roll, 150 deg/s yaw)."""
    return [simulate_flight(30.0, seed=seed, config=cfg).flight
            for seed in (1, 2, 3, 4) for cfg in (None, MANOEUVRE_CONFIG)]


def test_our_synthetic_flights_pass_with_and_without_attitude(synthetic_flights):
    for f in synthetic_flights:
        assert_allclose(f.metadata["units_check"]["ratio"], 1.0, atol=0.05)
        g = make_flight(f.time, f.rates, f.sticks)  # no attitude: the hover range decides
        assert g.metadata["units_check"]["roll_pitch_rms_rad_s"] < 0.2 * HOVER_RATE_RMS_MAX


def test_our_synthetic_flights_in_deg_per_s_are_refused_with_and_without_attitude(synthetic_flights):
    for f in synthetic_flights:
        deg = np.degrees(f.rates)
        # the aggressive flights' yaw passes 35 "rad/s" (the gyro range) first; the gentle ones need the physics
        with pytest.raises(UnitError, match=r"(the rates look|it looks) like deg/s"):
            make_flight(f.time, deg, f.sticks, attitude=f.attitude)
        with pytest.raises(UnitError, match=r"(RMS of \d\.\d+ .*they|it) looks? like deg/s; expected rad/s"):
            make_flight(f.time, deg, f.sticks)


def test_rate_attitude_ratio_is_one_for_a_noisy_flight(synthetic_flights):
    found = rate_attitude_ratio(synthetic_flights[0].time, synthetic_flights[0].rates, synthetic_flights[0].attitude)
    assert_allclose(found["ratio"], 1.0, atol=0.03)
    assert set(found["counted"]) == {"roll", "pitch", "yaw"}
    assert min(a["correlation"] for a in found["axes"].values()) > 0.95


def test_units_declared_by_a_format_skip_the_hover_range():
    """An importer declares its units: an aggressive flight without attitude is not refused for its RMS."""
    t, rates, sticks, _ = _arrays()
    fast = 3.0 * HOVER_RATE_RMS_MAX * np.sign(np.sin(2 * np.pi * 0.5 * t)) * np.ones((3, 1))
    with pytest.raises(UnitError, match="hovering helicopter"):
        make_flight(t, fast, sticks)
    f = make_flight(t, fast, sticks, units_from="betaflight-blackbox log")
    assert "declared by the betaflight-blackbox log" in f.metadata["units_check"]["rates"]
    with pytest.raises(UnitError, match="as read from the test log, beyond any gyro's range"):
        make_flight(t, 40.0 * np.ones((3, t.size)), sticks, units_from="test log")
    bad = np.array(_arrays()[3])
    bad[1, 7] = 2.0
    with pytest.raises(UnitError, match=r"'theta' reaches 2 rad as read from the test log.*attitude data is corrupt"):
        make_flight(t, rates, sticks, attitude=bad, units_from="test log")


@pytest.mark.parametrize("scale, unit", [(1e3, "milliseconds"), (1e6, "microseconds"), (1e9, "nanoseconds")])
def test_time_in_another_unit_is_named(scale, unit):
    t, rates, sticks, att = _arrays()
    with pytest.raises(UnitError, match=rf"time: the median sample interval is .*; it looks like {unit} "
                                        rf"\(a 100 Hz log\); expected seconds"):
        make_flight(t * scale, rates, sticks, attitude=att)


def test_too_slow_a_log_is_refused():
    t, rates, sticks, att = _arrays()
    with pytest.raises(UnitError, match=r"too slow for attitude dynamics"):
        make_flight(t * 1e13, rates, sticks)


def test_attitude_in_degrees_is_named():
    t, rates, sticks, att = _arrays()
    with pytest.raises(UnitError, match=r"column 'theta' reaches 4\.58.*looks like degrees; expected rad"):
        make_flight(t, rates, sticks, attitude=np.degrees(att))
    small = att * 0.3  # pitch within +-1.57 "degrees": the ratio tells
    with pytest.raises(UnitError, match=r"the attitude looks like degrees"):
        make_flight(t, rates * 0.3, sticks, attitude=np.degrees(small))


@pytest.mark.parametrize("transform, unit", [
    (lambda s: 1500.0 + 500.0 * s, r"PWM pulse widths in us \(1000\.\.2000, centre 1500\): normalise as"),
    (lambda s: 500.0 * s, r"Betaflight rcCommand units \(\+-500\): divide by 500"),
    (lambda s: 100.0 * s, r"percent \(\+-100\): divide by 100"),
], ids=["pwm", "rccommand", "percent"])
def test_sticks_in_another_unit_are_named(transform, unit):
    t, rates, sticks, att = _arrays()
    with pytest.raises(UnitError, match=rf"stick column 'lat' has \d+ values outside \[-1, 1\] .*; they look like "
                                        rf"{unit}"):
        make_flight(t, rates, transform(sticks), attitude=att)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda a: {**a, "rates": a["rates"][:2]}, r"rates must have shape \(3, 400\) to match time, got \(2, 400\)"),
        (lambda a: {**a, "sticks": a["sticks"][:, :-1]}, r"sticks must have shape \(4, 400\) to match time, got \(4, 399\)"),
        (lambda a: {**a, "attitude": a["attitude"].T}, r"attitude must have shape \(3, 400\) to match time, got \(400, 3\)"),
        (lambda a: {**a, "time": a["time"][None]}, r"time must be 1-D, got shape \(1, 400\)"),
        (lambda a: {**a, "extra": {"rpm": np.ones(3)}}, r"extra column 'rpm' must have 400 values, got shape \(3,\)"),
        (lambda a: {k: (v[..., :1] if k != "extra" else v) for k, v in a.items()}, r"a flight needs at least 2 samples, got 1"),
    ],
    ids=["rates", "sticks", "attitude", "time-2d", "extra", "one-sample"],
)
def test_array_shapes(change, message):
    t, rates, sticks, att = _arrays()
    args = change({"time": t, "rates": rates, "sticks": sticks, "attitude": att, "extra": {}})
    with pytest.raises(FlightLogError, match=message):
        make_flight(**args)


def test_messages_are_value_errors():
    """FlightLogError is a ValueError, so callers that catch ValueError keep working."""
    t, rates, sticks, att = _arrays()
    rates[0, 0] = np.nan
    with pytest.raises(ValueError, match=re.escape("column 'p'")):
        make_flight(t, rates, sticks, attitude=att)
