"""Tests of the native vector environment (:class:`heli_env.vector_env.HeliAttitudeVectorEnv`): its
autoresets and masked resets, seeds, spaces, bad input, threads, compiled-loop cache and pinned episodes.

That it reproduces single environments bit for bit in each task and configuration is
``tests/test_vector_env_matches_single_envs.py``.
"""

from __future__ import annotations

import hashlib

import gymnasium
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space
from numpy.testing import assert_allclose
from vector_side_by_side import random_actions

import heli_env  # noqa: F401  (registers HeliAttitude-v0)
from heli_env import ActionError, HeliAttitudeEnv
from heli_env.vector_env import HeliAttitudeVectorEnv

ENV_ID = "HeliAttitude-v0"


def test_autoreset_is_next_step():
    venv = HeliAttitudeVectorEnv(2, episode_seconds=0.05)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    venv.reset(seed=0)
    zero = np.zeros((2, 3), np.float32)
    for _ in range(4):
        _, rew, term, trunc, _ = venv.step(zero)
        assert not (term.any() or trunc.any())
    obs, rew, term, trunc, info = venv.step(zero)
    assert trunc.all() and not term.any()
    assert np.all(rew != 0.0)
    obs, rew, term, trunc, info = venv.step(np.ones((2, 3), np.float32))  # ignored: the copies reset
    assert np.all(rew == 0.0) and not (term.any() or trunc.any())
    assert np.all(info["time"] == 0.0)
    assert np.all(obs[:, 9:12] == 0.0)  # no previous action after a reset
    single = HeliAttitudeEnv(episode_seconds=0.05)
    single.reset(seed=0)
    for _ in range(5):
        single.step(np.zeros(3, np.float32))
    assert np.array_equal(obs[0], single.reset()[0])  # the reset observation of copy 0's next episode


def test_reset_mask_resets_only_the_masked_copies():
    venv = HeliAttitudeVectorEnv(4)
    venv.reset(seed=0)
    for _ in range(30):
        venv.step(np.full((4, 3), 0.2, np.float32))
    x_before = np.array(venv._x)
    mask = np.array([True, False, True, False])
    obs, info = venv.reset(options={"reset_mask": mask})
    x_after = np.array(venv._x)
    assert np.array_equal(x_after[:, ~mask], x_before[:, ~mask])
    assert not np.any(np.all(x_after[:, mask] == x_before[:, mask], axis=0))
    assert_allclose(info["time"], [0.0, 0.3, 0.0, 0.3])
    assert np.all(obs[mask, 9:12] == 0.0) and np.all(obs[~mask, 9:12] == np.float32(0.2))
    # the reset copies carry on their own random streams (episodes and sensor noise): copy 2 now runs the
    # episode a single env seeded 2 runs after the same 30 steps
    single = HeliAttitudeEnv()
    single.reset(seed=2)
    for _ in range(30):
        single.step(np.full(3, 0.2, np.float32))
    single.reset()
    assert np.array_equal(np.array(single._x), x_after[:, 2])


def test_a_masked_reset_of_an_ended_copy_replaces_its_autoreset():
    """Copies 0 and 1 end their episodes on one step; a masked reset of copy 0 starts its next episode now, so
    the next step steps it (time dt, a reward) while copy 1 is autoreset there (time 0, reward 0)."""
    venv = HeliAttitudeVectorEnv(3, episode_seconds=0.5)
    venv.reset(seed=0)
    for _ in range(50):  # a 0.5 s episode: all three end on the 50th step
        _, _, terminated, truncated, _ = venv.step(np.zeros((3, 3), np.float32))
    assert np.all(terminated | truncated)
    venv.reset(options={"reset_mask": np.array([True, False, False])})
    _, reward, terminated, truncated, info = venv.step(np.zeros((3, 3), np.float32))
    assert_allclose(info["time"], [0.01, 0.0, 0.0])
    assert reward[0] != 0.0 and reward[1] == 0.0 and reward[2] == 0.0
    assert not np.any(terminated | truncated)
    _, reward, _, _, info = venv.step(np.zeros((3, 3), np.float32))
    assert_allclose(info["time"], [0.02, 0.01, 0.01])


