"""Tests of identification.validation.frequency_response (and its report): the flight's stick-to-rate response with
coherence against the model's, CIFER-style.

The flights are synthetic (identification.bench.synthetic), 60 s with all three sticks swept at once over
0.3-3 Hz. With no wind and a still collective nothing but the stick drives the rate, so the flight's
estimate H = Pxy/Pxx must match the true model's response over the coherent band up to its random error
(with 16 averages at coherence 0.6 about ±1.4 dB, ±10° at one frequency): the tolerances below are on the
band's means and on CIFER's cost J (good fit: J <= 100).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from identification.bench.flight_config import FlightConfig
from identification.bench.synthetic import simulate_flight
from identification.errors import IdentifiabilityError
from identification.flight import Flight
from identification.reports.frequency_response import frequency_markdown, plot_frequency_response
from identification.validation.frequency_response import (
    COHERENCE_MIN,
    cifer_cost,
    coherent_band,
    compare_frequency_response,
    model_frequency_response,
    segment_samples,
)

CALM = FlightConfig(wind_level=0.0, collective_wander=0.0, sweep_mode="simultaneous")
"""No wind, a still collective, every stick swept at once: the stick alone drives the rate."""


@pytest.fixture(scope="module")
def calm():
    """A 60 s calm flight of the paper's aircraft with servo delays (eq. 31), and its comparison."""
    sim = simulate_flight(60.0, seed=2, config=CALM, effects=("servo_delay",))
    return sim, compare_frequency_response(sim.truth, sim.flight)


def test_the_flights_response_matches_the_true_models_over_the_coherent_band(calm):
    _, result = calm
    for axis, r in result.axes.items():
        low, high = r.band_hz
        assert low <= 0.5 and high >= 2.5, (axis, r.band_hz)  # the sweeps' band is coherent
        assert r.magnitude_error_db <= 1.0, (axis, r.magnitude_error_db)
        assert r.phase_error_deg <= 5.0, (axis, r.phase_error_deg)
        assert r.cost <= 50.0, (axis, r.cost)


def test_the_model_without_its_servo_delay_costs_more(calm):
    sim, result = calm
    undelayed = compare_frequency_response(sim.truth.with_values(tau_roll=0.0, tau_pitch=0.0, tau_yaw=0.0),
                                           sim.flight)
    for axis in result.axes:
        assert undelayed.axes[axis].cost > max(100.0, 3 * result.axes[axis].cost), axis
        assert undelayed.axes[axis].phase_error_deg > 3 * result.axes[axis].phase_error_deg, axis


def test_coherence_drops_above_the_sweeps_where_the_stick_has_no_power(calm):
    _, result = calm
    for axis, r in result.axes.items():
        quiet = r.freq >= 5.0
        swept = (r.freq >= 0.5) & (r.freq <= 2.5)
        assert r.coherence[quiet].max() < COHERENCE_MIN and not r.coherent[quiet].any(), axis
        assert r.coherence[swept].min() >= COHERENCE_MIN, axis


def test_an_axis_whose_stick_does_not_move_has_no_coherent_band(calm):
    sim, _ = calm
    f = sim.flight
    sticks = np.array(f.sticks, copy=True)
    sticks[3] = 0.1  # the pedal held still
    result = compare_frequency_response(sim.truth, Flight(f.time, f.rates, f.attitude, sticks, f.metadata))
    yaw = result.axes["yaw"]
    assert yaw.band_hz is None and not yaw.coherent.any()
    assert math.isnan(yaw.cost) and math.isnan(yaw.magnitude_error_db)
    assert result.to_dict()["axes"]["yaw"]["band_hz"] is None
    assert "| yaw | none | 0 | — | — | — |" in "\n".join(frequency_markdown(result))


