"""Tests of the gain sweep (:mod:`controllers.sweep`), its linear closed loop (:mod:`controllers.closed_loop`),
its outputs, the flight-test check (:mod:`controllers.flight_test`) and ``heli sweep``.

They use the model that ships with the package (three traces of 200 s) and a
copy of it with a servo delay (eq. 31), whose stability boundary lies inside
small grids. Windows are short where the test allows.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from controllers import closed_loop as cl
from controllers.errors import SweepError
from controllers.pd.law import pd_command
from controllers.flight_test import FlightTestConfig, fit_corner, validate_against_flights
from controllers.sweep import sweep_gains, sweep_pairs
from controllers.sweep_inputs import parse_range
from controllers.sweep_replay import TD_COLUMNS
from controllers.sweep_report import flight_test_markdown, markdown, plot_heatmap, plot_histograms
from controllers.sweep_result import COLUMNS
from heli_cli.main import main
from heli_env import HeliAttitudeEnv


@pytest.fixture(scope="session")
def delayed(shipped):
    """The shipped model with the flight generator's servo delays: unstable pairs appear at moderate gains."""
    return dataclasses.replace(shipped, params=shipped.params.with_values(tau_roll=0.08, tau_pitch=0.08,
                                                                           tau_yaw=0.05))


@pytest.fixture(scope="session")
def small_sweep(delayed):
    """A 4 x 3 grid across the stability boundary of the delayed model, 3 windows of 10 s.

    Its best pair, (40, 3), lies on the grid's upper Kd edge and Kp row below the boundary, so the
    sweep grows it once to 7 x 6 (Kp up to 320, Kd up to 81), where the best pair (80, 9) is interior.
    """
    return sweep_gains(delayed, [0.0, 5.0, 20.0, 40.0], [0.0, 1.0, 3.0], duration=10.0, windows=3, seed=7,
                       progress=False)


def _numeric(result):
    return {c: np.asarray(result.table[c], dtype=float) for c in COLUMNS if c not in ("status", "disagree")}


# ------------------------------------------------------------------------ sweep
def test_sweep_is_deterministic_for_a_seed(delayed, small_sweep):
    again = sweep_gains(delayed, [0.0, 5.0, 20.0, 40.0], [0.0, 1.0, 3.0], duration=10.0, windows=3, seed=7,
                        progress=False)
    assert again.windows == small_sweep.windows
    assert again.extension == small_sweep.extension and len(again.extension["rounds"]) == 2  # grown alike
    assert_array_equal(again.kp_values, small_sweep.kp_values)
    assert_array_equal(again.kd_values, small_sweep.kd_values)
    for c, v in _numeric(small_sweep).items():
        assert_array_equal(_numeric(again)[c], v, err_msg=c)
    assert_array_equal(again.hist_counts, small_sweep.hist_counts)
    other = sweep_gains(delayed, [5.0], [1.0], duration=10.0, windows=3, seed=8, progress=False)
    assert other.windows != small_sweep.windows


def test_windows_are_distinct_and_fit_their_traces(shipped):
    r = sweep_gains(shipped, [2.0], [1.0], duration=60.0, windows=10, seed=0, progress=False)
    assert len(r.windows) == 10 == len(set(r.windows))
    assert sorted({t for t, _ in r.windows}) == [0, 1, 2]
    for t, off in r.windows:
        assert 0 <= off <= shipped.lengths[t] - 6001


def test_unstable_pairs_are_detected_and_not_simulated(delayed, small_sweep):
    st = small_sweep.table["status"]
    unstable = st == "unstable"
    assert unstable.sum() >= 4 and (st == "stable").sum() >= 4
    # kp = 0 leaves a pole on the unit circle (the attitude drifts); kp = 40, kd = 0 is beyond the boundary
    assert unstable[small_sweep.index(0.0, 1.0)] and unstable[small_sweep.index(40.0, 0.0)]
    for c in TD_COLUMNS:
        col = np.asarray(small_sweep.table[c], dtype=float)
        assert np.all(np.isnan(col[unstable])), c
        assert np.all(np.isfinite(col[~unstable])), c
    assert np.all(np.isnan(small_sweep.table["pred_att_p90_deg"][unstable]))
    assert np.all(small_sweep.hist_counts[unstable] == 0)
    # python-control agrees, pair by pair, and so does the PD module's per-axis analysis
    from controllers.pd import loop_analysis

    plant = cl.hover_plant(delayed.params, 0.01, 0.2)
    nominal = np.array(small_sweep.settings["nominal_gains"])
    for i in range(small_sweep.n_pairs):
        kp, kd = small_sweep.table["kp"][i], small_sweep.table["kd"][i]
        poles = cl.closed_loop_system(plant, "roll", kp, kd, nominal).poles()
        assert (np.max(np.abs(poles)) < 1 - cl.STABILITY_MARGIN) == (not unstable[i])
        if kp > 0:
            assert loop_analysis(delayed.params, "roll", kp, kd, 0.01).stable == (not unstable[i])


def test_statistics_equal_the_shared_error_metrics(shipped):
    """The sweep's in-place float32 statistics are controllers.metrics.error_metrics of its samples."""
    from controllers.metrics import error_metrics

    r = sweep_pairs(shipped, [(1.0, 0.0), (6.0, 2.0)], duration=20.0, windows=3, keep_samples=True, progress=False)
    for i in range(2):
        m = error_metrics(*r.samples[i], hist_edges=r.hist_edges)
        for c in ("att_rms_deg", "att_p50_deg", "att_p90_deg", "att_p99_deg", "rate_rms_dps", "rate_p50_dps",
                  "rate_p90_dps", "rate_p99_dps", "stick_rms", "stick_p99", "saturation"):
            assert_allclose(r.table[c][i], m[c], rtol=1e-5, atol=1e-9, err_msg=c)
        assert np.abs(r.hist_counts[i] - m["hist_counts"]).sum() <= 4  # float32 rounding at bin edges
        assert r.hist_counts[i].sum() + r.hist_overflow[i] == m["n_samples"]


def test_pd_command_is_the_pd_controllers_law(shipped):
    from controllers.pd import PDController, PDGains

    rng = np.random.default_rng(1)
    obs = rng.uniform(-0.3, 0.3, (50, 12)).astype(np.float32)
    gains = PDGains(kp=(3.0, 5.0, 1.0), kd=(1.0, 0.5, 0.2))
    ctrl = PDController.from_model(shipped.params, gains)
    act, _ = ctrl.predict(obs)
    signs = np.sign(shipped.params.control_gains)
    for i in range(3):
        u = pd_command(gains.kp[i], gains.kd[i], signs[i], obs[:, i].astype(float), obs[:, 6 + i].astype(float))
        assert_allclose(np.clip(u, -1, 1), act[:, i], atol=1e-6)


