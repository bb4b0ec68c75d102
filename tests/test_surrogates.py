"""Phase-randomised surrogate gusts (heli_env.surrogates)."""

from __future__ import annotations

import numpy as np
import pytest

from heli_env import HeliAttitudeEnv
from heli_env.surrogates import phase_randomised, surrogate_model
from heli_env.vector_env import HeliAttitudeVectorEnv


def test_a_surrogate_keeps_the_spectrum_and_the_mean_but_not_the_gust(shipped):
    ud = shipped.ud[:, : int(shipped.lengths[0])]
    sur = phase_randomised(ud, np.random.default_rng(0))
    np.testing.assert_allclose(np.abs(np.fft.rfft(sur, axis=1)), np.abs(np.fft.rfft(ud, axis=1)), rtol=1e-9,
                               atol=1e-9)
    np.testing.assert_allclose(sur.mean(axis=1), ud.mean(axis=1), atol=1e-12)
    np.testing.assert_allclose(sur.std(axis=1), ud.std(axis=1), rtol=1e-9)
    assert abs(np.corrcoef(sur[0], ud[0])[0, 1]) < 0.5  # a new gust (a red spectrum has few degrees of freedom)
    # the axes share their phases: their cross-spectrum keeps its magnitude
    cross = np.fft.rfft(ud[0]) * np.conj(np.fft.rfft(ud[1]))
    cross_s = np.fft.rfft(sur[0]) * np.conj(np.fft.rfft(sur[1]))
    np.testing.assert_allclose(np.abs(cross_s), np.abs(cross), rtol=1e-6, atol=1e-9)


def test_the_surrogate_library_replays_in_both_envs(shipped):
    sur = surrogate_model(shipped, copies=2, seed=5)
    assert sur.n_traces == 2 * shipped.n_traces and sur.trace_ids[1].endswith("~surrogate1")
    np.testing.assert_array_equal(sur.collective[: int(sur.lengths[0])], shipped.collective[: int(shipped.lengths[0])])
    assert not np.allclose(sur.ud[:, :100], shipped.ud[:, :100])
    again = surrogate_model(shipped, copies=2, seed=5)
    np.testing.assert_array_equal(sur.ud, again.ud)  # same seed, same surrogates
    env, venv = HeliAttitudeEnv(model=sur), HeliAttitudeVectorEnv(2, model=sur)
    obs, _ = env.reset(seed=3)
    vobs, _ = venv.reset(seed=3)
    np.testing.assert_array_equal(obs, vobs[0])
    for _ in range(50):
        obs, *_ = env.step(np.zeros(3, np.float32))
        vobs, *_ = venv.step(np.zeros((2, 3), np.float32))
    np.testing.assert_allclose(obs, vobs[0], rtol=1e-6, atol=1e-7)
    with pytest.raises(ValueError, match="copies"):
        surrogate_model(shipped, copies=0)
