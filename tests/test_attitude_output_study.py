"""scripts/attitude_output_study.py: its likelihood of one axis, rate alone or with the attitude, is a
likelihood of the flight (best near the truth), and it refuses flights whose sticks its hold does not fit."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest


@pytest.mark.parametrize("with_attitude", [False, True], ids=["rate", "rate+attitude"])
def test_the_likelihood_prefers_the_true_damping_and_gain(with_attitude, load_script):
    from identification.bench.cells import BENCH_CELLS
    from identification.bench.flight_config import PAPER_PARAMS
    from identification.bench.synthetic import simulate_flight

    study = load_script("attitude_output_study")
    config = replace(BENCH_CELLS["held-sticks-pd"], duration=60.0, vibration_lines=(), vibration=0.0)
    flight = simulate_flight(60.0, seed=5, config=config).flight
    y, u = study.flight_signals(flight, 0)
    t = PAPER_PARAMS.values()
    truth = np.array([t["k3"], t["k2"], 0.0, np.log(4.0), np.log(0.35), np.log(1e-3), np.log(1e-2),
                      np.log(config.gyro_noise ** 2), np.log(config.attitude_noise ** 2)])
    at_truth = study.nll(truth, y, u, flight.dt, with_attitude)
    for index, factor in ((0, 1.5), (0, 0.6), (1, 1.3)):
        wrong = truth.copy()
        wrong[index] *= factor
        assert study.nll(wrong, y, u, flight.dt, with_attitude) > at_truth + 10.0
    assert study.nll(np.r_[-1.0, truth[1:]], y, u, flight.dt, with_attitude) == 1e12  # no negative damping


def test_a_cell_whose_sticks_are_interpolated_is_refused(load_script, capsys):
    with pytest.raises(SystemExit) as refused:
        load_script("attitude_output_study").main(["--cell", "independent", "--seeds", "1"])
    assert refused.value.code == 2
    assert "must hold its sticks over the sample" in capsys.readouterr().err


def test_the_estimated_attitude_follows_the_angle_and_carries_the_gyros_noise(load_script):
    """A flight controller's angle (a complementary filter of the gyro and a tilt): exact inputs give the angle
    back (to the integration's step), a noisy gyro and tilt give errors that are low-passed, not white."""
    study = load_script("attitude_output_study")
    dt = 0.01
    t = np.arange(6000) * dt
    angle, rate = 0.1 * np.sin(0.5 * t), 0.05 * np.cos(0.5 * t)
    exact = study.estimated_attitude(rate, angle, dt, 1.0, 0.0, np.random.default_rng(0))
    assert np.abs(exact - angle).max() < 1e-3
    noisy = study.estimated_attitude(rate + 0.03 * np.random.default_rng(1).standard_normal(t.size), angle, dt, 1.0,
                                     0.02, np.random.default_rng(2))
    error = noisy - angle
    assert 0.001 < error.std() < 0.01
    assert np.corrcoef(error[1:], error[:-1])[0, 1] > 0.9  # correlated from sample to sample
