"""Tests of identification.disturbance.equivalent_input: eqs. (41)-(47), the smoothing rule of Section 3.3, Section 3.4.

Thresholds were measured on 60 s synthetic flights (seeds 1-8, model identified
with ``IntegralIdentifier()``, default Δt = 0.02 s and 5 smoothing passes):
correlation of the identified u_d with the true wind 0.89-0.98 (roll), 0.89-0.97
(pitch), 0.94-0.99 (yaw); RMS error at most 0.45x the wind's RMS; rate MAE with
the identified disturbance 0.07-0.19x the MAE without. Seed 3, used here, gives
0.973 / 0.950 / 0.968.
"""

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import stats

from heli_core.params import ModelParams
from heli_core.terms import AXES
from identification.bench.synthetic import simulate_flight
from identification.disturbance.equivalent_input import DEFAULT_INTERVAL, DEFAULT_SMOOTHING, identify_disturbance
from identification.disturbance.profile import MODEL_LABELS, DisturbanceProfile, compare_with_truth
from identification.disturbance.smoothing import MAX_PASSES, smooth
from identification.errors import DisturbanceError
from identification.integral.method import IntegralIdentifier
from identification.reports.disturbance import profile_markdown, save_figures

MIN_CORRELATION = 0.9
MAX_RMS_RATIO = 0.4
MAX_MAE_RATIO = 0.25


@pytest.fixture(scope="session")
def synthetic():
    return simulate_flight(60, seed=3)


@pytest.fixture(scope="session")
def params(synthetic):
    return IntegralIdentifier().fit(synthetic.flight).params_


@pytest.fixture(scope="session")
def profile(synthetic, params):
    return identify_disturbance(synthetic.flight, params)


def test_defaults_are_the_studied_ones(profile):
    assert profile.interval == pytest.approx(DEFAULT_INTERVAL)
    assert profile.samples_per_interval == 2
    assert profile.passes == (DEFAULT_SMOOTHING,) * 3


def test_identified_wind_matches_truth(synthetic, profile):
    cmp = compare_with_truth(profile, synthetic.wind)
    for axis in AXES:
        assert cmp[axis]["correlation"] > MIN_CORRELATION, (axis, cmp[axis])
        assert cmp[axis]["rms_error"] < MAX_RMS_RATIO * cmp[axis]["rms_truth"], (axis, cmp[axis])


def test_zero_mean_and_offsets(profile, params):
    assert_allclose(profile.ud.mean(axis=1), 0.0, atol=1e-12)
    assert_allclose(profile.ud_raw.mean(axis=1), 0.0, atol=1e-12)
    # eq. (47): ū_d = k*u_d + kd holds exactly before smoothing
    assert_allclose(profile.control_gains[:, None] * profile.ud_raw + profile.kd[:, None], profile.torque, atol=1e-12)
    # kd of eq. (47) agrees with the identifier's mean per-interval offset
    assert_allclose(profile.kd, [params.kd1, params.kd2, params.kd3], atol=0.01)


def test_trace_is_piecewise_constant_and_aligned(profile):
    n, N = profile.time.size, profile.samples_per_interval
    assert profile.trace.shape == (3, n)
    assert profile.collective.shape == (n,)
    full = profile.n_intervals * N
    assert_array_equal(profile.trace[:, :full], np.repeat(profile.ud, N, axis=1))
    assert_array_equal(profile.trace[:, full:], profile.ud[:, -1:].repeat(n - full, axis=1))  # the tail holds
    assert_allclose(profile.interval_starts, profile.time[: full : N])


