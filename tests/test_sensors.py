"""The sensors identified from flights (identification.sensors) and their model-file entry (heli_core.sensors)."""

from __future__ import annotations

import numpy as np
import pytest

from heli_core.sensors import GyroLine, SensorModel
from identification.bench.cells import bench_flight
from identification.bench.synthetic import simulate_flight
from identification.sensors import identify_sensors, white_noise_level


@pytest.mark.parametrize("cell, gyro, lines", [
    ("default", 0.01, {30.0: 0.04, 40.0: 0.02}),  # rotor 30 Hz and its 60 Hz harmonic aliased to 40 Hz
    ("broadband-pd-noisy-gyro", 0.03, {27.0: 0.06, 30.0: 0.04, 40.0: 0.02, 41.5: 0.04}),
])
def test_levels_and_lines_of_the_bench_sensors(cell, gyro, lines):
    sensors = identify_sensors(bench_flight(cell, 2, 120.0).flight)
    np.testing.assert_allclose(sensors.gyro_noise, gyro, rtol=0.05)
    np.testing.assert_allclose(sensors.attitude_noise, 0.003, rtol=0.05)
    for axis in ("roll", "pitch", "yaw"):
        found = {round(ln.frequency_hz, 1): ln.amplitude for ln in sensors.gyro_lines if ln.axis == axis}
        assert set(found) == set(lines)
        for hz, amp in lines.items():
            assert found[hz] == pytest.approx(amp, abs=0.002)


def test_several_flights_pool_levels_and_lines():
    one = identify_sensors(simulate_flight(60, seed=1).flight)
    both = identify_sensors([simulate_flight(60, seed=1).flight, simulate_flight(60, seed=2).flight])
    assert len(both.gyro_lines) == len(one.gyro_lines) == 6
    np.testing.assert_allclose(both.gyro_noise, one.gyro_noise, rtol=0.05)
    with pytest.raises(ValueError, match="at least one flight"):
        identify_sensors([])


def test_white_noise_level_ignores_slow_motion_and_a_yaw_wrap():
    rng = np.random.default_rng(0)
    t = np.arange(20000) / 100.0
    slow = 0.5 * np.sin(2 * np.pi * 0.7 * t) + 0.2 * np.sin(2 * np.pi * 2.5 * t)
    assert white_noise_level(slow + 0.01 * rng.standard_normal(t.size))[0] == pytest.approx(0.01, rel=0.04)
    heading = np.angle(np.exp(1j * (0.8 * t + 0.003 * rng.standard_normal(t.size))))  # crosses +-pi many times
    flight = simulate_flight(30, seed=1).flight
    att = flight.attitude.copy()
    att[2] = heading[: flight.n]
    from identification.flight import make_flight

    wrapped = make_flight(flight.time, flight.rates, flight.sticks, attitude=att)
    assert identify_sensors(wrapped).attitude_noise[2] == pytest.approx(0.003, rel=0.15)


def test_the_model_file_entry_round_trips_and_bad_entries_are_named():
    s = SensorModel((0.01, 0.02, 0.03), (0.003, 0.003, 0.004), (GyroLine("roll", 30.0, 0.04),))
    assert SensorModel.from_dict(s.to_dict()) == s
    assert SensorModel.from_dict(None).silent and not s.silent
    with pytest.raises(ValueError, match="gyro_noise_rad_s"):
        SensorModel.from_dict({"gyro_noise_rad_s": {"rol": 0.1}})
    with pytest.raises(ValueError, match=r"gyro_lines\[0\]"):
        SensorModel.from_dict({"gyro_lines": [{"axis": "roll"}]})
    with pytest.raises(ValueError, match="must be a number"):
        SensorModel.from_dict({"attitude_noise_rad": {"roll": "low"}})
    with pytest.raises(ValueError, match="standard deviations >= 0"):
        SensorModel(gyro_noise=(-1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="axis"):
        GyroLine("heave", 30.0, 0.1)