def test_replay_equals_the_environment_under_the_same_pd_law(shipped):
    """The sweep's closed loop is the env's: same physics step, trim and stick clipping."""
    kp, kd = 3.0, 1.0
    r = sweep_pairs(shipped, [(kp, kd)], duration=5.0, traces=[(1, 1234)], keep_samples=True, progress=False,
                    sensors=False)  # the env below reads the true state too
    nominal = np.array(r.settings["nominal_gains"])
    signs = np.sign(shipped.params.control_gains)
    env = HeliAttitudeEnv(model=shipped, init_angle_deg=0.0, init_rate_deg=0.0, episode_seconds=5.0, obs_noise=0.0)
    obs, _ = env.reset(seed=0, options={"trace": 1, "offset": 1234})
    gains = [(kp, kd), tuple(nominal[1]), tuple(nominal[2])]
    errs = [0.0]
    for _ in range(499):
        x = env._x  # the true state (the observation is float32)
        q0, q1, q2, q3 = x[6:10]
        ang = cl_euler(q0, q1, q2, q3)
        a = [pd_command(g[0], g[1], signs[i], -ang[i], -x[i]) for i, g in enumerate(gains)]
        obs, _, term, trunc, info = env.step(np.array(a))
        errs.append(info["attitude_error_deg"][0])
    assert_allclose(r.samples[0][0][:500], errs, atol=1e-9)


def cl_euler(q0, q1, q2, q3):
    return (math.atan2(2 * (q0 * q1 + q2 * q3), 1 - 2 * (q1 * q1 + q2 * q2)),
            math.asin(max(-1.0, min(1.0, 2 * (q0 * q2 - q3 * q1)))),
            math.atan2(2 * (q0 * q3 + q1 * q2), 1 - 2 * (q2 * q2 + q3 * q3)))


# ------------------------------------------------------------- frequency domain
def test_linear_plant_matches_the_physics_core(delayed):
    """The sampled linear plant reproduces the core's discrete step for small inputs (rates exactly)."""
    from heli_core.discrete import discrete_kernel
    from heli_core.physics import trim_sticks

    params, dt = delayed.params, 0.01
    plant = cl.hover_plant(params, dt, 0.2)
    dstep = discrete_kernel(params, dt)[0]
    trim = trim_sticks(params, 0.2)
    rng = np.random.default_rng(0)
    u = 0.02 * rng.standard_normal((200, 3))
    w = 0.02 * rng.standard_normal((200, 3))
    x = (0.0, 0.0, 0.0, *trim, 1.0, 0.0, 0.0, 0.0)
    xl = np.zeros(plant.n)
    for k in range(200):
        sticks = (trim[0] + u[k, 0], trim[1] + u[k, 1], 0.2, trim[2] + u[k, 2])
        x = dstep(x, sticks, tuple(params.control_gains * w[k]))
        xl = plant.A @ xl + plant.Bu @ u[k] + plant.Bw @ w[k]
    assert_allclose(xl[plant.rate_idx], x[0:3], atol=1e-9)
    assert_allclose(xl[plant.angle_idx], cl_euler(*x[6:10]), atol=2e-4)  # O(dt^2) attitude integration


def test_frequency_domain_variance_equals_lyapunov_for_white_noise(delayed):
    """sum |H|^2 S df on the fine grid equals the discrete Lyapunov variance for white u_d (< 0.5 %)."""
    from scipy.linalg import solve_discrete_lyapunov

    dt, sigma = 0.01, 0.05
    plant = cl.hover_plant(delayed.params, dt, 0.2)
    nominal = cl.nominal_gains(plant)
    freq = np.linspace(0.0, 0.5 / dt, 1025)
    psd = np.zeros((3, freq.size))
    psd[0] = 2.0 * dt * sigma**2  # one-sided density of white noise of variance sigma^2
    kp, kd = np.array([2.0, 10.0, 20.0]), np.array([0.5, 1.0, 0.5])
    std = cl.predict_std(plant, "roll", kp, kd, nominal, freq, psd)
    K = cl.gain_matrices(plant, 0, kp, kd, nominal)
    for g in range(kp.size):
        A = plant.A - plant.Bu @ K[g]
        P = solve_discrete_lyapunov(A, sigma**2 * np.outer(plant.Bw[:, 0], plant.Bw[:, 0]))
        C = np.zeros((3, plant.n))
        C[0, plant.angle_idx[0]] = 1.0
        C[1, plant.rate_idx[0]] = 1.0
        C[2] = K[g, 0]
        assert_allclose(std[g], np.sqrt(np.diag(C @ P @ C.T)), rtol=5e-3)


def test_frequency_response_equals_python_control(delayed):
    """The partial-fraction evaluation equals control.frequency_response (checked via a line spectrum)."""
    import control

    dt = 0.01
    plant = cl.hover_plant(delayed.params, dt, 0.2)
    nominal = cl.nominal_gains(plant)
    sysd = cl.closed_loop_system(plant, "roll", 8.0, 1.5, nominal)
    f0 = 1.3  # a narrow band around f0 picks |H(f0)|^2
    freq = np.linspace(0.0, 0.5 / dt, 50001)
    psd = np.zeros((3, freq.size))
    psd[0] = np.exp(-0.5 * ((freq - f0) / 0.002) ** 2)
    area = np.trapezoid(psd[0], freq)
    got = cl.predict_std(plant, "roll", [8.0], [1.5], nominal, freq, psd, n_freq=200000)[0] ** 2 / area
    mag = control.frequency_response(sysd[:, 0], [2 * math.pi * f0]).magnitude.reshape(3)
    assert_allclose(got, mag**2, rtol=2e-3)


def test_time_and_frequency_domain_agree_for_small_gains(ideal):
    """Linear regime (no saturation): the two predictions agree within 10 % on RMS and p90 (measured ~3 %)."""
    r = sweep_pairs(ideal, [(1.0, 0.5), (3.0, 1.0), (8.0, 3.0)], duration=None, progress=False)
    assert np.all(r.table["saturation"] == 0.0)
    for td, fd in (("att_rms_deg", "pred_att_rms_deg"), ("att_p90_deg", "pred_att_p90_deg"),
                   ("rate_rms_dps", "pred_rate_rms_dps"), ("rate_p90_dps", "pred_rate_p90_dps"),
                   ("stick_rms", "pred_stick_rms")):
        assert_allclose(r.table[td], r.table[fd], rtol=0.10, err_msg=td)
    assert not np.any(r.table["disagree"])


def test_saturation_is_counted_and_flagged(ideal):
    """Gusts 15 times the library's saturate the stick: the linear prediction underestimates, and says why."""
    strong = dataclasses.replace(ideal, ud=ideal.ud * 15.0)
    r = sweep_pairs(strong, [(10.0, 1.0)], duration=30.0, windows=3, progress=False)
    assert r.table["saturation"][0] > 0.1
    assert r.table["disagree"][0] and r.table["att_p90_rel_diff"][0] > 0.2
    assert "saturated" in markdown(r)
    # twice as strong again: the stick cannot hold the aircraft; reported as diverged, statistics left empty
    wild = sweep_pairs(dataclasses.replace(ideal, ud=ideal.ud * 30.0), [(3.0, 1.0)], duration=30.0, windows=3,
                       progress=False)
    assert wild.table["status"][0] == "diverged" and np.isnan(wild.table["att_p90_deg"][0])


