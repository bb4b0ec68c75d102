"""Tests of :func:`identification.fit_warnings.fit_warnings`: one line per concern, none for good data."""

from __future__ import annotations

import numpy as np
import pytest

from identification.fit_warnings import MIN_DURATION_S, MIN_R2, fit_warnings
from identification.flight import make_flight


def _flight(duration=120.0, rate=50.0, source="f.csv", ped=0.3, r_scale=1.0):
    t = np.arange(0.0, duration, 1.0 / rate)
    w = 2 * np.pi * 0.4
    sticks = np.array([0.3 * np.sin(w * t), 0.3 * np.cos(w * t), 0.1 + 0 * t, ped * np.sin(1.3 * w * t)])
    rates = np.array([0.2 * np.sin(w * t), 0.2 * np.cos(w * t), r_scale * 0.3 * np.sin(1.3 * w * t)])
    return make_flight(t, rates, sticks, metadata={"source": source})


GOOD = {"roll": 0.8, "pitch": 0.75, "yaw": 0.9}


def test_a_long_well_excited_well_fitted_flight_gets_no_warning():
    assert fit_warnings([_flight()], GOOD) == []
    assert fit_warnings(_flight(), GOOD) == []  # one flight needs no list


def test_a_short_flight_is_named_with_its_length():
    (line,) = fit_warnings([_flight(duration=5.0, source="hop.csv")], GOOD)
    assert line.startswith(f"flight 'hop.csv' lasts 5.0 s, shorter than {MIN_DURATION_S:.0f} s")


def test_a_weak_fit_names_the_axis_and_the_share_explained():
    lines = fit_warnings([_flight()], {**GOOD, "pitch": 0.02})
    assert lines == [f"pitch: the fit explains 2 % of the rate variance (R² 0.02), below {100 * MIN_R2:.0f} %: the "
                     "model says little about this axis; check the input source (--inputs), the segment and the "
                     "logging rate"]
    assert len(fit_warnings([_flight()], {**GOOD, "roll": -0.5})) == 1  # a negative R² reads as 0 %


@pytest.mark.parametrize("kwargs", [{"ped": 0.0}, {"r_scale": 0.0}], ids=["stick-still", "rate-still"])
def test_a_barely_excited_axis_is_named(kwargs):
    (line,) = fit_warnings([_flight(**kwargs)], GOOD)
    assert line.startswith("yaw is barely excited: the ped stick varies by")


def test_axes_without_a_figure_are_not_judged_and_order_is_flights_then_axes():
    flights = [_flight(duration=30.0, source="a.csv", ped=0.0), _flight(duration=40.0, source="b.csv", ped=0.0)]
    lines = fit_warnings(flights, {"roll": None, "pitch": float("nan"), "yaw": 0.1})
    assert [line.split(" ")[0] for line in lines] == ["flight", "flight", "yaw", "yaw:"]
    assert "'a.csv'" in lines[0] and "'b.csv'" in lines[1]
    assert fit_warnings(flights, None)[:2] == lines[:2]


def test_thresholds_can_be_changed():
    assert fit_warnings([_flight(duration=30.0)], GOOD, min_duration_s=20.0) == []
    assert len(fit_warnings([_flight()], GOOD, min_r2=0.85)) == 2