def test_reset_mask_errors():
    venv = HeliAttitudeVectorEnv(3)
    with pytest.raises(ResetNeeded, match="first reset must reset every copy"):
        venv.reset(seed=0, options={"reset_mask": np.array([True, False, True])})
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"reset_mask must have shape \(3,\)"):
        venv.reset(options={"reset_mask": np.array([True, False])})


def test_seed_list_and_options_apply_per_reset():
    venv = HeliAttitudeVectorEnv(3)
    _, info = venv.reset(seed=[5, 6, 7], options={"trace": 1, "gusts": False})
    assert np.all(info["trace"] == 1)
    assert np.all(info["disturbance"] == 0.0)
    same = HeliAttitudeVectorEnv(3)
    same.reset(seed=5, options={"trace": 1, "gusts": False})
    assert np.array_equal(np.array(venv._x), np.array(same._x))
    with pytest.raises(ValueError, match="seed must be an int or 3 seeds"):
        venv.reset(seed=[1, 2])
    with pytest.raises(ValueError, match=r"options\['trace'\] must be a trace index"):
        venv.reset(seed=0, options={"trace": 5})
    with pytest.raises(ValueError, match=r"options\['gust_scale'\] must be a number in \[0, 100\]"):
        venv.reset(seed=0, options={"gust_scale": -1.0})


def test_spaces_are_batched_single_spaces():
    venv = HeliAttitudeVectorEnv(5)
    single = HeliAttitudeEnv()
    assert venv.single_observation_space == single.observation_space
    assert venv.single_action_space == single.action_space
    assert venv.observation_space == batch_space(single.observation_space, 5)
    assert venv.action_space == batch_space(single.action_space, 5)
    obs, _ = venv.reset(seed=0)
    assert obs.dtype == np.float32 and obs in venv.observation_space
    for _ in range(50):
        obs, *_ = venv.step(venv.action_space.sample())
        assert obs in venv.observation_space


@pytest.mark.parametrize("shape", [(3,), (4, 2), (5, 3), (4, 3, 1)])
def test_actions_of_wrong_shape_raise(shape):
    venv = HeliAttitudeVectorEnv(4)
    venv.reset(seed=0)
    with pytest.raises(ActionError, match=r"actions must have shape \(4, 3\)"):
        venv.step(np.zeros(shape, np.float32))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_actions_raise_naming_the_copy(bad):
    venv = HeliAttitudeVectorEnv(4)
    venv.reset(seed=0)
    actions = np.zeros((4, 3), np.float32)
    actions[2, 1] = bad
    with pytest.raises(ActionError, match="actions must be finite; copy 2"):
        venv.step(actions)


@pytest.mark.parametrize("bad", [np.full((4, 3), 0.1 + 0.2j), [["a", 0, 0]] * 4, "abc"])
def test_actions_that_are_not_real_numbers_raise_and_change_nothing(bad):
    venv = HeliAttitudeVectorEnv(4)
    obs, _ = venv.reset(seed=0)
    with pytest.raises(ActionError, match="actions must be real numbers"):  # no imaginary part silently dropped
        venv.step(bad)
    again, *_ = venv.step(np.zeros((4, 3), np.float32))
    ref = HeliAttitudeVectorEnv(4)
    ref.reset(seed=0)
    assert np.array_equal(again, ref.step(np.zeros((4, 3), np.float32))[0])


def test_step_before_reset_raises():
    with pytest.raises(ResetNeeded, match=r"call reset\(\) before step\(\)"):
        HeliAttitudeVectorEnv(2).step(np.zeros((2, 3), np.float32))