def test_welch_spectrum_keeps_the_library_variance_and_the_wind_bandwidth(shipped):
    freq, psd = cl.disturbance_spectrum(shipped, 0.01)
    var = np.sum(psd, axis=1) * (freq[1] - freq[0])
    ud = np.concatenate([shipped.ud[:, s:s + n] - shipped.ud[:, s:s + n].mean(axis=1, keepdims=True)
                         for s, n in zip(shipped.starts, shipped.lengths)], axis=1)
    assert_allclose(np.sqrt(var), ud.std(axis=1), rtol=0.03)
    # the shipped library's flights met Gauss-Markov gusts (time constants 4 s and 0.35 s, the bench's
    # 'independent' cell), to which a Butterworth fit puts the corner at 3.8 Hz; its traces, posterior draws,
    # give the same (3.76-3.87 Hz per axis). The smoother's mean it held before issue #30 gave 0.5 Hz.
    assert 3.0 < fit_corner(freq, psd[0]) < 4.7


# ------------------------------------------------------------------ bad inputs
@pytest.mark.parametrize("text, match", [
    ("1:0:3", "reversed"), ("0:1:0", "empty"), ("nan:1:3", "finite"), ("0:inf:3", "finite"),
    ("-1:1:3", ">= 0"), ("a:b:3", "numbers"), ("1:2", "A:B:N"), ("0:1:2.5", "whole"), ("0:1:1", "N = 1"),
])
def test_bad_ranges_raise(text, match):
    with pytest.raises(SweepError, match=match):
        parse_range(text, "--kp")


def test_good_ranges():
    assert_allclose(parse_range("0:3:4"), [0, 1, 2, 3])
    assert_allclose(parse_range("2.5"), [2.5])
    assert_allclose(parse_range("2:2:1"), [2.0])


@pytest.mark.parametrize("kp, match", [([], "non-empty"), ([1.0, np.inf], "finite"), ([-1.0], ">= 0"),
                                       ([[1.0, 2.0]], "1-D")])
def test_bad_gains_raise(shipped, kp, match):
    with pytest.raises(SweepError, match=match):
        sweep_gains(shipped, kp, [1.0], duration=1.0, progress=False)


def test_bad_settings_raise(shipped, tmp_path):
    with pytest.raises(SweepError, match="does not exist"):
        sweep_gains(tmp_path / "nowhere", [1.0], [1.0], progress=False)
    with pytest.raises(SweepError, match="axis"):
        sweep_gains(shipped, [1.0], [1.0], axis="heave", progress=False)
    with pytest.raises(SweepError, match="does not fit"):
        sweep_gains(shipped, [1.0], [1.0], duration=500.0, progress=False)
    with pytest.raises(SweepError, match="whole number"):
        sweep_gains(shipped, [1.0], [1.0], dt=0.015, progress=False)
    with pytest.raises(SweepError, match="out of range"):
        sweep_gains(shipped, [1.0], [1.0], traces=[7], progress=False)


@pytest.mark.parametrize("traces, match", [
    ([7], "trace index 7 out of range"), ([-1], "trace index -1 out of range"), ([], "at least one"),
    ([(3, 0)], "trace index 3 out of range"), ([(0, -5)], r"window \(0, -5\) does not fit"),
    ([(0, 20000)], r"window \(0, 20000\) does not fit"),
])
def test_bad_traces_of_whole_trace_replays_raise(shipped, traces, match):
    """duration=None checks ``traces`` as a fixed duration does (no IndexError, no silent other trace)."""
    with pytest.raises(SweepError, match=match):
        sweep_gains(shipped, [1.0], [1.0], duration=None, traces=traces, progress=False)


def test_whole_trace_replay_of_explicit_windows_runs_to_the_shortest_end(shipped):
    """duration=None with (trace, offset) windows: each from its offset, for the shortest remainder."""
    n = int(shipped.lengths[1])
    r = sweep_pairs(shipped, [(3.0, 1.0)], duration=None, traces=[(1, n - 501), (2, n - 801)], progress=False)
    assert r.windows == ((1, n - 501), (2, n - 801))
    assert r.settings["steps"] == 500
    fixed = sweep_pairs(shipped, [(3.0, 1.0)], duration=5.0, traces=[(1, n - 501), (2, n - 801)], progress=False)
    for c, v in _numeric(fixed).items():
        assert_array_equal(_numeric(r)[c], v, err_msg=c)


class _SpyBackend:
    """Stands in for the backend a sweep makes from a name; records whether the sweep closed it."""

    def __init__(self):
        from heli_core.backends import LocalBackend

        self.inner, self.closed = LocalBackend(1), False

    def map(self, *args, **kwargs):
        return self.inner.map(*args, **kwargs)

    def describe(self):
        return self.inner.describe()

    def close(self):
        self.closed = True


def test_a_backend_made_from_a_name_is_closed_after_the_sweep(shipped, monkeypatch):
    import heli_core.backends as backends

    made = []
    monkeypatch.setattr(backends, "make_backend", lambda name: made.append(_SpyBackend()) or made[-1])
    r = sweep_gains(shipped, [3.0], [1.0], duration=2.0, windows=1, progress=False, backend="local")
    assert r.settings["backend"] == "local, 1 worker" and made[-1].closed
    with pytest.raises(SweepError, match="out of range"):  # a sweep that fails before the replay closes it too
        sweep_gains(shipped, [3.0], [1.0], duration=2.0, traces=[7], progress=False, backend="local")
    with pytest.raises(SweepError, match="chunk_pairs"):
        sweep_gains(shipped, [3.0], [1.0], duration=2.0, progress=False, backend="local", chunk_pairs=0)
    assert all(b.closed for b in made)  # every backend made from a name, whether or not the sweep ran


# --------------------------------------------------------------------- outputs
def test_outputs_are_written(small_sweep, tmp_path):
    paths = [small_sweep.to_csv(tmp_path / "s.csv"), small_sweep.to_json(tmp_path / "s.json"),
             plot_heatmap(small_sweep, tmp_path / "h.png"), plot_histograms(small_sweep, tmp_path / "g.png")]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.png", "h.png", "s.csv", "s.json"]  # no temp files
    rows = list(csv.DictReader((tmp_path / "s.csv").open()))
    assert tuple(rows[0]) == COLUMNS and len(rows) == small_sweep.n_pairs
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["schema"] == "heli-env/gain-sweep" and len(doc["rows"]) == small_sweep.n_pairs
    unstable = [r for r in doc["rows"] if r["status"] == "unstable"]
    assert unstable and all(r["att_p90_deg"] is None for r in unstable)
    assert np.array(doc["histogram"]["counts"]).shape == small_sweep.hist_counts.shape
    for p in paths[2:]:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    md = markdown(small_sweep)
    assert "unstable (max pole" in md and "best pair" in md


