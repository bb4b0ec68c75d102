"""The robustness check (controllers.robustness): the same agent on perturbed copies of the model."""

from __future__ import annotations

import pytest

from controllers.pd import PDController, design_gains
from controllers.robustness import CASES, robustness_check
from heli_env.env_model import perturbed


def test_perturbed_model_and_the_degradation_of_a_pd(shipped):
    slow = perturbed(shipped, delay=0.02, gain=0.8)
    assert slow.params.tau_roll == pytest.approx(shipped.params.tau_roll + 0.02)
    assert slow.params.k6 == pytest.approx(0.8 * shipped.params.k6)
    assert slow.torque is not shipped.torque and (slow.torque == shipped.torque).all()  # the same gusts
    fast = perturbed(shipped, delay=-0.04)  # a shorter delay stops at none (roll's 45 ms -> 5 ms, yaw's 35 ms -> 0)
    assert fast.params.tau_roll == pytest.approx(shipped.params.tau_roll - 0.04) and fast.params.tau_yaw == 0.0
    pd = PDController.from_model(shipped.params, design_gains(shipped.params))
    check = robustness_check(pd, shipped, traces="all", episodes_per_trace=2, episode_seconds=10.0, seed=1)
    assert list(check) == list(CASES)
    assert check["nominal"]["ratio"] == {"roll": 1.0, "pitch": 1.0, "yaw": 1.0}
    for axis in ("roll", "pitch", "yaw"):  # less control authority, larger errors; more, smaller
        assert check["gain -20 %"]["ratio"][axis] > 1.05 and check["gain +20 %"]["ratio"][axis] < 0.95
        assert check["+20 ms servo delay"]["ratio"][axis] > 1.0
    assert all(r["ended_early"] == 0 for r in check.values())