def test_bad_num_envs_and_render_mode_raise():
    with pytest.raises(ValueError, match="num_envs must be a positive whole number"):
        HeliAttitudeVectorEnv(0)
    with pytest.raises(ValueError, match="render_mode must be 'rgb_array' or None"):
        HeliAttitudeVectorEnv(2, render_mode="human")
    with pytest.raises(ValueError, match="task must be one of"):
        HeliAttitudeVectorEnv(2, task="hover")


def test_make_vec_passes_arguments_through():
    envs = gymnasium.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point", task="rate",
                              episode_seconds=1.0)
    venv = envs.unwrapped
    assert isinstance(venv, HeliAttitudeVectorEnv)
    assert venv.spec_.task.task == "rate" and venv.spec_.episode_steps == 100
    envs.close()


def test_vector_render_shows_copy_zero():
    venv = HeliAttitudeVectorEnv(3, task="track", render_mode="rgb_array")
    venv.reset(seed=0)
    for _ in range(20):
        venv.step(np.zeros((3, 3), np.float32))
    frame = venv.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    single = HeliAttitudeEnv(task="track", render_mode="rgb_array")
    single.reset(seed=0)
    for _ in range(20):
        single.step(np.zeros(3, np.float32))
    assert np.array_equal(frame, single.render())
    venv.close()


def test_thread_count_does_not_change_results():
    """The copies are split among numba's threads; one thread and all threads give identical episodes."""
    import numba

    most = numba.config.NUMBA_NUM_THREADS
    runs = []
    for threads in sorted({1, most}):
        venv = HeliAttitudeVectorEnv(64, task="track", episode_seconds=1.0, threads=threads)
        obs, _ = venv.reset(seed=3)
        trail = [obs]
        for actions in random_actions(150, 64, seed=4):
            obs, rew, term, trunc, info = venv.step(actions)
            trail += [obs, rew, term, trunc, info["attitude_error_deg"], info["disturbance"]]
        runs.append((np.array(venv._x), trail))
    x0, trail0 = runs[0]
    for x, trail in runs[1:]:
        assert np.array_equal(x, x0)
        assert all(np.array_equal(a, b) for a, b in zip(trail, trail0))


def test_copies_of_every_chunk_step_as_their_own_env():
    """The loop takes CHUNK copies at a time, on one thread or the pool, switching between them from step to
    step as the measured default does: copies in the first, a middle and the last chunk equal lone copies."""
    import numba

    from heli_env.kernels import CHUNK

    n = 2 * CHUNK + 5
    most = numba.config.NUMBA_NUM_THREADS
    big = HeliAttitudeVectorEnv(n, task="track", episode_seconds=0.5, threads=most)  # the thread test's loops
    picks = [0, CHUNK + 1, n - 1]
    lone = [HeliAttitudeVectorEnv(1, task="track", episode_seconds=0.5, threads=1) for _ in picks]
    big.reset(seed=11)
    for env, i in zip(lone, picks):
        env.reset(seed=11 + i)
    for k, actions in enumerate(random_actions(80, n, seed=3)):
        big._thread_choice.parallel = most > 1 and k % 3 != 0  # the pool's loop and the one-thread loop in turn
        obs, rew, term, trunc, info = big.step(actions)
        for env, i in zip(lone, picks):
            o, r, te, tr, inf = env.step(actions[i:i + 1])
            assert np.array_equal(obs[i], o[0]) and rew[i] == r[0] and term[i] == te[0] and trunc[i] == tr[0]
            assert np.array_equal(info["disturbance"][i], inf["disturbance"][0])
            assert np.array_equal(big._x[:, i], env._x[:, 0])


@pytest.mark.parametrize("threads", [0, 1.5, 10_000])
def test_bad_thread_count_raises(threads):
    with pytest.raises(ValueError, match="threads must be a whole number from 1 to"):
        HeliAttitudeVectorEnv(2, threads=threads)


