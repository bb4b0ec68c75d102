"""Tests of the SB3 ``VecEnv`` adapter over the native vector env (:mod:`controllers.rl.vec_env`).

SB3 expects a same-step reset: the step that ends an episode returns ``done``,
the first observation of the next episode, and the last observation in
``infos[i]["terminal_observation"]``; ``TimeLimit.truncated`` tells time limits
from failures. The native env resets on the *next* step instead; these tests
hold the adapter against it step by step.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

pytest.importorskip("stable_baselines3")

from controllers.rl.vec_env import GymnasiumVecEnv  # noqa: E402
from controllers.trace_split import TraceSegment, WindowSampler  # noqa: E402
from heli_env.vector_env import HeliAttitudeVectorEnv  # noqa: E402


def _pair(shipped, n=3, seconds=0.05, **kw):
    return (GymnasiumVecEnv(HeliAttitudeVectorEnv(n, model=shipped, episode_seconds=seconds), **kw),
            HeliAttitudeVectorEnv(n, model=shipped, episode_seconds=seconds))


def test_same_step_reset_and_terminal_observation_against_native_env(shipped):
    adapter, native = _pair(shipped)
    adapter.seed(7)
    obs = adapter.reset()
    n_obs, _ = native.reset(seed=7)
    assert_array_equal(obs, n_obs)
    rng = np.random.default_rng(0)
    for k in range(1, 6):  # episodes of 5 steps
        a = rng.uniform(-0.3, 0.3, (3, 3)).astype(np.float32)
        obs, rew, done, infos = adapter.step(a)
        n_obs, n_rew, n_term, n_trunc, _ = native.step(a)
        assert_array_equal(rew, n_rew.astype(np.float32))
        if k < 5:
            assert not done.any()
            assert_array_equal(obs, n_obs)
            assert all("terminal_observation" not in d and d["TimeLimit.truncated"] is False for d in infos)
    assert done.all() and n_trunc.all()
    for i, d in enumerate(infos):
        assert_array_equal(d["terminal_observation"], n_obs[i])  # the native env's last observation
        assert d["TimeLimit.truncated"] is True
        assert d["time"] == pytest.approx(0.05)
    # the native env resets on its next step (reward 0, action ignored); the adapter already has
    n_obs, n_rew, n_term, n_trunc, _ = native.step(np.zeros((3, 3)))
    assert_array_equal(n_rew, 0.0)
    assert_array_equal(obs, n_obs)
    assert all(d["time"] == 0.0 for d in adapter.reset_infos)
    # and the next episode runs on: no step is lost to the reset
    obs, rew, done, infos = adapter.step(np.zeros((3, 3), np.float32))
    assert not done.any() and np.all(rew != 0.0)
    assert all(d["time"] == pytest.approx(0.01) for d in infos)


def test_failure_is_not_a_time_limit(shipped):
    adapter, _ = _pair(shipped, n=2, seconds=20.0)
    adapter.seed(0)
    adapter.reset()
    full_roll = np.tile(np.array([1.0, 0.0, 0.0], np.float32), (2, 1))
    ended = {}
    for _ in range(1500):
        obs, rew, done, infos = adapter.step(full_roll)
        for i in np.flatnonzero(done):
            ended.setdefault(int(i), (infos[i], obs[i]))
        if len(ended) == 2:
            break
    assert sorted(ended) == [0, 1]  # both copies roll past 60 degrees at full stick
    for info, first_obs in ended.values():
        assert info["TimeLimit.truncated"] is False
        assert abs(info["terminal_observation"][0]) > np.radians(60.0)
        assert abs(first_obs[0]) < np.radians(10.0)  # the new episode starts near level

def test_episode_options_pin_training_segments_and_are_seeded(shipped):
    seg = (TraceSegment(1, 0.0, 0.5),)
    runs = []
    for _ in range(2):
        sampler = WindowSampler(shipped, seg, needed=11)
        adapter, _ = _pair(shipped, n=4, seconds=0.1, episode_options=sampler)
        adapter.seed(3)
        first = adapter.reset()
        infos_seen = list(adapter.reset_infos)
        steps = [first]
        for _ in range(25):
            obs, _, done, infos = adapter.step(np.zeros((4, 3), np.float32))
            steps.append(obs)
            infos_seen += [adapter.reset_infos[i] for i in np.flatnonzero(done)]
        assert {d["trace"] for d in infos_seen} == {1}
        runs.append(np.array(steps))
    assert_array_equal(runs[0], runs[1])


def test_fixed_seed_replays_the_same_episodes(shipped):
    adapter, _ = _pair(shipped, n=2, fixed_seed=11,
                       episode_options=WindowSampler(shipped, (TraceSegment(0),), needed=6))
    a = adapter.reset()
    adapter.step(np.zeros((2, 3), np.float32))
    b = adapter.reset()
    assert_array_equal(a, b)


def test_rejects_same_step_autoreset():
    from gymnasium.vector import AutoresetMode

    class Fake:
        metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}

    with pytest.raises(ValueError, match="NEXT_STEP"):
        GymnasiumVecEnv(Fake())


# --------------------------------------------------------------------------------------------- twins
def _twins(shipped, n=4, seconds=0.3):
    sampler = WindowSampler(shipped, (TraceSegment(0), TraceSegment(1)), needed=int(seconds * 100) + 1)
    return GymnasiumVecEnv(HeliAttitudeVectorEnv(n, model=shipped, episode_seconds=seconds), episode_options=sampler,
                           twins=True)


def test_twins_meet_the_same_gusts_starts_and_sensor_noise(shipped):
    """Twin copies given the same actions stay equal bit for bit, through episode ends and restarts."""
    adapter = _twins(shipped)
    adapter.seed(5)
    obs = adapter.reset()
    assert_array_equal(obs[:2], obs[2:])
    assert not np.array_equal(obs[0], obs[1])  # the two pairs differ from each other
    rng = np.random.default_rng(1)
    ends = 0
    for _ in range(100):
        a = rng.uniform(-0.5, 0.5, (2, 3)).astype(np.float32)
        obs, rew, done, infos = adapter.step(np.concatenate([a, a]))
        assert_array_equal(obs[:2], obs[2:])
        assert_array_equal(rew[:2], rew[2:])
        assert_array_equal(done[:2], done[2:])
        ends += int(done[:2].sum())
    assert ends >= 4
    assert [d["trace"] for d in adapter.reset_infos[:2]] == [d["trace"] for d in adapter.reset_infos[2:]]


def test_a_copy_ends_with_its_twin(shipped):
    """A twin that fails (full roll stick) ends its pair: the other copy is truncated, not terminated."""
    adapter = _twins(shipped, n=2, seconds=20.0)
    adapter.seed(0)
    adapter.reset()
    for _ in range(1500):
        obs, rew, done, infos = adapter.step(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]], np.float32))
        if done.any():
            break
    assert done.all()
    assert infos[0]["TimeLimit.truncated"] is False and infos[1]["TimeLimit.truncated"] is True
    assert_array_equal(obs[0], obs[1])  # both restarted together


def test_twins_need_an_even_number_of_copies(shipped):
    with pytest.raises(ValueError, match="even number of copies"):
        GymnasiumVecEnv(HeliAttitudeVectorEnv(3, model=shipped), twins=True)


def test_concatenated_groups_fly_as_one_vecenv(shipped):
    # training on several delays side by side: two groups of copies seen as one VecEnv fly exactly as one
    # VecEnv of all the copies would (each copy seeded seed + its index over the whole), through episode ends
    from controllers.rl.vec_env import ConcatVecEnv

    whole = GymnasiumVecEnv(HeliAttitudeVectorEnv(5, model=shipped, episode_seconds=0.05))
    parts = ConcatVecEnv([GymnasiumVecEnv(HeliAttitudeVectorEnv(n, model=shipped, episode_seconds=0.05))
                          for n in (2, 3)])
    assert parts.num_envs == 5
    whole.seed(11)
    parts.seed(11)
    assert_array_equal(parts.reset(), whole.reset())
    rng = np.random.default_rng(0)
    for _ in range(8):  # one episode end at step 5
        a = rng.uniform(-0.3, 0.3, (5, 3)).astype(np.float32)
        got, want = parts.step(a), whole.step(a)
        for g, w in zip(got[:3], want[:3]):
            assert_array_equal(g, w)
        assert [d["time"] for d in got[3]] == [d["time"] for d in want[3]]
    assert parts.get_attr("num_envs", [1, 3]) == [2, 3]  # each copy answered by its own group
    with pytest.raises(ValueError, match="spaces"):
        ConcatVecEnv([parts, _Boxed(parts)])


class _Boxed:
    """A VecEnv stand-in with another observation space."""

    def __init__(self, env):
        import gymnasium

        self.num_envs, self.action_space = env.num_envs, env.action_space
        self.observation_space = gymnasium.spaces.Box(-1.0, 1.0, (2,))