def test_the_results_old_report_methods_warn_and_call_the_report(small_sweep, tmp_path):
    """A sweep's result no longer imports its report (issue 34); its ``to_markdown()`` and ``plot_*()`` answer
    for one release through :func:`heli_core.deprecation.moved_method`, naming the report's function."""
    with pytest.warns(DeprecationWarning, match="sweep_report.markdown.*0.2.0"):
        assert small_sweep.to_markdown() == markdown(small_sweep)
    with pytest.warns(DeprecationWarning, match="sweep_report.plot_heatmap"):
        assert small_sweep.plot_heatmap(tmp_path / "h.png").exists()
    with pytest.warns(DeprecationWarning, match="sweep_report.plot_histograms"):
        assert small_sweep.plot_histograms(tmp_path / "g.png").exists()


def test_histograms_count_every_sample(small_sweep):
    stable = small_sweep.stable
    n = small_sweep.settings["steps"] * small_sweep.settings["n_windows"]
    assert_array_equal(small_sweep.hist_counts[stable].sum(axis=1) + small_sweep.hist_overflow[stable], n)


# ---------------------------------------------------------------- flight tests
@pytest.mark.slow
def test_flight_tests_match_the_prediction(ideal):
    """Fresh-wind flights of the model itself: KS below 0.15 with 5 x 60 s (bench: ~0.05 with 10 x 60 s)."""
    res = validate_against_flights(ideal, [(3.0, 1.0)], n_flights=5, duration=60.0, seed=3, progress=False)
    assert res.table["status"][0] == "flown"
    assert 0.0 < res.table["ks_att"][0] < 0.15
    assert 0.0 < res.table["ks_rate"][0] < 0.15
    assert abs(res.table["att_p90_err_td"][0]) < 0.15
    assert "Prediction checked against flight tests" in flight_test_markdown(res)


@pytest.mark.slow
def test_flight_tests_of_a_loose_loop_meet_the_library_spectrum(shipped):
    """Kp 0.5, Kd 0 hardly closes the loop: its error is the slow gust itself. Fresh gusts with the library's
    whole spectrum (surrogates, the default) fly the predicted distribution up to the sampling noise of a few
    minutes of slow gusts (KS 0.05-0.14 over seeds 0-4 with 6 x 60 s); the one-corner coloured noise has too
    little slow power and flies about half the predicted error (KS 0.35-0.47 over seeds 0-4 with 3 x 60 s)."""
    pairs = [(0.5, 0.0)]
    prediction = sweep_pairs(shipped, pairs, duration=None, keep_samples=True, progress=False)
    runs = {g: validate_against_flights(shipped, pairs, n_flights=n, duration=60.0, seed=2, progress=False,
                                        prediction=prediction, gusts=g) for g, n in (("spectrum", 6), ("corner", 3))}
    assert runs["spectrum"].settings["gusts"] == "spectrum"
    ks = {g: float(r.table["ks_att"][0]) for g, r in runs.items()}
    assert ks["spectrum"] < 0.2 and ks["corner"] > 0.3
    assert ks["spectrum"] < 0.5 * ks["corner"]
    assert runs["corner"].table["att_p90_err_td"][0] > 0.3  # the prediction is far above what one corner flies
    assert abs(runs["spectrum"].table["att_p90_err_td"][0]) < 0.25


def test_flight_tests_skip_unstable_pairs(delayed):
    pred = sweep_pairs(delayed, [(0.0, 1.0), (5.0, 1.0)], duration=10.0, windows=2, keep_samples=True,
                       progress=False)
    res = validate_against_flights(delayed, [(0.0, 1.0), (5.0, 1.0)], n_flights=1, duration=5.0, prediction=pred,
                                   progress=False)
    assert list(res.table["status"]) == ["unstable", "flown"]
    assert np.isnan(res.table["ks_att"][0]) and np.isfinite(res.table["ks_att"][1])


@pytest.fixture(scope="module")
def short_prediction(shipped):
    """Roll, dt = 0.01 s, pairs (3, 1) and (5, 1), with samples: what the mismatch tests vary."""
    return sweep_pairs(shipped, [(3.0, 1.0), (5.0, 1.0)], duration=2.0, windows=1, keep_samples=True,
                       progress=False)


@pytest.mark.parametrize("kwargs, pairs, match", [
    ({"axis": "pitch"}, [(3.0, 1.0)], r"axis \(pitch\), got a sweep of roll"),
    ({"dt": 0.02}, [(3.0, 1.0)], r"dt = 0.02 s, got dt = 0.01 s"),
    ({}, [(3.0, 1.0), (4.0, 1.0)], r"no row for the pair \(kp, kd\) = \(4, 1\) \(its nearest is \(3, 1\)\)"),
    ({}, [(5.5, 1.0)], r"no row for the pair \(kp, kd\) = \(5.5, 1\) \(its nearest is \(5, 1\)\)"),
])
def test_flight_tests_reject_a_prediction_of_other_flights(shipped, short_prediction, kwargs, pairs, match):
    """A prediction of another axis, dt or pairs is refused, not matched to its nearest row."""
    with pytest.raises(SweepError, match=match):
        validate_against_flights(shipped, pairs, n_flights=1, duration=1.0, prediction=short_prediction,
                                 progress=False, **kwargs)


def test_flight_tests_reject_a_prediction_without_samples(shipped):
    pred = sweep_pairs(shipped, [(3.0, 1.0)], duration=2.0, windows=1, progress=False)
    with pytest.raises(SweepError, match="keep_samples=True"):
        validate_against_flights(shipped, [(3.0, 1.0)], n_flights=1, duration=1.0, prediction=pred, progress=False)


def test_flight_tests_use_the_rows_of_a_matching_prediction(shipped, short_prediction):
    """Pairs in another order than the sweep's each get their own row's prediction."""
    res = validate_against_flights(shipped, [(5.0, 1.0), (3.0, 1.0)], n_flights=1, duration=2.0,
                                   prediction=short_prediction, progress=False)
    assert list(res.table["status"]) == ["flown", "flown"]
    assert_array_equal(res.table["pred_td_att_p90_deg"], short_prediction.table["att_p90_deg"][::-1])


def _same_flight_tests(a, b):
    for c, v in a.table.items():
        assert_array_equal(b.table[c], v, err_msg=c)
    assert a.settings == b.settings
    assert a.samples.keys() == b.samples.keys()
    for k, v in a.samples.items():
        assert_array_equal(b.samples[k][0], v[0])