def test_returned_arrays_are_not_overwritten_by_the_next_step():
    """Observations and infos are fresh arrays each step: keeping them (as a replay buffer does) is safe."""
    venv = HeliAttitudeVectorEnv(4)
    obs, _ = venv.reset(seed=0)
    kept_obs, kept = obs.copy(), []
    first = venv.step(np.zeros((4, 3), np.float32))
    kept = [first[0].copy(), first[4]["disturbance"].copy(), first[4]["attitude_error_deg"].copy(), first[1].copy()]
    for _ in range(5):
        venv.step(np.full((4, 3), 0.5, np.float32))
    assert np.array_equal(obs, kept_obs)
    assert np.array_equal(first[0], kept[0]) and np.array_equal(first[1], kept[3])
    assert np.array_equal(first[4]["disturbance"], kept[1])
    assert np.array_equal(first[4]["attitude_error_deg"], kept[2])


def _tiny_loop(marker: float):
    from heli_env.kernel_modules import compile_function

    return compile_function(["def tiny(x):", "    for i in prange(x.shape[0]):", f"        x[i] = x[i] * {marker!r}"],
                    "tiny", "test")


def test_compiled_loops_are_kept_in_the_cache_folder(tmp_path, monkeypatch):
    """A generated loop is written once, as a module named by its source, and reused by the next process."""
    monkeypatch.setenv("HELI_ENV_CACHE_DIR", str(tmp_path / "kernels"))
    loop = _tiny_loop(2.5)
    x = np.ones(4)
    loop(x)
    assert np.array_equal(x, np.full(4, 2.5))
    modules = list((tmp_path / "kernels").glob("tiny_*.py"))
    assert len(modules) == 1 and "prange" in modules[0].read_text()
    stamp = modules[0].stat().st_mtime_ns
    _tiny_loop(2.5)
    assert modules[0].stat().st_mtime_ns == stamp  # not rewritten