def test_one_flights_coherence_is_scipys(calm):
    from scipy import signal

    sim, result = calm
    f = sim.flight
    n = segment_samples([f])
    freq, gamma2 = signal.coherence(f.sticks[0], f.rates[0], fs=f.sample_rate, nperseg=n, noverlap=n // 2)
    roll = result.axes["roll"]
    keep = np.isin(np.round(freq, 9), np.round(roll.freq, 9))
    assert_allclose(roll.coherence, gamma2[keep], rtol=1e-9, atol=1e-12)


def test_the_models_response_is_eq_18_with_the_pade_servo_of_eq_31(calm):
    sim, _ = calm
    p = sim.truth
    f = np.array([0.1, 1.0, 3.0])
    s = 2j * np.pi * f
    tau = p.tau_roll
    pade = (1 - s * tau / 2) / (1 + s * tau / 2)
    assert_allclose(model_frequency_response(p, 0, f), p.k2 * pade / (s + p.k3), rtol=1e-6)
    plain = p.with_values(tau_roll=0.0)
    assert_allclose(model_frequency_response(plain, 0, f), p.k2 / (s + p.k3), rtol=1e-6)


def test_cifer_cost_is_zero_for_a_perfect_model_and_20_weights_for_one_db():
    freq = np.linspace(0.5, 3.0, 30)
    h = 1.0 / (2j * np.pi * freq + 2.0)
    gamma2 = np.ones_like(freq)
    mask = np.ones(freq.size, bool)
    assert cifer_cost(freq, h, h, gamma2, mask) == pytest.approx(0.0, abs=1e-20)
    weight = (1.58 * (1 - np.exp(-1.0))) ** 2
    assert cifer_cost(freq, h, h * 10 ** (1 / 20), gamma2, mask) == pytest.approx(20 * weight, rel=1e-9)
    assert math.isnan(cifer_cost(freq, h, h, gamma2, np.zeros(freq.size, bool)))


def test_a_lone_frequency_above_the_threshold_is_not_a_band():
    gamma2 = np.array([0.1, 0.7, 0.1, 0.7, 0.8, 0.9, 0.2, 0.65, 0.7])
    assert coherent_band(gamma2).tolist() == [False, False, False, True, True, True, False, False, False]


def test_bad_inputs_are_refused(calm):
    sim, _ = calm
    with pytest.raises(ValueError, match="coherence_min must lie in"):
        compare_frequency_response(sim.truth, sim.flight, coherence_min=1.5)
    with pytest.raises(ValueError, match="at least one flight"):
        compare_frequency_response(sim.truth, [])
    with pytest.raises(ValueError, match="window_s must be a positive number"):
        compare_frequency_response(sim.truth, sim.flight, window_s=-1.0)
    with pytest.raises(IdentifiabilityError, match="segments of 64 samples or more"):
        compare_frequency_response(sim.truth, sim.flight.segment(0.0, 0.5))
    half = Flight(sim.flight.time[::2], sim.flight.rates[:, ::2], sim.flight.attitude[:, ::2],
                  sim.flight.sticks[:, ::2], sim.flight.metadata)
    with pytest.raises(ValueError, match="share one sample rate"):
        compare_frequency_response(sim.truth, [sim.flight, half])


def test_pooled_flights_average_their_segments(calm):
    sim, result = calm
    other = simulate_flight(60.0, seed=3, config=CALM, effects=("servo_delay",)).flight
    pooled = compare_frequency_response(sim.truth, [sim.flight, other])
    assert pooled.segments == 2 * result.segments
    for axis, r in pooled.axes.items():
        assert r.cost <= 50.0, (axis, r.cost)


def test_report_table_and_figure(calm, tmp_path):
    _, result = calm
    md = "\n".join(frequency_markdown(result))
    assert f"γ² ≥ {COHERENCE_MIN:g}" in md and "| roll | 0." in md
    assert "(frequency_response.png)" in md
    assert "frequency_response.png" not in "\n".join(frequency_markdown(result, figure=None))
    path = plot_frequency_response(result, tmp_path / "fr.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    d = result.to_dict()
    assert set(d["axes"]) == {"roll", "pitch", "yaw"} and d["coherence_min"] == COHERENCE_MIN