def test_flight_tests_take_their_settings_as_one_config_or_by_keyword(shipped, short_prediction):
    """The same flights, bit for bit, from a FlightTestConfig and from its fields by keyword; a keyword given
    beside a config replaces the config's field (as SweepConfig's and TrainConfig's do)."""
    kw = {"n_flights": 2, "duration": 2.0, "seed": 7, "truth": "paper", "substeps": 2, "progress": False}
    config = FlightTestConfig(**kw)
    by_keyword = validate_against_flights(shipped, [(3.0, 1.0), (5.0, 1.0)], prediction=short_prediction, **kw)
    by_config = validate_against_flights(shipped, [(3.0, 1.0), (5.0, 1.0)], config, prediction=short_prediction)
    _same_flight_tests(by_keyword, by_config)
    other_seed = validate_against_flights(shipped, [(3.0, 1.0), (5.0, 1.0)], config, prediction=short_prediction,
                                          seed=8)
    assert other_seed.settings["seed"] == 8 and config.seed == 7
    _same_flight_tests(validate_against_flights(shipped, [(3.0, 1.0), (5.0, 1.0)], prediction=short_prediction,
                                                **{**kw, "seed": 8}), other_seed)
    with pytest.raises(TypeError, match="unknown flight test settings flights; expected fields of FlightTestConfig"):
        validate_against_flights(shipped, [(3.0, 1.0)], flights=3)
    with pytest.raises(TypeError, match="config must be a FlightTestConfig"):
        validate_against_flights(shipped, [(3.0, 1.0)], "pitch")


@pytest.mark.parametrize("field, value, match", [
    ("n_flights", 0, "n_flights must be a whole number >= 1, got 0"),
    ("n_flights", 2.5, "n_flights must be a whole number >= 1, got 2.5"),
    ("duration", -1.0, "duration must be a positive number of seconds, got -1.0"),
    ("dt", float("nan"), "dt must be a positive control period in seconds, got nan"),
    ("seed", -1, "seed must be a whole number >= 0, got -1"),
    ("truth", "moon", "truth must be 'model', 'paper' or a ModelParams, got 'moon'"),
    ("substeps", 0, "substeps must be a whole number >= 1, got 0"),
    ("sensors", "yes", "sensors must be True or False, got 'yes'"),
    ("gusts", "gaussian", "gusts must be one of \\('spectrum', 'corner'\\), got 'gaussian'"),
    ("axis", "up", "axis"),
])
def test_a_bad_flight_test_setting_is_named(field, value, match):
    with pytest.raises(SweepError, match=match):
        FlightTestConfig(**{field: value})


# ------------------------------------------------------------------------- CLI
def test_cli_writes_the_outputs(tmp_path, capsys):
    out = tmp_path / "sw"
    rc = main(["sweep", "--kp", "1:4:2", "--kd", "0:1:2", "--duration", "5", "--out", str(out), "--no-progress"])
    assert rc == 0
    assert sorted(p.name for p in out.iterdir()) == ["heatmap.png", "histograms.png", "sweep.csv", "sweep.html",
                                                     "sweep.json", "sweep.md"]
    text = capsys.readouterr().out
    assert "best by p90" in text and "best with gain margin >= 6 dB and phase margin >= 45 deg: Kp = " in text
    # the 2 x 2 grid's best pair is its corner (4, 1): the grid grows until the best pair is interior (on the
    # shipped model, whose 45 ms servo delay bounds the gains, Kp 64, Kd 16)
    assert "grid grown 2 times from 2 x 2 to 5 x 8" in text and "extension stopped: interior" in text
    rows = list(csv.DictReader((out / "sweep.csv").open()))
    assert len(rows) == 40 and {r["extension_round"] for r in rows} == {"0", "1", "2"}


def test_cli_no_extend_sweeps_the_grid_as_given(tmp_path, capsys):
    out = tmp_path / "sw"
    assert main(["sweep", "--kp", "1:4:2", "--kd", "0:1:2", "--duration", "2", "--windows", "1", "--out", str(out),
                 "--no-extend", "--no-plots", "-q"]) == 0
    rows = list(csv.DictReader((out / "sweep.csv").open()))
    assert [(r["kp"], r["kd"], r["extension_round"]) for r in rows] == [
        ("1", "0", "0"), ("1", "1", "0"), ("4", "0", "0"), ("4", "1", "0")]
    text = capsys.readouterr().out
    assert "extension stopped: disabled: the best pair (Kp 4, Kd 1) lies on the upper Kp edge and the upper Kd " \
           "edge (extension off)" in text


