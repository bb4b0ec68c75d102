"""The native vector environment reproduces single environments bit for bit
(:class:`heli_env.vector_env.HeliAttitudeVectorEnv` beside :class:`heli_env.HeliAttitudeEnv`).

Each test runs ``num_envs`` single environments seeded ``seed + i`` beside one vector environment seeded
``seed`` under the same actions (:func:`vector_side_by_side.run_side_by_side`), through terminations,
truncations and autoresets, in a configuration of its own (task, sensors, delays, model structure): most
compile loops of their own (6-10 s each on a new machine), so they live in a file apart: the test run gives each file
to one worker, and two files of compiles can go to two.
"""

from __future__ import annotations

import dataclasses

import pytest
from vector_side_by_side import run_side_by_side

from heli_core.sensors import GyroLine, SensorModel
from heli_env import HeliAttitudeEnv, default_model_dir, load_env_model
from heli_env.kernels import BLOCK
from heli_env.tasks import TaskConfig
from identification.bench.flight_config import EFFECTS


@pytest.mark.parametrize("task", ["hold", "track", "rate"])
def test_vector_env_reproduces_single_envs_across_autoresets(task):
    counts = run_side_by_side({"task": task, "episode_seconds": 2.5})
    assert counts["terminated"] >= 1 and counts["truncated"] >= 2
    ends = counts["terminated"] + counts["truncated"]
    assert ends - 4 <= counts["autoreset"] <= ends  # every episode end but those on the last step


@pytest.mark.parametrize(
    "kwargs",
    [
        {"task": "track", "reference": "smooth", "obs_noise": (0.01, 0.03), "action_delay": 2},
        {"task": "rate", "dt": 0.02, "gust_scale": 2.0, "collective": 0.1},
        {"task": "hold", "init_angle_deg": 0.0, "init_rate_deg": 0.0},
        {"task": TaskConfig(task="track", axis_weights=(1.0, 9.0, 0.25)), "obs_noise": (0.01, 0.03)},
        {"task": "hold", "obs_noise": SensorModel((0.01, 0.02, 0.03), (0.003, 0.002, 0.0), (
            GyroLine("roll", 30.0, 0.04), GyroLine("yaw", 40.0, 0.02), GyroLine("roll", 27.0, 0.03)))},
        {"task": TaskConfig(task="hold", stick_step_weight=0.5), "action_delay": 1, "obs_noise": (0.01, 0.03)},
    ],
    ids=["noise-delay", "dt-gust-collective", "level", "axis-weights", "identified-sensors", "stick-step"],
)
def test_vector_env_reproduces_single_envs_with_other_settings(kwargs):
    counts = run_side_by_side({**kwargs, "episode_seconds": 2.0}, n=3, n_steps=300, seed=7)
    assert counts["autoreset"] >= 1


@pytest.mark.parametrize("effects", [(), tuple(EFFECTS)], ids=["shipped", "every-effect"])
def test_copies_in_every_block_reproduce_single_envs(effects):
    """The step loop runs a block of copies at a time: copies at the edges of the blocks and in a last,
    partial block step and observe as their single envs do (the shipped model's sensors and gyro lines; a
    model whose every constant is used: the loop reads them from an argument)."""
    shipped = load_env_model(default_model_dir())
    model = dataclasses.replace(shipped, params=shipped.params.with_values(
        **{k: v for e in effects for k, v in EFFECTS[e].items()}))
    n = 2 * BLOCK + 3
    counts = run_side_by_side({"model": model, "episode_seconds": 1.0}, n=n, n_steps=160, seed=3,
                               watch=[0, 2, BLOCK - 1, BLOCK, 2 * BLOCK - 1, 2 * BLOCK, n - 1])
    assert counts["autoreset"] >= 7


def test_vector_env_reproduces_pinned_traces_running_out():
    """A pinned offset near the end of a trace: each copy truncates where a single env does."""
    length = int(HeliAttitudeEnv().model.lengths[2])
    counts = run_side_by_side({"task": "hold"}, n=3, n_steps=60, options={"trace": 2, "offset": length - 21})
    assert counts["truncated"] >= 2