def test_an_unwritable_cache_folder_compiles_in_memory(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("HELI_ENV_CACHE_DIR", str(blocker / "kernels"))
    x = np.ones(3)
    _tiny_loop(-1.5)(x)
    assert np.array_equal(x, np.full(3, -1.5))


@pytest.mark.parametrize("convert", [lambda a: a.tolist(), lambda a: a.astype(np.float16), lambda a: a.astype(np.int64),
                                     lambda a: np.asfortranarray(a.astype(np.float64))],
                         ids=["list", "float16", "int64", "fortran-float64"])
def test_actions_of_any_numeric_kind_step_alike(convert):
    a = np.array([[1.0, -1.0, 0.0], [0.0, 2.0, -3.0]], dtype=np.float32)
    runs = []
    for actions in (a, convert(a)):
        venv = HeliAttitudeVectorEnv(2)
        venv.reset(seed=5)
        runs.append(venv.step(actions)[0])
    assert np.array_equal(runs[0], runs[1])


@pytest.mark.parametrize("delay", [0, 2])
def test_a_rejected_action_changes_nothing(delay):
    """After an ActionError the env goes on exactly as one that never saw the bad actions."""
    clean, hit = HeliAttitudeVectorEnv(3, action_delay=delay), HeliAttitudeVectorEnv(3, action_delay=delay)
    clean.reset(seed=1)
    hit.reset(seed=1)
    actions = random_actions(6, 3, seed=2)
    bad = actions[0].copy()
    bad[2, 1] = np.nan
    for k, a in enumerate(actions):
        if k == 3:
            with pytest.raises(ActionError, match="copy 2"):
                hit.step(bad)
        want, got = clean.step(a), hit.step(a)
        assert np.array_equal(want[0], got[0]) and np.array_equal(want[1], got[1])
    assert np.array_equal(np.array(clean._x), np.array(hit._x))


def test_default_thread_count_follows_the_batch_size(monkeypatch):
    """One thread below THREADED_FROM copies (the pool is never compiled in); measured from there."""
    import numba

    from heli_env.threads import THREADED_FROM

    monkeypatch.delenv("HELI_NUM_THREADS", raising=False)
    small = HeliAttitudeVectorEnv(8)
    assert small._thread_choice.threads == 1 and small._step_pool is None
    most = numba.config.NUMBA_NUM_THREADS
    big = HeliAttitudeVectorEnv(THREADED_FROM)
    assert big._thread_choice.measured == (most > 1)
    fixed = HeliAttitudeVectorEnv(8, threads=most)
    assert fixed._thread_choice.threads == most and not fixed._thread_choice.measured
    monkeypatch.setenv("HELI_NUM_THREADS", "1")
    assert HeliAttitudeVectorEnv(THREADED_FROM)._step_pool is None


def test_a_masked_reset_leaves_the_other_copies_alone():
    """Resetting copy 0 alone neither changes copy 1's observation nor spends its sensor noise: copy 1 goes on
    exactly as the single env of its seed."""
    venv = HeliAttitudeVectorEnv(2, episode_seconds=5.0)  # the shipped model's sensors
    single = HeliAttitudeEnv(episode_seconds=5.0)
    obs, _ = venv.reset(seed=[4, 9])
    s_obs, _ = single.reset(seed=9)
    actions = np.random.default_rng(2).uniform(-0.2, 0.2, (40, 3)).astype(np.float32)
    for k, a in enumerate(actions):
        if k == 20:
            before = obs[1].copy()
            obs, _ = venv.reset(options={"reset_mask": np.array([True, False])})
            assert_allclose(obs[1], before, rtol=0, atol=0)
        obs, *_ = venv.step(np.stack([a, a]))
        s_obs, *_ = single.step(a)
        assert_allclose(obs[1], s_obs, rtol=1e-12, atol=1e-12)


def _episode_digest(task):
    n = 16
    venv = HeliAttitudeVectorEnv(n, task=task, episode_seconds=1.0, threads=1)
    obs, _ = venv.reset(seed=21)
    rng = np.random.default_rng(22)
    digest = hashlib.sha256(obs.tobytes())
    for _ in range(250):  # four episodes a copy, random sticks beyond the limits, terminations among them
        obs, _, terminated, truncated, _ = venv.step(rng.uniform(-1.2, 1.2, (n, 3)).astype(np.float32))
        for part in (obs, terminated, truncated, np.ascontiguousarray(venv._x)):
            digest.update(part.tobytes())
    return digest.hexdigest()


@pytest.mark.parametrize("task, expected", [
    ("hold", "c8cbaefef013eced1ac76ede316364fbf9d8288ef96eb830ea12108a52547e8a"),
    ("track", "cecf6fa127a9a15e78bf8ae730bb8abc0374c40286081761b1f0c4cc046d4f21"),
])
def test_same_seed_same_episode_as_before_the_fused_step(task, expected):
    """States, float32 observations and episode ends bit for bit as the vector env of 74f3d69 (numpy's
    arctan2, separate loops) gave them: a faster step must not change an episode. A change of the shipped
    model or library changes these digests too."""
    assert _episode_digest(task) == expected


def test_a_reset_writes_the_state_action_and_gust_rows_in_one_block():
    """A reset writes rows x0 .. gust of the block layout as one run of rows (heli_env.restarts.Starts): they
    must be the state, the action and the gust scale, in that order and with nothing between them."""
    from heli_env.kernels import R
    from heli_env.restarts import START_ROWS

    names = [f"x{i}" for i in range(10)] + [f"act{i}" for i in range(3)] + ["gust"]
    assert [R[name] for name in names] == list(range(R["x0"], R["x0"] + START_ROWS))


def test_every_profile_variant_changes_the_step_it_is_timed_against():
    """scripts/env_profile.py attributes a step's time to its parts by removing one at a time: each variant
    must change the generated step (a pattern that no longer matches would time the full step under another
    name) and stay a function Python can compile. Nothing is compiled by numba here."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "env_profile.py"
    spec = importlib.util.spec_from_file_location("env_profile", path)
    profile = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(profile)
    lines = profile.step_lines(HeliAttitudeVectorEnv(4))
    for name, variant in profile.VARIANTS.items():
        changed = variant(lines)
        assert changed != lines, name
        compile("\n".join(changed) + "\n", name, "exec")


@pytest.mark.parametrize("options, seed", [({}, None), ({"trace": 1, "offset": 17}, None), ({"gust_scale": 0.5}, None),
                                           ({}, 40)], ids=["plain", "pinned-trace", "gust-scale", "new-seed"])
def test_a_reset_after_episodes_were_drawn_ahead_is_the_reset_of_a_single_env(options, seed):
    """A step draws each copy's next episode ahead (heli_env.restarts). A masked reset afterwards starts the
    episode a single env's reset would: the one drawn ahead when its options are the defaults, one drawn from
    the generator's state before that draw when they are not (the options change the draws), one from the new
    generator with a new seed; and the copies' later episodes follow on."""
    kwargs = {"episode_seconds": 0.3}  # the shipped model's sensors: noise and gyro lines, phases drawn per episode
    venv = HeliAttitudeVectorEnv(3, **kwargs)
    venv.reset(seed=10)
    single = HeliAttitudeEnv(**kwargs)
    single.reset(seed=11)
    zero = np.zeros(3, np.float32)
    for _ in range(5):
        venv.step(np.zeros((3, 3), np.float32))
        single.step(zero)
    assert venv._ahead.ready.all()  # every copy's next episode is drawn
    obs, _ = venv.reset(seed=None if seed is None else [0, seed + 1, 0],
                        options={**options, "reset_mask": np.array([False, True, False])})
    s_obs, _ = single.reset(seed=None if seed is None else seed + 1, options=options)
    assert np.array_equal(obs[1], s_obs) and np.array_equal(np.array(venv._x)[:, 1], np.array(single._x))
    venv.reset(options={"reset_mask": np.array([True, False, True])})  # the others use theirs: a batch is due
    done, ready = False, []
    for _ in range(70):  # two more episodes, autoreset from draws ahead
        obs, reward, *_ = venv.step(np.zeros((3, 3), np.float32))
        ready.append(venv._ahead.ready.copy())
        if done:  # the vector env's next step starts the next episode (NEXT_STEP autoreset)
            (s_obs, _), s_reward, done = single.reset(), 0.0, False
        else:
            s_obs, s_reward, terminated, truncated, _ = single.step(zero)
            done = terminated or truncated
        assert np.array_equal(obs[1], s_obs)
        assert_allclose(reward[1], s_reward, rtol=1e-12, atol=1e-12)  # (the rewards' sums are compiled apart)
    ready = np.array(ready)
    if options:  # a copy reset with options is not drawn ahead (its draw would be put back) until a plain reset
        assert not ready[:25, 1].any() and ready[30:, 1].any()


def test_a_deep_copy_draws_from_its_own_generators_and_outlives_the_original():
    """The compiled draws read each copy's generator at its state's address (heli_env.generator_draws): a deep
    copy of the env (as a user's snapshot makes) must read its own generators, step as the original would, and
    keep working once the original is gone."""
    import copy
    import gc

    kwargs = {"episode_seconds": 0.2}
    venv = HeliAttitudeVectorEnv(3, **kwargs)
    venv.reset(seed=4)
    actions = np.zeros((3, 3))
    for _ in range(5):
        venv.step(actions)
    twin = copy.deepcopy(venv)
    expected = [venv.step(actions)[0] for _ in range(60)]  # three more episodes each, drawn by the original
    del venv
    gc.collect()
    for obs in expected:
        assert np.array_equal(twin.step(actions)[0], obs)
