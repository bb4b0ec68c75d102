"""The stick-noise test (``identification.likelihood.stick_noise``): a log whose sticks moved between its samples is
named, one whose sticks the aircraft felt as logged is not, and ``heli identify``'s warning says so."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from identification.bench.aircraft import AIRCRAFT

AGILE = AIRCRAFT["agile"]
"""A 450-class flybarless helicopter (the bench's 'agile', :mod:`identification.bench.aircraft`): its stiff yaw shows
stick noise most."""


def _flight(log_every: int, seed: int = 1301, duration: float = 90.0):
    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight

    config = replace(BENCH_CELLS["held-sticks-pd"], duration=duration, log_every=log_every)
    return simulate_flight(duration, seed=seed, config=config, truth=AGILE)


@pytest.fixture(scope="module")
def checks():
    """The test on a link four times faster than its log (command noise 0.01 on the frames the log skips) and on
    the same cell held at the log's rate."""
    from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier
    from identification.likelihood.stick_noise import check_stick_noise

    out = {}
    for every in (4, 1):
        ident = MaximumLikelihoodIdentifier(**CLI_TIMING).fit(_flight(every).flight)
        out[every] = (ident, check_stick_noise(ident))
    return out


def test_neighbour_shrinking_keeps_lines_and_ends_and_damps_alternation():
    from identification.likelihood.stick_noise import neighbour_shrunk

    t = np.arange(50.0)
    sticks = np.vstack([np.full(50, 0.3), 0.01 * t - 0.2, (-1.0) ** t * 0.1, np.sin(0.05 * t)])
    out = neighbour_shrunk(sticks, 0.75)
    assert out.shape == sticks.shape
    np.testing.assert_allclose(out[:2], sticks[:2], atol=1e-15)  # a constant and a straight line
    np.testing.assert_array_equal(out[:, [0, -1]], sticks[:, [0, -1]])
    np.testing.assert_allclose(out[2, 1:-1], (1 - 2 * 0.75) * sticks[2, 1:-1])  # -0.5 x the alternation
    np.testing.assert_allclose(out[3], sticks[3], atol=0.75 * 0.5 * 0.05 ** 2 + 1e-12)  # a slow sine barely moves
    np.testing.assert_array_equal(neighbour_shrunk(sticks, 0.0), sticks)


def test_sticks_that_moved_between_samples_are_named_on_the_axis_they_bias(checks):
    """At a link four times the log's rate the agile yaw gain reads 4-10 % low; its shrunk sticks explain the yaw
    rate far better than a parameter's worth, and the gain solved on them moves up; the refit on them agrees."""
    from identification.likelihood.stick_noise import refit_on_shrunk

    ident, check = checks[4]
    assert "yaw" in check.axes
    assert check.lr["yaw"] > 5 * check.thresholds["yaw"]
    assert check.moved["yaw"]["k10"] > 1.0 and "k11" not in check.moved["yaw"]  # the gains, not the damping
    assert set(check.describe()["axes"]) == set(check.axes)
    refit = refit_on_shrunk(ident)
    assert ident.axes_["yaw"].nll - refit.axes_["yaw"].nll == pytest.approx(check.lr["yaw"], rel=0.1)
    assert refit.params_.k10 > ident.params_.k10 * 1.01 and refit.params_.k11 > ident.params_.k11


def test_sticks_felt_as_logged_are_not_named(checks):
    """Held at the log's rate (the same pilot and command noise): the shrunk sticks explain the rates worse."""
    _, check = checks[1]
    assert check.axes == ()
    assert check.lr["yaw"] < 0


def test_the_warning_names_the_axes_and_what_avoids_it(checks):
    from identification.validation.fit_warnings import stick_noise_warning

    [line] = stick_noise_warning(checks[4][1])
    assert "yaw stick carries noise the aircraft did not feel" in line
    assert "Log the commands at the loop's rate" in line and "k10 +" in line
    assert stick_noise_warning(checks[1][1]) == [] and stick_noise_warning(None) == []


def test_an_unfitted_estimator_is_refused():
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier
    from identification.likelihood.stick_noise import check_stick_noise

    with pytest.raises(ValueError, match="needs a fitted MaximumLikelihoodIdentifier"):
        check_stick_noise(MaximumLikelihoodIdentifier())


def test_heli_identify_writes_the_warning_and_the_figures(tmp_path):
    """The workflow behind ``heli identify``: the warning among the run's warnings and in report.md, the test's
    figures in model.json."""
    import json

    from identification.workflows.identify import identify_and_report

    run = identify_and_report([_flight(4, seed=1302).flight], tmp_path / "m", plots=False, compare_structures=False,
                              disturbances=False)
    assert any("noise the aircraft did not feel" in w for w in run.warnings)
    noted = json.loads((tmp_path / "m" / "model.json").read_text())["fit_statistics"]["stick_noise"]
    assert "yaw" in noted["axes"] and noted["lr"]["yaw"] > noted["thresholds"]["yaw"]
    assert "noise the aircraft did not feel" in (tmp_path / "m" / "report.md").read_text()


def test_a_flight_controller_faster_than_the_fit_is_named_and_one_at_its_rate_is_not():
    """The inputs are a flight controller's commands: a warning where its loop (stated, or unknown) runs more
    than a quarter faster than the rate they are fitted at; none where it runs at that rate or for a pilot's
    sticks."""
    from types import SimpleNamespace

    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.validation.fit_warnings import controller_loop_warning

    def autopilot(every):
        config = replace(BENCH_CELLS["broadband-autopilot"], duration=5.0, log_every=every)
        return simulate_flight(5.0, seed=1, config=config).flight

    [line] = controller_loop_warning([autopilot(4)])
    assert "fitted at 100 Hz, and its loop runs at 400 Hz" in line and "reads that as damping" in line
    [cause] = controller_loop_warning([autopilot(4)], advice=False)
    assert line.startswith(cause) and "Identify from" not in cause and "Identify from the pilot's sticks" in line
    assert controller_loop_warning([autopilot(1)]) == []  # the loop decides at each logged sample
    pilot = simulate_flight(5.0, seed=1, config=replace(BENCH_CELLS["independent"], duration=5.0)).flight
    assert controller_loop_warning([pilot]) == []

    def imported(source, loop=None):
        meta = {"imported_from": {"format": "betaflight-blackbox", "input_source": source,
                                  **({"loop_rate_hz": loop} if loop else {})}}
        return SimpleNamespace(metadata=meta, sample_rate=200.0)

    [line] = controller_loop_warning([imported("controller")])
    assert "(heli import --inputs controller) fitted at 200 Hz" in line and "not in the log" in line
    assert controller_loop_warning([imported("servos", 240.0)]) == []  # within a quarter of the fit's rate
    assert len(controller_loop_warning([imported("servos", 4000.0)])) == 1
    assert controller_loop_warning([imported("sticks", 4000.0)]) == []
    own_servos = SimpleNamespace(metadata={"input_source": "servos (eq. 67)"}, sample_rate=100.0)
    assert controller_loop_warning([own_servos]) == []  # a CSV's servo columns: the pilot's radio drives them