def test_eq46_recovers_a_known_piecewise_constant_torque():
    """Noise-free flight driven by a piecewise-constant torque: eq. (46) returns it."""
    from identification.flight import make_flight
    from heli_core.physics import simulate

    params = ModelParams(k2=1.3475, k3=2.4208, kd1=0.04, k6=-0.8903, k7=2.5188, kd2=0.01,
                         k10=13.47, k11=3.43, k12=-0.56, kd3=0.1)
    time = np.arange(0, 20.0001, 0.01)
    rng = np.random.default_rng(0)
    sticks = np.zeros((4, time.size))
    sticks[:, :] = 0.1 * np.sin(2 * np.pi * rng.uniform(0.05, 0.2, (4, 1)) * time)  # slow: see the tolerance
    steps = rng.normal(0, 0.05, (3, time.size // 20 + 1))
    ud = np.repeat(steps, 20, axis=1)[:, : time.size]
    torque = params.control_gains[:, None] * ud
    state = simulate(params, time, sticks, torque=torque, substeps=8)
    flight = make_flight(time, state[:3], sticks)
    prof = identify_disturbance(flight, params, interval=0.2, prefilter=False, smoothing=0, simulate=False)
    want = steps[:, : prof.n_intervals]
    # The simulator holds sticks over a sample, the trapezium rule interpolates them: per interval an error
    # of (u(t_i) - u(t_{i-1})) * dt / (2 Δt) in u_d, below 1e-3 for these slow sticks.
    assert_allclose(prof.ud_raw, want - want.mean(axis=1, keepdims=True), atol=1e-3)
    assert_allclose(prof.kd, [params.kd1 + params.k2 * want[0].mean(), params.kd2 + params.k6 * want[1].mean(),
                              params.kd3 + params.k10 * want[2].mean()], atol=1e-3 * 14)


def test_simulation_with_disturbance_beats_without(profile):
    sim = profile.simulation
    assert sim.labels == list(MODEL_LABELS)
    for axis in AXES:
        without = sim.rate_stats[MODEL_LABELS[0]][axis]["mae_deg_s"]
        with_d = sim.rate_stats[MODEL_LABELS[1]][axis]["mae_deg_s"]
        assert with_d < MAX_MAE_RATIO * without, (axis, without, with_d)
        assert sim.attitude_stats[MODEL_LABELS[1]][axis]["mae_deg"] < sim.attitude_stats[MODEL_LABELS[0]][axis]["mae_deg"]


def test_smoothing_rule_is_the_papers_and_deterministic(synthetic, params):
    a = identify_disturbance(synthetic.flight, params, smoothing="auto", simulate=False)
    b = identify_disturbance(synthetic.flight, params, smoothing="auto", simulate=False)
    assert a.passes == b.passes
    assert_array_equal(a.ud, b.ud)
    grid = np.linspace(-1.5, 1.5, 20001)
    for i, axis in enumerate(AXES):
        stick = synthetic.flight.sticks[[0, 1, 3][i]]
        mu_s, sd_s = stats.norm.fit(stick - stick.mean())
        # brute force: the least-squares distance of the fitted densities on a grid, every pass count
        cost = []
        for k in range(MAX_PASSES + 1):
            mu, sd = stats.norm.fit(smooth(a.ud_raw[i], k) - smooth(a.ud_raw[i], k).mean())
            cost.append(np.sum((stats.norm.pdf(grid, mu, sd) - stats.norm.pdf(grid, mu_s, sd_s)) ** 2) * (grid[1] - grid[0]))
        assert a.passes[i] == int(np.argmin(cost)) == a.statistics[axis]["auto_passes"]
        assert_allclose(a.smoothing_cost[i], cost, rtol=1e-6, atol=1e-9)


def test_smoothing_is_centred_for_even_pass_counts():
    x = np.zeros(101)
    x[50] = 1.0
    y = smooth(x, 2)
    assert_allclose(np.sum(y * np.arange(101)), 50.0)
    assert_allclose(y, y[::-1], atol=1e-15)


def test_fixed_smoothing_and_statistics(synthetic, params):
    prof = identify_disturbance(synthetic.flight, params, smoothing=0, simulate=False)
    assert prof.passes == (0, 0, 0)
    assert_allclose(prof.ud, prof.ud_raw)
    s = prof.statistics["roll"]
    assert s["ud_interval90"][0] < 0 < s["ud_interval90"][1]
    ks = stats.ks_2samp(prof.ud[0], synthetic.flight.lat - synthetic.flight.lat.mean())
    assert s["ks_statistic"] == pytest.approx(ks.statistic)
    assert s["ks_pvalue"] == pytest.approx(ks.pvalue)


def test_single_axis(synthetic, params):
    prof = identify_disturbance(synthetic.flight, params, axes=("roll",), simulate=False)
    assert prof.axes == ("roll",)
    assert set(prof.statistics) == {"roll"}
    assert_array_equal(prof.trace[1:], 0.0)


def test_servo_delay_uses_the_pade_command(synthetic, params):
    delayed = params.with_values(tau_roll=0.05)
    a = identify_disturbance(synthetic.flight, params, axes=("roll",), smoothing=0, simulate=False)
    b = identify_disturbance(synthetic.flight, delayed, axes=("roll",), smoothing=0, simulate=False)
    assert not np.allclose(a.ud_raw[0], b.ud_raw[0])


@pytest.mark.parametrize(
    "interval, match",
    [
        (0.01, "shorter than two samples"),
        (61.0, "longer than the flight"),
        (40.0, "need at least 2 intervals"),
        (-1.0, "positive number of seconds"),
        (float("nan"), "positive number of seconds"),
    ],
)
def test_bad_interval(synthetic, params, interval, match):
    with pytest.raises(DisturbanceError, match=match):
        identify_disturbance(synthetic.flight, params, interval=interval, simulate=False)


def test_bad_smoothing(synthetic, params):
    with pytest.raises(DisturbanceError, match="smoothing must be 'auto' or a number of passes"):
        identify_disturbance(synthetic.flight, params, smoothing="lots", simulate=False)


def test_bad_axes(synthetic, params):
    with pytest.raises(DisturbanceError, match="axes must be a non-empty subset"):
        identify_disturbance(synthetic.flight, params, axes=("heave",), simulate=False)


def test_axis_without_control_gain(synthetic, params):
    with pytest.raises(DisturbanceError, match="control gain k6 is 0"):
        identify_disturbance(synthetic.flight, params.with_values(k6=0.0), simulate=False)


def test_compare_with_truth_shape(profile):
    with pytest.raises(ValueError, match="true_ud must have shape"):
        compare_with_truth(profile, np.zeros((3, 5)))


def test_report_outputs(profile, synthetic, tmp_path):
    d = profile.to_dict()
    text = json.dumps(d, allow_nan=False)
    assert json.loads(text)["samples_per_interval"] == 2
    assert set(d["statistics"]) == set(AXES)
    assert set(d["simulation"]["rate_stats"]) == set(MODEL_LABELS)
    md = profile_markdown(profile)
    assert "| Roll |" in md and "KS p-value" in md and "rate MAE with" in md
    paths = save_figures(profile, tmp_path, true_ud=synthetic.wind)
    assert set(paths) == {"profile", "distributions", "simulation"}
    for p in paths.values():
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*.tmp"))
    assert isinstance(profile, DisturbanceProfile)