@pytest.mark.parametrize("argv, match", [
    (["--kp", "4:1:3", "--kd", "0:1:2"], "reversed"),
    (["--kp", "1:4:0", "--kd", "0:1:2"], "empty"),
    (["--kp", "1:4:2", "--kd", "nan:1:2"], "finite"),
    (["--kp", "1:4:2", "--kd=-1:1:2"], ">= 0"),  # a leading minus needs "="
    (["--kp", "1:4:2", "--kd", "0:1:2", "--model", "/no/such/model"], "does not exist"),
])
def test_cli_errors_exit_2(argv, match, tmp_path, capsys):
    assert main(["sweep", *argv, "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "SweepError" in err and match in err
    assert not (tmp_path / "o").exists()


def test_cli_rejects_a_bad_duration(capsys):
    with pytest.raises(SystemExit) as e:
        main(["sweep", "--kp", "1", "--kd", "1", "--duration", "-5"])
    assert e.value.code == 2


# ------------------------------------------------------- one closed loop, one sampler, one config
def test_the_replay_splits_pairs_into_chunks_without_changing_a_number(shipped):
    """controllers.replay.fly: every pair's states are independent of the others in its chunk."""
    from controllers.replay import Autopilot, fly, zoh_step
    from controllers.sweep_inputs import prepare

    rp = prepare(shipped, "pitch", 2.0, 0.01, 3, None, 3)
    kp, kd = np.array([1.0, 3.0, 6.0]), np.array([0.5, 1.0, 2.0])
    nominal = np.array([[8.0, 2.0], [8.0, 2.0], [1.0, 0.3]])
    autopilot = Autopilot(1, kp, kd, nominal, np.sign(shipped.params.control_gains))
    step = zoh_step(shipped.params, 0.01)
    whole = [rec for _, rec in fly(step, rp.inputs, autopilot, progress=False)]
    parts = [rec for _, rec in fly(step, rp.inputs, autopilot, max_batch=1, progress=False)]
    assert len(whole) == 1 and len(parts) == 3
    for name in ("att", "rate", "act", "sat", "omax"):
        assert_array_equal(np.concatenate([getattr(r, name) for r in parts]), getattr(whole[0], name),
                           err_msg=name)


def test_the_replay_with_zero_sensor_noise_flies_the_true_state(shipped):
    from controllers.replay import Autopilot, LoopInputs, fly, rk4_step
    from controllers.sweep_inputs import prepare

    rp = prepare(shipped, "roll", 1.0, 0.01, 0, None, 2, sensors=False)
    quiet = LoopInputs(rp.inputs.trim, rp.inputs.col, rp.inputs.torque, np.zeros_like(rp.inputs.torque),
                       np.zeros_like(rp.inputs.torque))
    autopilot = Autopilot(0, np.array([3.0]), np.array([1.0]), np.array([[3.0, 1.0]] * 3),
                          np.sign(shipped.params.control_gains))
    step = rk4_step(shipped.params, 0.01, 2)
    (_, a), = fly(step, rp.inputs, autopilot, progress=False)
    (_, b), = fly(step, quiet, autopilot, progress=False)
    for name in ("att", "rate", "act", "sat"):
        assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_in_place_metrics_equal_the_shared_error_metrics():
    from controllers.metrics import error_metrics, error_metrics_inplace, histogram_edges

    rng = np.random.default_rng(4)
    att, rate, act = (rng.standard_normal((3, 5000)) * s for s in (2.0, 20.0, 0.3))
    edges = histogram_edges()
    ref = error_metrics(att, rate, act, saturated=np.zeros(att.shape, bool), hist_edges=edges)
    got = error_metrics_inplace(*(np.abs(v).astype(np.float32) for v in (att, rate, act)), np.zeros(3), edges)
    for c in ("att_rms_deg", "att_p50_deg", "att_p90_deg", "att_p99_deg", "rate_rms_dps", "rate_p99_dps",
              "stick_rms", "stick_p99", "saturation"):
        assert_allclose(got[c], ref[c], rtol=1e-5, atol=1e-9, err_msg=c)
    assert np.abs(got["hist_counts"] - ref["hist_counts"]).sum() <= 6  # float32 rounding at bin edges
    assert_array_equal(got["hist_counts"].sum(axis=1) + got["hist_overflow"], 5000)


def test_sweep_config_runs_the_same_sweep_as_the_keywords(shipped):
    from controllers.sweep import SweepConfig

    cfg = SweepConfig(axis="yaw", duration=2.0, windows=2, seed=5, progress=False, hist_bins=30)
    a = sweep_gains(shipped, [1.0, 2.0], [0.5], **dataclasses.asdict(cfg))
    b = sweep_gains(shipped, [1.0, 2.0], [0.5], axis="yaw", duration=2.0, windows=2, seed=5, progress=False,
                    hist_bins=30)
    assert a.windows == b.windows and a.settings["axis"] == "yaw"
    for c, v in _numeric(a).items():
        assert_array_equal(_numeric(b)[c], v, err_msg=c)


def test_one_window_sampler_for_sweep_episodes_and_splits(shipped):
    """heli_env.tasks' draws are the ones draw_episode, the sweep and trace_split make."""
    from controllers.sweep_inputs import draw_library_windows
    from heli_env.spec import build_spec
    from heli_env.tasks import draw_episode, draw_offset, draw_offsets, window_count

    assert window_count(100, 100) == 1 and window_count(99, 100) == 0
    spec = build_spec(shipped, episode_seconds=10.0, init_angle_deg=0.0, init_rate_deg=0.0)
    assert (spec.model.n_traces, spec.needed, spec.episode_steps) == (3, 1001, 1000)
    ep = draw_episode(np.random.default_rng(2), spec)
    rng = np.random.default_rng(2)
    trace = int(rng.integers(3))
    assert (ep.trace, ep.offset) == (trace, draw_offset(rng, window_count(shipped.lengths[trace], 1001)))
    wins = draw_library_windows(shipped, [1], 3, 100, 1, 9)
    assert list(wins) == [(1, o) for o in draw_offsets(np.random.default_rng(9), window_count(shipped.lengths[1],
                                                                                                101), 3)]
    assert len(set(wins)) == 3


def test_gain_matrices_are_the_slopes_of_the_pd_law(shipped):
    plant = cl.hover_plant(shipped.params, 0.01, 0.1)
    nominal = cl.nominal_gains(plant)
    K = cl.gain_matrices(plant, 1, [2.0, 5.0], [0.5, 1.5], nominal)
    x = np.random.default_rng(0).standard_normal(plant.n)
    for g, (kp, kd) in enumerate(((2.0, 0.5), (5.0, 1.5))):
        gains = [tuple(nominal[0]), (kp, kd), tuple(nominal[2])]
        u = [pd_command(p, d, plant.signs[i], -x[plant.angle_idx[i]], -x[plant.rate_idx[i]])
             for i, (p, d) in enumerate(gains)]
        assert_allclose(-K[g] @ x, u, rtol=1e-12, atol=1e-15)


# ------------------------------------------------------------- the grid grows past an edge; margins
def _assert_same_rows(a, b, rows_a=slice(None), rows_b=slice(None)):
    for c, v in _numeric(a).items():
        assert_array_equal(_numeric(b)[c][rows_b], v[rows_a], err_msg=c)
    assert_array_equal(b.table["status"][rows_b], a.table["status"][rows_a])
    assert_array_equal(b.hist_counts[rows_b], a.hist_counts[rows_a])


def test_a_grid_whose_best_pair_is_on_an_edge_grows_until_it_is_interior(small_sweep):
    ext = small_sweep.extension
    assert ext["kp_asked"] == [0.0, 5.0, 20.0, 40.0] and ext["kd_asked"] == [0.0, 1.0, 3.0]
    # the grid asked for had its best pair, (40, 3), on the upper Kd edge (and (80, 3) beyond Kp is unstable)
    assert ext["rounds"][0]["best_before"]["kp"] == 40.0 and ext["rounds"][0]["best_before"]["kd"] == 3.0
    assert [r["edges"] for r in ext["rounds"]] == [["upper Kd edge"], ["upper Kp edge"]]
    assert_allclose(small_sweep.kd_values, [0, 1, 3, 9, 27, 81])  # the grid's last ratio (3) continued
    assert_allclose(small_sweep.kp_values, [0, 5, 20, 40, 80, 160, 320])  # ... and here 2
    assert ext["stop"] == "interior"
    best = small_sweep.best()
    i, j = divmod(small_sweep.index(best["kp"], best["kd"]), small_sweep.kd_values.size)
    assert 0 < i < small_sweep.kp_values.size - 1 and 0 < j < small_sweep.kd_values.size - 1
    assert best["att_p90_deg"] < ext["rounds"][0]["best_before"]["att_p90_deg"]
    # the pairs added are recorded, by round
    rounds = small_sweep.grid("extension_round")
    assert (rounds[:4, :3] == 0).all() and (rounds[:4, 3:] == 1).all() and (rounds[4:] == 2).all()
    assert [r["pairs_added"] for r in ext["rounds"]] == [12, 18] and small_sweep.n_pairs == 42
    assert "grew 2 times" in markdown(small_sweep) and "added by extension 2" in markdown(small_sweep)


def test_the_grown_grid_equals_a_sweep_of_the_final_grid(delayed, small_sweep):
    """Rows are computed pair by pair on the same windows: growing changes no number."""
    once = sweep_gains(delayed, small_sweep.kp_values, small_sweep.kd_values, duration=10.0, windows=3, seed=7,
                       progress=False, extend=False)
    once.table["extension_round"] = small_sweep.table["extension_round"]  # the one column that differs
    _assert_same_rows(small_sweep, once)


def test_extend_false_sweeps_the_grid_as_given(delayed, small_sweep):
    r = sweep_gains(delayed, [0.0, 5.0, 20.0, 40.0], [0.0, 1.0, 3.0], duration=10.0, windows=3, seed=7,
                    progress=False, extend=False)
    assert_array_equal(r.kp_values, [0, 5, 20, 40]) and r.n_pairs == 12
    assert r.extension["rounds"] == [] and r.extension["stop"] == "disabled"
    assert "lies on the upper Kd edge" in r.extension["stop_detail"]
    assert not r.table["extension_round"].any()
    asked = np.flatnonzero(small_sweep.table["extension_round"] == 0)
    _assert_same_rows(r, small_sweep, rows_b=asked)
    again = sweep_gains(delayed, [0.0, 5.0, 20.0, 40.0], [0.0, 1.0, 3.0], duration=10.0, windows=3, seed=7,
                        progress=False, max_extensions=0)
    assert again.n_pairs == 12 and again.extension["stop"] == "limit"


def test_extension_stops_where_the_pair_beyond_is_unstable_or_at_the_limit(delayed, shipped):
    # Kd given as one value; beyond the best Kp, 40, the delayed model's loop is unstable at Kp 80
    r = sweep_gains(delayed, [5.0, 20.0, 40.0], [3.0], duration=2.0, windows=1, progress=False)
    assert r.extension["stop"] == "unstable beyond" and r.n_pairs == 3
    assert "upper Kp edge (Kp 80, Kd 3 beyond it is unstable)" in r.extension["stop_detail"]
    assert "only Kd value (the axis was given as one value)" in r.extension["stop_detail"]
    # the shipped model (no delay) stays stable far beyond: one round is not enough
    r = sweep_gains(shipped, [1.0, 2.0], [0.5, 1.0], duration=2.0, windows=1, progress=False, max_extensions=1)
    assert r.extension["stop"] == "limit" and len(r.extension["rounds"]) == 1
    assert_allclose(r.kp_values, [1, 2, 4, 8, 16]) and r.best()["kp"] == 16.0


def test_continuation_of_a_grid_axis():
    from controllers.sweep_extend import continuation

    assert_allclose(continuation([1.0, 2.0, 4.0], "high")[0], [8, 16, 32])
    assert_allclose(continuation([1.0, 2.0, 4.0], "low")[0], [0.125, 0.25, 0.5])
    assert_allclose(continuation([0.0, 5.0, 10.0], "high")[0], [20, 40, 80])
    assert_allclose(continuation([0.0, 1.0], "high")[0], [2, 4, 8])  # no ratio from 0: doubling
    assert continuation([0.0, 1.0], "low") == (None, "no gain below 0")
    assert continuation([3.0], "high")[0] is None and continuation([2.0, 1.0], "high")[0] is None


@pytest.mark.parametrize("kwargs, match", [({"max_extensions": -1}, "max_extensions"),
                                           ({"max_extensions": 1.5}, "max_extensions"),
                                           ({"extend": "yes"}, "extend must be True or False")])
def test_bad_extension_settings_raise(shipped, kwargs, match):
    with pytest.raises(SweepError, match=match):
        sweep_gains(shipped, [1.0], [1.0], duration=1.0, progress=False, **kwargs)


def test_margins_are_the_pd_loop_analysis_margins(delayed, small_sweep):
    """Every pair's margins equal controllers.pd.loop_analysis on the decoupled model (stable or not)."""
    from controllers.pd import loop_analysis

    for kp, kd in ((5.0, 1.0), (20.0, 3.0), (80.0, 9.0), (40.0, 0.0), (320.0, 81.0)):
        row = small_sweep.row(small_sweep.index(kp, kd))
        la = loop_analysis(delayed.params, "roll", kp, kd, 0.01)
        assert_allclose(row["gain_margin_db"], la.gain_margin_db, rtol=1e-6, err_msg=(kp, kd))
        assert_allclose(row["phase_margin_deg"], la.phase_margin, rtol=1e-6, err_msg=(kp, kd))
        assert (row["status"] == "unstable") == (not la.stable)
    assert np.all((small_sweep.table["gain_margin_db"] > 0) | ~small_sweep.stable)


def test_the_best_robust_pair_keeps_the_margins(small_sweep, tmp_path):
    rob = small_sweep.best_robust()
    assert rob["status"] == "stable" and rob["gain_margin_db"] >= 6.0 and rob["phase_margin_deg"] >= 45.0
    assert (rob["kp"], rob["kd"]) == (5.0, 3.0)  # the best pair, (80, 9), keeps 1.3 dB and 4.5°
    t = small_sweep.table
    keeps = small_sweep.stable & (t["gain_margin_db"] >= 6.0) & (t["phase_margin_deg"] >= 45.0)
    assert rob["att_p90_deg"] == np.nanmin(t["att_p90_deg"][keeps])
    assert small_sweep.best_robust(min_gain_margin_db=40.0) is None
    md = markdown(small_sweep)
    assert "best robust pair (gain margin ≥ 6 dB and phase margin ≥ 45°): **Kp = 5, Kd = 3**" in md
    rows = list(csv.DictReader(open(small_sweep.to_csv(tmp_path / "s.csv"))))
    zero = rows[small_sweep.index(0.0, 0.0)]  # no loop at all: margins infinite
    assert (zero["gain_margin_db"], zero["phase_margin_deg"]) == ("inf", "inf")


def test_the_sweep_reads_the_state_through_the_models_sensors(shipped):
    """The shipped model's sensors (white noise and vibration lines) in both domains: the replay's autopilot
    reads them (same noise for every pair, drawn apart from the windows), the frequency domain adds their
    variance; a high derivative gain pays for the gyro noise it amplifies, so the two domains agree on it."""
    from controllers.sweep_inputs import prepare

    rp = prepare(shipped, "roll", 5.0, 0.01, 3, None, 2)
    quiet = prepare(shipped, "roll", 5.0, 0.01, 3, None, 2, sensors=False)
    assert rp.windows == quiet.windows and quiet.inputs.rate_noise is None
    lines = [ln.amplitude for ln in shipped.sensors.gyro_lines if ln.axis == "roll"]  # 27, 30, 40 Hz
    expected = np.sqrt(shipped.sensors.gyro_noise[0] ** 2 + sum(a * a / 2 for a in lines))
    assert np.std(rp.inputs.rate_noise[0]) == pytest.approx(expected, rel=0.1)
    assert np.std(rp.inputs.att_noise[0]) == pytest.approx(shipped.sensors.attitude_noise[0], rel=0.1)
    pairs = [(30.0, 1.0), (30.0, 12.0)]
    on = sweep_pairs(shipped, pairs, duration=20.0, windows=2, progress=False)
    off = sweep_pairs(shipped, pairs, duration=20.0, windows=2, progress=False, sensors=False)
    assert on.settings["sensors"]["gyro_lines"] and off.settings["sensors"] is None
    assert on.table["stick_rms"][1] > 2 * off.table["stick_rms"][1]  # kd x gyro noise on the stick
    for r in (on, off):
        assert_allclose(r.table["att_p90_deg"], r.table["pred_att_p90_deg"], rtol=0.2)


def test_a_pair_that_misses_the_ks_target_is_named_with_its_reason():
    from controllers.sweep_report import miss_reason

    settings = {"duration": 60.0, "prediction": "3 windows of 60 s"}
    row = {"pred_settle_s": 12.4, "saturation": 0.0, "att_p90_err_td": 0.9}
    assert miss_reason(row, settings).startswith("a slow loop (it settles in 12.4 s)")
    assert "saturates 5.0 %" in miss_reason({**row, "pred_settle_s": 1.0, "saturation": 0.05}, settings)
    assert "+90 % off" in miss_reason({**row, "pred_settle_s": 1.0}, settings)


def test_a_sweep_takes_its_settings_as_one_config_or_by_keyword(shipped):
    from controllers.sweep import SweepConfig

    cfg = SweepConfig(duration=2.0, windows=1, progress=False, extend=False)
    a = sweep_gains(shipped, [1.0, 3.0], [0.5], cfg)
    b = sweep_gains(shipped, [1.0, 3.0], [0.5], duration=2.0, windows=1, progress=False, extend=False)
    np.testing.assert_array_equal(a.table["att_p90_deg"], b.table["att_p90_deg"])
    c = sweep_gains(shipped, [1.0, 3.0], [0.5], cfg, duration=3.0)  # a keyword replaces the config's field
    assert c.settings["duration"] == pytest.approx(3.0)
    with pytest.raises(TypeError, match="unknown sweep settings windowz"):
        sweep_gains(shipped, [1.0], [0.5], windowz=3)
    with pytest.raises(TypeError, match="config must be a SweepConfig"):
        sweep_pairs(shipped, [(1.0, 0.5)], "roll")


@pytest.mark.slow
def test_cli_window_longer_than_the_traces_names_the_option_and_the_longest_that_fits(tmp_path, capsys):
    """Issue 31: '(shorten duration)' named neither the option nor the longest duration that fits."""
    import re

    from heli_cli.main import main

    assert main(["sweep", "--kp", "1:4:2", "--kd", "0:1:2", "--duration", "5000", "--out", str(tmp_path / "sw"),
                 "-q", "--no-plots"]) == 2
    err = capsys.readouterr().err
    advised = re.search(r"the longest that fits every trace is ([\d.]+) s: pass --duration \1 or less", err)
    assert advised and "duration=" not in err, err
    assert main(["sweep", "--kp", "1:4:2", "--kd", "0:1:2", "--duration", advised.group(1), "--out",
                 str(tmp_path / "sw"), "-q", "--no-plots"]) == 0


@pytest.mark.slow
def test_a_growing_sweep_draws_one_bar_over_all_its_rounds(shipped, monkeypatch):
    """Issue 31: 'heli sweep' drew a separate '0/1 task' bar per round of its growing grid; one bar now counts
    every round's tasks (the backend adds each map's tasks to the bar it is given)."""
    import io

    import tqdm

    class _Terminal(io.StringIO):
        def isatty(self):
            return True

    bars = []
    real = tqdm.tqdm

    def counted(*args, **kwargs):
        bars.append(real(*args, **kwargs))
        return bars[-1]

    monkeypatch.setattr(tqdm, "tqdm", counted)
    monkeypatch.setattr("sys.stderr", _Terminal())
    r = sweep_gains(shipped, [1.0, 4.0], [0.0, 1.0], duration=2.0, windows=2, progress=True, backend="local",
                    chunk_pairs=1)
    assert len(r.settings["extension"]["rounds"]) >= 1, "the grid grew: several rounds of tasks"
    assert len(bars) == 1 and bars[0].n == bars[0].total == r.settings["tasks"]


# ------------------------------------------------------------- derivative filter
def test_a_filtered_sweep_flies_what_the_filtered_pd_controller_flies(shipped):
    """With d_filter_hz the replay is the environment under PDController.predict with that filter (its state
    carried), and its margins are controllers.pd.loop_analysis' with the filter in the loop."""
    from controllers.pd import PDController, PDGains, loop_analysis

    kp, kd, f_c = 20.0, 3.0, 8.0
    r = sweep_pairs(shipped, [(kp, kd)], duration=5.0, traces=[(1, 1234)], keep_samples=True, progress=False,
                    sensors=False, d_filter_hz=f_c)
    assert r.settings["d_filter_hz"] == [f_c] * 3 and "low-passed" in markdown(r)
    nominal = np.array(r.settings["nominal_gains"])
    gains = PDGains((kp, nominal[1][0], nominal[2][0]), (kd, nominal[1][1], nominal[2][1]), f_c)
    pol = PDController.from_model(shipped.params, gains)
    env = HeliAttitudeEnv(model=shipped, init_angle_deg=0.0, init_rate_deg=0.0, episode_seconds=5.0, obs_noise=0.0)
    obs, _ = env.reset(seed=0, options={"trace": 1, "offset": 1234})
    state, errs = None, [0.0]
    for _ in range(499):
        a, state = pol.predict(obs, state)
        obs, _, term, trunc, info = env.step(a)
        errs.append(info["attitude_error_deg"][0])
    assert_allclose(r.samples[0][0][:500], errs, atol=1e-5)  # the env's observation is float32
    la = loop_analysis(shipped.params, "roll", kp, kd, 0.01, d_filter_hz=f_c)
    assert_allclose(r.table["gain_margin_db"][0], la.gain_margin_db, rtol=1e-6)
    assert_allclose(r.table["phase_margin_deg"][0], la.phase_margin, rtol=1e-6)


def test_a_filtered_sweep_predicts_its_smoother_stick_in_both_domains(shipped):
    """The model's sensors through a 5 Hz filter: the stick's RMS falls in the replay and in the frequency
    domain alike, and the two domains still agree on the p90."""
    pairs = [(30.0, 6.0)]
    plain = sweep_pairs(shipped, pairs, duration=20.0, windows=2, progress=False)
    smooth = sweep_pairs(shipped, pairs, duration=20.0, windows=2, progress=False, d_filter_hz=5.0)
    assert smooth.table["stick_rms"][0] < 0.7 * plain.table["stick_rms"][0]
    assert smooth.table["pred_stick_rms"][0] < 0.7 * plain.table["pred_stick_rms"][0]
    assert_allclose(smooth.table["stick_rms"], smooth.table["pred_stick_rms"], rtol=0.2)
    assert_allclose(smooth.table["att_p90_deg"], smooth.table["pred_att_p90_deg"], rtol=0.2)
    with pytest.raises(SweepError, match="d_filter_hz must be a cutoff frequency > 0 Hz"):
        sweep_pairs(shipped, pairs, duration=1.0, windows=1, progress=False, d_filter_hz=-2.0)


def test_cli_sweep_takes_a_derivative_filter(tmp_path, capsys):
    assert main(["sweep", "--kp", "10", "--kd", "1", "--duration", "2", "--windows", "1", "--no-extend",
                 "--d-filter-hz", "5", "--no-plots", "--out", str(tmp_path / "sw"), "-q"]) == 0
    assert json.loads((tmp_path / "sw" / "sweep.json").read_text())["settings"]["d_filter_hz"] == [5.0] * 3
    assert "low-passed" in (tmp_path / "sw" / "sweep.md").read_text()
    with pytest.raises(SystemExit):
        main(["sweep", "--kp", "10", "--kd", "1", "--d-filter-hz", "0"])
    assert "expected one positive cutoff in Hz or three" in capsys.readouterr().err
