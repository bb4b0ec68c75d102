"""Tests of the counter-based sensor noise (:mod:`heli_env.sensor_noise`)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import stats

from heli_env import HeliAttitudeEnv
from heli_env.sensor_noise import CHANNELS, draw_noise_key, noise_block, normal_pair, standard_normal
from heli_env.vector_env import HeliAttitudeVectorEnv


def test_the_stream_is_pinned():
    """The noise of a key never changes silently: same seed, same episode, across versions."""
    assert_allclose(noise_block(np.uint64(2024), 0, 1)[0],
                    [1.0703748255973264, 0.4682886784219065, 0.8737750099718387, 0.1688683539919577,
                     -0.7966297197131655, -0.9125994230384523], rtol=0, atol=0)
    assert_allclose(noise_block(np.uint64(2**64 - 1), 1000, 1)[0],
                    [0.7623346313143281, -0.4422825362515535, -0.5636515344611138, 0.4074748800840388,
                     -0.22913666441260097, -0.6040238531349603], rtol=0, atol=0)


def test_any_step_is_read_directly():
    key = np.uint64(77)
    whole = noise_block(key, 0, 300)
    assert np.array_equal(noise_block(key, 123, 40), whole[123:163])
    assert whole.shape == (300, CHANNELS)
    assert [standard_normal(key, 6 * 7 + c) for c in range(CHANNELS)] == whole[7].tolist()
    assert list(normal_pair(key, 3 * 7 + 1)) == whole[7, 2:4].tolist()


def test_the_normals_are_standard_and_independent():
    """400 000 samples: moments, the KS statistic, the tail beyond the ziggurat's base layer, correlations."""
    z = np.concatenate([noise_block(np.uint64(k), 0, 10_000) for k in range(1, 8)]).reshape(-1, CHANNELS)
    flat = z.ravel()
    assert abs(flat.mean()) < 5 / np.sqrt(flat.size) and abs(flat.var() - 1) < 0.01
    assert stats.kstest(flat, "norm").pvalue > 1e-3
    tail = np.mean(np.abs(flat) > 3.6541528853610088)  # sampled by the ziggurat's slow path
    assert_allclose(tail, 2 * stats.norm.sf(3.6541528853610088), rtol=0.25)
    corr = np.corrcoef(np.hstack([z[1:], z[:-1]]).T)  # channels with each other and with the step before
    assert np.abs(corr - np.eye(2 * CHANNELS)).max() < 0.015


def test_neighbouring_keys_give_unrelated_streams():
    a, b = noise_block(np.uint64(10), 0, 20_000).ravel(), noise_block(np.uint64(11), 0, 20_000).ravel()
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.02


def test_keys_are_drawn_from_the_generator():
    rng1, rng2 = np.random.default_rng(3), np.random.default_rng(3)
    k1, k2 = draw_noise_key(rng1), draw_noise_key(rng2)
    assert k1 == k2 and k1.dtype == np.uint64 and draw_noise_key(rng1) != k1


def test_the_single_env_observes_through_its_keys_noise():
    """The observed attitude error ("hold": minus the measured attitude) is the true one minus
    std * standard_normal(key, 6 k + c)."""
    env = HeliAttitudeEnv(obs_noise=(0.01, 0.0))
    obs, info = env.reset(seed=5)
    z = noise_block(env._noise_key, 0, 1)[0]
    assert_allclose(obs[:3], np.radians(info["attitude_error_deg"]) - 0.01 * z[:3], rtol=0, atol=1e-6)


@pytest.mark.parametrize("seed", [0, 1])
def test_vector_copies_draw_the_single_envs_keys(seed):
    venv = HeliAttitudeVectorEnv(3)
    venv.reset(seed=seed)
    for i in range(3):
        single = HeliAttitudeEnv()
        single.reset(seed=seed + i)
        assert venv._key[i] == single._noise_key
