"""Tests of the single environment ``HeliAttitude-v0`` (:class:`heli_env.env.HeliAttitudeEnv`).

A session fixture writes a model directory the way a user does: ``heli
simulate-flight --duration 60`` then ``heli identify --no-plots`` (one trace of
60 s in its library). Other tests use the model that ships with the package
(three traces of 200 s). Episodes are short where the test allows.
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from numpy.testing import assert_allclose

import heli_env
from heli_cli.main import main
from heli_core.physics import step, trim_sticks
from heli_core.quaternion import euler_from_quaternion
from heli_env import ActionError, EnvModelError, HeliAttitudeEnv, default_model_dir, load_env_model
from heli_env.env_model import as_env_model
from heli_env.spec import build_spec
from heli_env.tasks import N_SINES, TWO_PI, TaskConfig, draw_episodes, reference_bounds
from heli_env.vector_env import HeliAttitudeVectorEnv
from identification.bench.flight_config import EFFECTS
from model_store.disturbance_library import DisturbanceLibrary

ENV_ID = "HeliAttitude-v0"
TASKS = ("hold", "track", "rate")
HUMAN_NO_DISPLAY = "render_mode='human' without an interactive matplotlib backend"


@pytest.fixture(scope="session")
def model_dir(tmp_path_factory):
    """``heli simulate-flight --duration 60`` then ``heli identify --no-plots``: a model directory."""
    folder = tmp_path_factory.mktemp("heli_model")
    csv = folder / "flight.csv"
    assert main(["simulate-flight", "--duration", "60", "--seed", "11", "--out", str(csv)]) == 0
    out = folder / "model"
    assert main(["identify", str(csv), "--out", str(out), "--no-plots"]) == 0
    return out


@pytest.fixture(scope="module")
def default_model():
    return load_env_model()


def _attitude(env):
    """True (roll, pitch, yaw) [rad] of a single env's state."""
    return euler_from_quaternion(np.array(env.unwrapped._x[6:10]))


def _rollout(env, actions, seed=None, options=None):
    """Reset then step through ``actions`` (stops at the episode's end); returns obs, rewards, infos, flags, states."""
    obs, info = env.reset(seed=seed, options=options)
    out = {"obs": [obs], "rew": [], "info": [info], "term": [], "trunc": [], "x": [env.unwrapped._x]}
    for a in actions:
        obs, r, te, tr, info = env.step(a)
        for key, v in zip(("obs", "rew", "info", "term", "trunc", "x"), (obs, r, info, te, tr, env.unwrapped._x)):
            out[key].append(v)
        if te or tr:
            break
    return out


def _zero_action_episode(env, seed=0, options=None):
    """Max |roll|, |pitch| [deg], steps and flags of an episode with zero action from trim."""
    env.reset(seed=seed, options=options)
    zero = np.zeros(3, dtype=np.float32)
    worst, n = 0.0, 0
    while True:
        _, _, te, tr, _ = env.step(zero)
        n += 1
        worst = max(worst, float(np.max(np.abs(np.degrees(_attitude(env)[:2])))))
        if te or tr:
            return worst, n, te, tr


def _random_actions(n, seed=0, scale=0.5):
    return np.random.default_rng(seed).uniform(-scale, scale, (n, 3)).astype(np.float32)


# ------------------------------------------------------------------------------------------ registration


def test_import_registers_the_env_and_its_vector_entry_point():
    spec = gymnasium.spec(ENV_ID)
    assert heli_env.ENV_ID == ENV_ID
    assert spec.entry_point == "heli_env.env:HeliAttitudeEnv"
    assert spec.vector_entry_point == "heli_env.vector_env:HeliAttitudeVectorEnv"


def test_make_without_model_uses_the_shipped_model():
    env = gymnasium.make(ENV_ID)
    assert isinstance(env.unwrapped, HeliAttitudeEnv)
    assert env.unwrapped.model.path == default_model_dir()
    assert (default_model_dir() / "model.json").is_file()
    assert env.unwrapped.model.n_traces == 3
    obs, _ = env.reset(seed=0)
    assert obs in env.observation_space
    env.close()


def test_make_with_a_heli_identify_directory(model_dir):
    env = gymnasium.make(ENV_ID, model=model_dir)
    model = env.unwrapped.model
    assert model.path == model_dir
    library = DisturbanceLibrary.open(model_dir)
    traces = library.load(library.latest_version)
    assert model.n_traces == len(traces) == 1
    assert model.lengths.tolist() == [6001]  # 60 s at 100 Hz
    assert_allclose(model.ud, traces[0].ud, rtol=0, atol=0)
    obs, info = env.reset(seed=1)
    assert info["trace_id"] == model.trace_ids[0]
    for a in _random_actions(100):
        obs, *_ = env.step(a)
        assert obs in env.observation_space
    # model.json itself is accepted too
    assert gymnasium.make(ENV_ID, model=model_dir / "model.json").unwrapped.model.path == model_dir


def test_make_vec_returns_the_native_vector_env():
    envs = gymnasium.make_vec(ENV_ID, num_envs=8, vectorization_mode="vector_entry_point")
    assert isinstance(envs.unwrapped, HeliAttitudeVectorEnv)
    assert envs.num_envs == 8
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (8, 12)
    envs.close()


# ------------------------------------------------------------------------------------------ env checkers


@pytest.mark.parametrize("task", TASKS)
def test_gymnasium_env_checker_passes(task):
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make(ENV_ID, task=task)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)  # also renders each render mode through the registered spec
    env.close()
    unexpected = [str(w.message) for w in caught if HUMAN_NO_DISPLAY not in str(w.message)]
    assert unexpected == []


@pytest.mark.parametrize("task", TASKS)
def test_sb3_env_checker_passes(task):
    from stable_baselines3.common.env_checker import check_env

    env = gymnasium.make(ENV_ID, task=task)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # SB3 warns on anything it dislikes (spaces, dtypes, bounds)
        check_env(env.unwrapped, warn=True)
    env.close()


def test_a_tiny_sb3_training_run():
    from stable_baselines3 import PPO

    env = gymnasium.make(ENV_ID, episode_seconds=1.0)
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=128)
    action, _ = model.predict(env.reset(seed=0)[0], deterministic=True)
    assert action.shape == (3,) and np.all(np.abs(action) <= 1.0)


# ------------------------------------------------------------------------------------------ determinism


@pytest.mark.parametrize("task", TASKS)
def test_same_seed_gives_identical_trajectories(task):
    actions = _random_actions(300, seed=4)
    runs = [_rollout(HeliAttitudeEnv(task=task, episode_seconds=3.0), actions, seed=123) for _ in range(2)]
    a, b = runs
    assert len(a["rew"]) == len(b["rew"]) == 300
    for key in ("obs", "rew", "x", "term", "trunc"):
        assert np.array_equal(np.array(a[key]), np.array(b[key])), key
    for ia, ib in zip(a["info"], b["info"]):
        assert ia.keys() == ib.keys()
        for k in ia:
            assert np.array_equal(ia[k], ib[k]), k


def test_unseeded_resets_continue_the_seeded_stream():
    envs = [HeliAttitudeEnv(task="track") for _ in range(2)]
    for env in envs:
        env.reset(seed=9)
    second = [env.reset() for env in envs]
    assert np.array_equal(second[0][0], second[1][0])
    assert envs[0]._episode.offset == envs[1]._episode.offset


def test_different_seeds_draw_different_traces_offsets_and_starts():
    env = HeliAttitudeEnv()
    draws, firsts = [], []
    for seed in range(12):
        obs, info = env.reset(seed=seed)
        draws.append((info["trace"], env._episode.offset))
        firsts.append(obs)
    traces = {t for t, _ in draws}
    assert traces == {0, 1, 2}  # 12 draws from 3 traces
    assert len(set(draws)) == len(draws)
    assert len({o.tobytes() for o in firsts}) == len(firsts)


# ------------------------------------------------------------------------------------------ gusts and trim


def test_gusts_off_zero_action_from_a_level_start_stays_level():
    env = HeliAttitudeEnv(init_angle_deg=0.0, init_rate_deg=0.0)
    worst, n, te, tr = _zero_action_episode(env, seed=0, options={"gusts": False})
    assert (n, te, tr) == (3000, False, True)  # the full 30 s
    assert worst < 1e-6


def test_gusts_off_zero_action_with_a_constant_collective_stays_level():
    env = HeliAttitudeEnv(init_angle_deg=0.0, init_rate_deg=0.0, collective=0.3, episode_seconds=5.0)
    worst, n, te, tr = _zero_action_episode(env, seed=2, options={"gusts": False})
    assert (n, te, tr) == (500, False, True)
    assert worst < 1e-6


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gusts_off_zero_action_from_a_random_start_stays_bounded(seed):
    worst, n, te, tr = _zero_action_episode(HeliAttitudeEnv(), seed=seed, options={"gusts": False})
    assert (n, te, tr) == (3000, False, True)
    assert worst < 15.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gusts_make_the_attitude_wander(seed):
    env = HeliAttitudeEnv(init_angle_deg=0.0, init_rate_deg=0.0)
    calm, *_ = _zero_action_episode(env, seed=seed, options={"gusts": False})
    windy, n, te, tr = _zero_action_episode(env, seed=seed)
    assert not te
    assert calm < 1e-6
    assert windy > 3.0  # degrees (9-14° for these seeds)


# ------------------------------------------------------------------------------------------ reset options


def test_options_pin_trace_and_offset_and_info_reports_the_library_gust():
    env = HeliAttitudeEnv(gust_scale=0.5)
    library = DisturbanceLibrary.open(default_model_dir())
    trace = library.load(library.latest_version)[2]
    offset = 1234
    _, info = env.reset(seed=0, options={"trace": 2, "offset": offset})
    assert info["trace"] == 2
    assert info["trace_id"] == trace.metadata["id"]
    assert_allclose(info["disturbance"], 0.5 * trace.ud[:, offset], rtol=1e-15)  # the gust about to act
    for k in range(20):
        _, _, _, _, info = env.step(np.zeros(3, dtype=np.float32))
        assert_allclose(info["disturbance"], 0.5 * trace.ud[:, offset + k], rtol=1e-15)  # the gust just applied
        assert info["time"] == pytest.approx(0.01 * (k + 1), abs=1e-12)


def test_gust_scale_option_scales_the_disturbance_and_overrides_the_constructor():
    infos = {}
    for scale in (1.0, 2.0, 0.0):
        env = HeliAttitudeEnv(gust_scale=0.3)
        run = _rollout(env, np.zeros((50, 3), np.float32), seed=5, options={"gust_scale": scale})
        infos[scale] = np.array([i["disturbance"] for i in run["info"]])
    assert np.abs(infos[1.0]).max() > 0.0
    assert_allclose(infos[2.0], 2.0 * infos[1.0], rtol=1e-15)
    assert np.all(infos[0.0] == 0.0)
    off = _rollout(HeliAttitudeEnv(), np.zeros((50, 3), np.float32), seed=5, options={"gusts": False})
    zero = _rollout(HeliAttitudeEnv(), np.zeros((50, 3), np.float32), seed=5, options={"gust_scale": 0.0})
    assert np.array_equal(np.array(off["x"]), np.array(zero["x"]))


@pytest.mark.parametrize(
    "options, match",
    [
        ({"trace": -1}, r"options\['trace'\] must be a trace index in \[0, 3\)"),
        ({"trace": 3}, r"options\['trace'\] must be a trace index in \[0, 3\)"),
        ({"trace": 0, "offset": -1}, r"options\['offset'\] must be a sample in \[0, 20000\) of trace 0"),
        ({"trace": 0, "offset": 20000}, r"options\['offset'\] must be a sample in \[0, 20000\) of trace 0"),
        ({"gust_scale": -0.5}, r"options\['gust_scale'\] must be a number in \[0, 100\]"),
        ({"gust_scale": float("nan")}, r"options\['gust_scale'\] must be a number in \[0, 100\]"),
        ({"gust_scale": float("inf")}, r"options\['gust_scale'\] must be a number in \[0, 100\]"),
        ({"gust_scale": 1e300}, r"options\['gust_scale'\] must be a number in \[0, 100\], got 1e\+300"),
        ({"gusts": 0}, r"options\['gusts'\] must be True or False, got 0"),
        ({"gusts": "off"}, r"options\['gusts'\] must be True or False, got 'off'"),
        ({"trace": 0.9}, r"options\['trace'\] must be a whole number \(an index\), got 0.9"),
        ({"trace": True}, r"options\['trace'\] must be a whole number"),
        ({"seed": 3}, r"unknown reset option\(s\) \['seed'\]"),
    ],
)
def test_invalid_reset_options_raise(options, match):
    env = HeliAttitudeEnv()
    with pytest.raises(ValueError, match=match):  # OptionError is a ValueError
        env.reset(seed=0, options=options)


@pytest.mark.parametrize("action", ["abc", ["a", 0, 0], [1j, 0, 0], np.array([0.1 + 0.5j, 0, 0]), object()])
def test_an_action_that_is_not_real_numbers_is_an_action_error(action):
    from heli_env.errors import ActionError

    env = HeliAttitudeEnv()
    env.reset(seed=0)
    with pytest.raises(ActionError):
        env.step(action)


# ------------------------------------------------------------------------------------------ episode end


def test_truncation_after_episode_seconds():
    env = HeliAttitudeEnv(episode_seconds=0.5)
    run = _rollout(env, np.zeros((80, 3), np.float32), seed=0)
    assert len(run["rew"]) == 50
    assert run["trunc"] == [False] * 49 + [True]
    assert not any(run["term"])
    assert run["info"][-1]["time"] == pytest.approx(0.5)
    with pytest.raises(ResetNeeded, match="the episode is over"):
        env.step(np.zeros(3, np.float32))
    env.reset()  # and a reset starts the next one
    env.step(np.zeros(3, np.float32))


@pytest.mark.parametrize("dt, steps", [(0.01, 10), (0.02, 5)])
def test_truncation_when_the_trace_runs_out(dt, steps):
    env = HeliAttitudeEnv(dt=dt)
    length = int(env.model.lengths[1])
    run = _rollout(env, np.zeros((50, 3), np.float32), seed=0, options={"trace": 1, "offset": length - 11})
    # the replay ends on the trace's last sample, 10 sample periods after the offset
    assert len(run["rew"]) == steps
    assert run["trunc"] == [False] * (steps - 1) + [True]
    assert run["info"][-1]["time"] == pytest.approx(0.1)
    with pytest.raises(ResetNeeded, match="end of the disturbance trace"):
        env.step(np.zeros(3, np.float32))


@pytest.mark.parametrize("action, axis", [((1.0, 0.0, 0.0), 0), ((-1.0, 0.0, 0.0), 0), ((0.0, 1.0, 0.0), 1)])
def test_termination_beyond_60_degrees(action, axis):
    env = HeliAttitudeEnv(init_angle_deg=0.0, init_rate_deg=0.0)
    run = _rollout(env, np.tile(np.array(action, np.float32), (3000, 1)), seed=0, options={"gusts": False})
    assert run["term"][-1] and not run["trunc"][-1]
    assert not any(run["term"][:-1])
    angle = [abs(i["attitude_error_deg"][axis]) for i in run["info"]]  # hold: -attitude
    assert angle[-1] > 60.0 >= max(angle[:-1])
    assert len(run["rew"]) < 1000  # well before the time limit


# ------------------------------------------------------------------------------------------ actions


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("index", [0, 2])
def test_non_finite_action_raises(bad, index):
    env = gymnasium.make(ENV_ID)
    env.reset(seed=0)
    action = np.zeros(3, dtype=np.float32)
    action[index] = bad
    with pytest.raises(ActionError, match="action must be finite"):
        env.step(action)


@pytest.mark.parametrize("action", [np.zeros(2), np.zeros(4), np.zeros((1, 3)), 0.5, [0.1, 0.2]])
def test_wrong_action_shape_raises(action):
    env = HeliAttitudeEnv()
    env.reset(seed=0)
    with pytest.raises(ActionError, match=r"action must have shape \(3,\)"):
        env.step(action)


def test_actions_of_other_types_are_accepted():
    runs = [_rollout(HeliAttitudeEnv(), [a] * 20, seed=0)
            for a in ([0.5, -0.25, 0.0], np.array([0.5, -0.25, 0.0]), np.array([0.5, -0.25, 0.0], np.float32))]
    assert np.array_equal(np.array(runs[0]["x"]), np.array(runs[1]["x"]))
    assert np.array_equal(np.array(runs[0]["x"]), np.array(runs[2]["x"]))


def test_out_of_range_actions_are_clipped():
    raw = 3.0 * _random_actions(200, seed=1, scale=1.0)
    assert np.abs(raw).max() > 2.0
    a = _rollout(HeliAttitudeEnv(task="track"), raw, seed=3)
    b = _rollout(HeliAttitudeEnv(task="track"), np.clip(raw, -1.0, 1.0), seed=3)
    assert np.array_equal(np.array(a["x"]), np.array(b["x"]))
    assert np.array_equal(np.array(a["obs"]), np.array(b["obs"]))
    assert a["rew"] == b["rew"]
    assert np.abs(np.array(a["obs"])[:, 9:12]).max() == 1.0  # the observed previous action is the clipped one


def test_step_before_reset_raises():
    with pytest.raises(ResetNeeded):
        gymnasium.make(ENV_ID).step(np.zeros(3, np.float32))
    with pytest.raises(ResetNeeded, match=r"call reset\(\) before step\(\)"):
        HeliAttitudeEnv().step(np.zeros(3, np.float32))


# ------------------------------------------------------------------------------------------ model directories


def _break_model_json(d):
    (d / "model.json").write_text('{"schema": "heli-env/model", "parameters": ')


def _break_manifest(d):
    (d / "disturbances" / "manifest-v0001.json").write_text("[not a manifest")


def _trace_file(d):
    (path,) = sorted((d / "disturbances" / "traces").glob("*.npy"))
    return path


def _flip_a_trace_byte(d):
    path = _trace_file(d)
    data = bytearray(path.read_bytes())
    data[-8] ^= 0x01
    path.write_bytes(bytes(data))


@pytest.mark.parametrize(
    "damage, named",
    [
        (lambda d: (d / "model.json").unlink(), "model.json"),
        (_break_model_json, "model.json"),
        (lambda d: shutil.rmtree(d / "disturbances"), "disturbances"),
        (_break_manifest, "manifest-v0001.json"),
        (lambda d: (d / "disturbances" / "manifest-v0001.json").unlink(), "disturbances"),
        (_flip_a_trace_byte, "TRACE"),
        (lambda d: _trace_file(d).unlink(), "TRACE"),
    ],
    ids=["missing-model-json", "corrupt-model-json", "missing-library", "corrupt-manifest", "missing-manifest",
         "trace-checksum", "missing-trace"],
)
def test_a_damaged_model_directory_raises_naming_the_file(model_dir, tmp_path, damage, named):
    d = tmp_path / "model"
    shutil.copytree(model_dir, d)
    if named == "TRACE":
        named = _trace_file(d).name
    damage(d)
    with pytest.raises(EnvModelError, match=named.replace(".", r"\.")):
        HeliAttitudeEnv(model=d)
    with pytest.raises(EnvModelError, match=named.replace(".", r"\.")):
        gymnasium.make(ENV_ID, model=d)


def test_a_missing_model_directory_raises(tmp_path):
    with pytest.raises(EnvModelError, match="does not exist"):
        HeliAttitudeEnv(model=tmp_path / "nowhere")


def test_env_model_error_is_a_value_error():
    assert issubclass(EnvModelError, ValueError) and issubclass(ActionError, ValueError)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"dt": 0.015}, r"dt=0.015 s must be a whole number of the disturbance traces' sample periods"),
        ({"dt": 0.005}, r"must be a whole number of the disturbance traces' sample periods"),
        ({"dt": 0.0}, "dt must be a positive control period"),
        ({"dt": float("nan")}, "dt must be a positive control period"),
        ({"gust_scale": -1.0}, r"gust_scale must be a number in \[0, 100\]"),
        ({"gust_scale": float("inf")}, r"gust_scale must be a number in \[0, 100\]"),
        ({"gust_scale": 1e300}, r"gust_scale must be a number in \[0, 100\]"),
        ({"init_rate_deg": -1.0}, r"init_rate_deg must be a number in \[0, 1000\]"),
        ({"init_angle_deg": "5"}, r"init_angle_deg must be a number in \[0, 90\]"),
        ({"task": "hover"}, r"task must be one of \('hold', 'track', 'rate'\)"),
        ({"task": "track", "reference": "zigzag"}, "reference must be one of"),
        ({"episode_seconds": 0.0}, "episode_seconds must be positive"),
        ({"obs_noise": -0.1}, "obs_noise must be .model., a std"),
        ({"obs_noise": (0.1, 0.2, 0.3)}, "obs_noise must be .model., a std"),
        ({"action_delay": -1}, "action_delay must be a whole number"),
        ({"action_delay": 1.5}, "action_delay must be a whole number"),
        ({"collective": 1.5}, "collective must be 'trace' or a stick value"),
        ({"render_mode": "ascii"}, "render_mode must be one of"),
    ],
)
def test_bad_constructor_arguments_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        HeliAttitudeEnv(**kwargs)


# ------------------------------------------------------------------------------------------ noise and delay


def test_observation_noise_changes_observations_not_the_state():
    actions = _random_actions(400, seed=2)
    clean = _rollout(HeliAttitudeEnv(obs_noise=0.0), actions, seed=8)
    noisy = _rollout(HeliAttitudeEnv(obs_noise=(0.02, 0.05)), actions, seed=8)
    assert np.array_equal(np.array(clean["x"]), np.array(noisy["x"]))  # same episode, same dynamics
    diff = np.array(noisy["obs"], dtype=float) - np.array(clean["obs"], dtype=float)
    assert np.all(diff[:, 9:12] == 0.0)  # previous action
    assert_allclose(diff[:, 0:3].std(), 0.02, rtol=0.15)  # attitude noise [rad]
    assert_allclose(diff[:, 3:6].std(), 0.05, rtol=0.15)  # rate noise [rad/s]
    assert_allclose(diff[:, 6:9], -diff[:, 3:6], atol=1e-6)  # the rate error sees the same measured rates
    # reward, termination and info score the true state
    assert clean["rew"] == noisy["rew"]
    for a, b in zip(clean["info"], noisy["info"]):
        assert np.array_equal(a["attitude_error_deg"], b["attitude_error_deg"])


def test_action_delay_shifts_the_actions_by_whole_steps():
    actions = _random_actions(300, seed=6, scale=1.0)
    shifted = np.vstack([np.zeros((2, 3), np.float32), actions[:-2]])
    delayed = _rollout(HeliAttitudeEnv(action_delay=2), actions, seed=1)
    direct = _rollout(HeliAttitudeEnv(), shifted, seed=1)
    assert np.array_equal(np.array(delayed["x"]), np.array(direct["x"]))
    assert np.array_equal(np.array(delayed["obs"]), np.array(direct["obs"]))
    undelayed = _rollout(HeliAttitudeEnv(), actions, seed=1)
    assert not np.array_equal(np.array(delayed["x"]), np.array(undelayed["x"]))


# ------------------------------------------------------------------------------------------ tasks


def _reference(ep, cfg, t):
    """The episode's reference value and derivative at time t, from its draws (tasks.draw_episode)."""
    if ep.smooth:
        arg = ep.freq * t + ep.phase
        return (ep.amp * np.sin(arg)).sum(axis=1), (ep.amp * ep.freq * np.cos(arg)).sum(axis=1)
    seg = min(int(t // cfg.step_period), ep.steps.shape[1] - 1)
    return ep.steps[:, seg], np.zeros(3)


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("reference", ["steps", "smooth"])
def test_track_observes_reference_minus_attitude(reference):
    env = HeliAttitudeEnv(task="track", reference=reference, episode_seconds=8.0, obs_noise=0.0)
    env.reset(seed=21)
    ep, cfg = env._episode, env.spec_.task
    assert ep.smooth == (reference == "smooth")
    refs = []
    for k, a in enumerate(_random_actions(800, seed=3, scale=0.3)):
        obs, r, te, tr, info = env.step(a)
        ref, dref = _reference(ep, cfg, (k + 1) * 0.01)
        refs.append(ref)
        att = _attitude(env)
        rates = np.array(env._x[0:3])
        assert_allclose(obs[0:3], _wrap(ref - att), atol=2e-6)
        assert_allclose(obs[3:6], rates, atol=2e-6)
        assert_allclose(obs[6:9], dref - rates, atol=2e-6)
        assert_allclose(info["attitude_error_deg"], np.degrees(_wrap(ref - att)), atol=1e-9)
        effort = np.sum(a.astype(float) ** 2)
        assert_allclose(r, -(np.sum((_wrap(ref - att) / cfg.attitude_scale) ** 2)
                             + 0.1 * np.sum(((dref - rates) / cfg.rate_scale) ** 2) + 0.01 * effort), rtol=1e-9)
    refs = np.array(refs)
    assert np.all(np.abs(np.degrees(refs)) <= np.array([15.0, 15.0, 30.0]) + 1e-9)  # roll, pitch, yaw bounds
    if reference == "steps":
        assert np.all(refs[:299] == 0.0)  # starts from the hold point, first step at 3 s
        assert len({tuple(r) for r in refs}) == 3  # new targets at 3 s and 6 s
    else:
        assert np.ptp(refs, axis=0).min() > 0.0


def test_mixed_references_draw_both_kinds():
    env = HeliAttitudeEnv(task="track")
    kinds = set()
    for seed in range(16):
        env.reset(seed=seed)
        kinds.add(env._episode.smooth)
    assert kinds == {True, False}


def _episode_drawn_one_quantity_a_call(rng, spec, options):
    """An episode as draw_episode drew it before its draws were batched: one ``uniform`` call per quantity."""
    cfg, lengths = spec.task, spec.model.lengths
    trace = int(rng.integers(spec.model.n_traces))
    trace = trace if options.get("trace") is None else options["trace"]
    offset = int(rng.integers(max(int(lengths[trace]) - spec.needed + 1, 1)))
    angles = rng.uniform(-spec.init_angle, spec.init_angle, 2)
    rates = rng.uniform(-spec.init_rate, spec.init_rate, 3)
    smooth = bool(rng.random() < 0.5) if cfg.reference == "mixed" else cfg.reference == "smooth"
    unit_steps = rng.uniform(-1.0, 1.0, (3, int(spec.episode_steps * spec.dt // cfg.step_period) + 1))
    unit_amp = rng.uniform(0.2, 1.0, (3, N_SINES))
    freq = TWO_PI * rng.uniform(0.05, 0.4, (3, N_SINES))
    phase = rng.uniform(0.0, TWO_PI, (3, N_SINES))
    bound = reference_bounds(cfg)[:, None]
    unit_steps[:, 0] = 0.0
    return (trace, offset, angles, rates, smooth, unit_steps * bound,
            unit_amp / unit_amp.sum(axis=1, keepdims=True) * bound, freq, phase)


@pytest.mark.parametrize("task, reference", [("track", "mixed"), ("track", "smooth"), ("rate", "steps"),
                                             ("hold", "mixed")])
def test_batched_episode_draws_equal_one_uniform_call_per_quantity(task, reference):
    """draw_episodes takes one ``random`` call per generator for what was a ``uniform`` call per quantity: the
    same numbers bit for bit, and the generators left in the same state."""
    spec = build_spec(as_env_model(None), task, reference, episode_seconds=7.0, init_angle_deg=12.0)
    for options in ({}, {"trace": 1}):
        rngs = [np.random.default_rng(seed) for seed in range(40)]
        batch = draw_episodes(rngs, spec, options)
        for i, seed in enumerate(range(40)):
            again = np.random.default_rng(seed)
            expected = _episode_drawn_one_quantity_a_call(again, spec, options)
            ep = batch[i]
            got = (ep.trace, ep.offset, ep.angles, ep.rates, ep.smooth, ep.steps, ep.amp, ep.freq, ep.phase)
            for name, a, b in zip(("trace", "offset", "angles", "rates", "smooth", "steps", "amp", "freq", "phase"),
                                  got, expected):
                assert np.array_equal(a, b), (name, seed)
            assert rngs[i].integers(2**62) == again.integers(2**62)  # the same state after the draws


def test_rate_reward_ignores_the_attitude():
    """Rate dynamics do not depend on the attitude: two starts that differ only in attitude score the same."""
    runs = {}
    for task in ("rate", "hold"):
        for angle in (0.0, 20.0):
            env = HeliAttitudeEnv(task=task, init_angle_deg=angle, episode_seconds=3.0)
            runs[task, angle] = _rollout(env, _random_actions(300, seed=5), seed=4, options={"gusts": False})
    level, tilted = runs["rate", 0.0], runs["rate", 20.0]
    assert np.array_equal(np.array(level["x"])[:, 0:3], np.array(tilted["x"])[:, 0:3])  # same rates
    assert not np.allclose(np.array(level["obs"])[:, 0:3], np.array(tilted["obs"])[:, 0:3])  # other attitude
    assert level["rew"] == tilted["rew"]
    assert runs["hold", 0.0]["rew"] != runs["hold", 20.0]["rew"]
    cfg = HeliAttitudeEnv(task="rate").spec_.task
    for r, info, a in zip(tilted["rew"], tilted["info"][1:], _random_actions(300, seed=5)):
        expected = -(np.sum((np.radians(info["rate_error_deg_s"]) / cfg.rate_scale) ** 2)
                     + 0.01 * np.sum(a.astype(float) ** 2))
        assert r == pytest.approx(expected, rel=1e-9)


def test_axis_weights_weigh_each_axis_errors_in_the_reward():
    """``axis_weights`` multiply each axis' squared attitude and rate errors; all ones is the unweighted reward."""
    actions = _random_actions(200, seed=3)
    weights = (1.0, 9.0, 0.25)
    env = HeliAttitudeEnv(task=TaskConfig(axis_weights=weights), episode_seconds=2.0)
    run = _rollout(env, actions, seed=2)
    cfg = env.spec_.task
    plain = _rollout(HeliAttitudeEnv(episode_seconds=2.0), actions, seed=2)
    assert np.array_equal(np.array(run["x"]), np.array(plain["x"]))  # the weights change the score, not the flight
    for r, r0, info, a in zip(run["rew"], plain["rew"], run["info"][1:], actions):
        e_att, e_rate = np.radians(info["attitude_error_deg"]), np.radians(info["rate_error_deg_s"])
        effort = 0.01 * np.sum(a.astype(float) ** 2)
        expected = -(np.sum(weights * e_att ** 2) / cfg.attitude_scale ** 2
                     + 0.1 * np.sum(weights * e_rate ** 2) / cfg.rate_scale ** 2 + effort)
        assert r == pytest.approx(expected, rel=1e-9)
        assert r0 == pytest.approx(-(np.sum(e_att ** 2) / cfg.attitude_scale ** 2
                                     + 0.1 * np.sum(e_rate ** 2) / cfg.rate_scale ** 2 + effort), rel=1e-9)
    assert run["rew"] != plain["rew"]


def test_the_stick_step_weight_charges_the_change_of_the_applied_action():
    """``stick_step_weight`` adds ``w * sum((a_k - a_(k-1))^2)`` of the applied (clipped) actions, the first step
    from rest; the flight is unchanged, and a weight of 0 is the reward of before, bit for bit."""
    actions = _random_actions(200, seed=5)
    w = 0.7
    run = _rollout(HeliAttitudeEnv(task=TaskConfig(stick_step_weight=w), episode_seconds=2.0), actions, seed=4)
    plain = _rollout(HeliAttitudeEnv(episode_seconds=2.0), actions, seed=4)
    zero = _rollout(HeliAttitudeEnv(task=TaskConfig(stick_step_weight=0.0), episode_seconds=2.0), actions, seed=4)
    assert np.array_equal(np.array(run["x"]), np.array(plain["x"])) and zero["rew"] == plain["rew"]
    applied = np.clip(actions[:len(run["rew"])].astype(float), -1.0, 1.0)
    step = np.diff(np.vstack([np.zeros(3), applied]), axis=0)
    assert_allclose(np.array(run["rew"]), np.array(plain["rew"]) - w * np.sum(step ** 2, axis=1), rtol=1e-12,
                    atol=1e-12)
    for bad in (-0.1, float("nan"), float("inf"), True, "1"):
        with pytest.raises(ValueError, match="^stick_step_weight must be a number >= 0"):
            TaskConfig(stick_step_weight=bad)


@pytest.mark.parametrize("bad", [(1.0, 2.0), (1.0, -1.0, 1.0), (1.0, float("nan"), 1.0), (1.0, float("inf"), 0.0),
                                 (1.0, True, 1.0), ("1", 1.0, 1.0), "abc", 3.0])
@pytest.mark.parametrize("name", ["axis_weights", "weights"])
def test_reward_weights_must_be_three_finite_non_negative_numbers(name, bad):
    # an infinite weight would make every reward -inf (or nan at zero error): refused with the field's name
    with pytest.raises(ValueError, match=f"^{name} must be 3 finite numbers >= 0"):
        TaskConfig(**{name: bad})
    assert TaskConfig(**{name: np.array([1, 0.5, 0])}).__getattribute__(name) == (1.0, 0.5, 0.0)


# ------------------------------------------------------------------------------------------ integration


def _compare_with_rk4(params, seed, default_model):
    """Max rate error [rad/s] and attitude error [deg] of the env against RK4 (20 sub-steps) over 30 s."""
    model = dataclasses.replace(default_model, params=params)
    env = HeliAttitudeEnv(model=model)
    env.reset(seed=seed)
    ep = env._episode
    base = int(model.starts[ep.trace]) + ep.offset
    x = tuple(env._x)
    worst_rate = worst_att = 0.0
    for k, a in enumerate(np.random.default_rng(seed).normal(0.0, 0.4, (3000, 3)).clip(-1, 1).astype(np.float32)):
        _, _, te, tr, _ = env.step(a)
        col = float(model.collective[base + k])
        sticks = np.clip(np.array(trim_sticks(params, col)) + a, -1.0, 1.0)
        d = params.control_gains * model.ud[:, base + k]
        x = step(x, (sticks[0], sticks[1], col, sticks[2]), tuple(d.tolist()), params, 0.01, substeps=20)
        worst_rate = max(worst_rate, float(np.max(np.abs(np.subtract(env._x[0:3], x[0:3])))))
        diff = euler_from_quaternion(np.array(env._x[6:10])) - euler_from_quaternion(np.array(x[6:10]))
        worst_att = max(worst_att, float(np.degrees(np.max(np.abs(_wrap(diff))))))
        assert not te
    assert tr
    return worst_rate, worst_att


@pytest.mark.parametrize(
    "effects, rate_tol, att_tol",
    [((), 1e-13, 0.002), (("cross_coupling", "gyroscopic"), 5e-4, 0.005), (("servo_delay",), 1e-9, 0.015)],
    ids=["decoupled", "coupled", "servo-delay"],
)
def test_integration_matches_rk4_to_the_documented_error(default_model, effects, rate_tol, att_tol):
    undelayed = default_model.params.with_values(tau_roll=0.0, tau_pitch=0.0, tau_yaw=0.0)  # the case sets its own
    params = undelayed.with_values(**{k: v for e in effects for k, v in EFFECTS[e].items()})
    rate_err, att_err = _compare_with_rk4(params, seed=3, default_model=default_model)
    assert rate_err < rate_tol
    assert att_err < att_tol


def test_integration_of_an_identified_model_matches_rk4(model_dir):
    model = load_env_model(model_dir)
    rate_err, att_err = _compare_with_rk4(model.params, seed=0, default_model=model)
    assert rate_err < 1e-13
    assert att_err < 0.002


# ------------------------------------------------------------------------------------------ render


def _dial_ground_fraction(frame):
    """Share of ground-brown pixels in the left and the right half of the attitude dial."""
    pix = frame[:, : frame.shape[1] // 2].astype(int)
    ground = np.abs(pix - np.array([0xA0, 0x74, 0x4D])).sum(axis=2) < 30
    sky = np.abs(pix - np.array([0x87, 0xB6, 0xE6])).sum(axis=2) < 30
    cols = np.flatnonzero((ground | sky).any(axis=0))
    mid = (cols[0] + cols[-1] + 1) // 2  # the dial's centre column
    return ground[:, cols[0]:mid].sum() / (ground | sky)[:, cols[0]:mid].sum(), \
        ground[:, mid:cols[-1] + 1].sum() / (ground | sky)[:, mid:cols[-1] + 1].sum()


def test_rgb_array_frames_save_as_png(tmp_path):
    import matplotlib.pyplot as plt

    env = HeliAttitudeEnv(task="track", render_mode="rgb_array")
    env.reset(seed=3)
    for a in _random_actions(300, seed=1, scale=0.2):
        env.step(a)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert frame.shape[:2] == (320, 640)
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 50  # a picture, not a blank canvas
    path = tmp_path / "frame.png"
    plt.imsave(path, frame)
    back = plt.imread(path)
    assert back.shape[:2] == frame.shape[:2]
    assert_allclose(back[..., :3], frame / 255.0, atol=1 / 255)
    env.close()


def test_rendered_horizon_follows_roll_and_pitch():
    env = HeliAttitudeEnv(render_mode="rgb_array", init_angle_deg=0.0, init_rate_deg=0.0)
    env.reset(seed=0, options={"gusts": False})
    level_left, level_right = _dial_ground_fraction(env.render())
    assert level_left == pytest.approx(level_right, rel=0.05)
    for _ in range(150):  # full right stick: roll right (positive)
        env.step(np.array([1.0, 0.0, 0.0], np.float32))
    assert _attitude(env)[0] > math.radians(20)
    left, right = _dial_ground_fraction(env.render())
    assert right > 1.5 * left  # a right roll shows more ground on the right, as seen from the cockpit
    env.reset(seed=0, options={"gusts": False})
    for _ in range(150):  # nose up: the horizon sinks
        env.step(np.array([0.0, -1.0, 0.0], np.float32))
    assert _attitude(env)[1] > math.radians(10)
    up_left, up_right = _dial_ground_fraction(env.render())
    assert up_left + up_right < 0.8 * (level_left + level_right)
    env.close()


def test_render_without_a_mode_warns_and_returns_none():
    env = HeliAttitudeEnv()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


def test_render_before_reset_raises():
    with pytest.raises(ResetNeeded):
        HeliAttitudeEnv(render_mode="rgb_array").render()


def test_human_mode_draws_each_step():
    env = HeliAttitudeEnv(render_mode="human", episode_seconds=0.05)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=HUMAN_NO_DISPLAY)
        env.reset(seed=0)
        for _ in range(5):
            assert env.render() is None
            env.step(np.zeros(3, np.float32))
    env.close()


def _model_copy_with_moved_gains(tmp_path, default_model):
    """The shipped model directory with k2 and k10 changed in model.json (as a refresh may do)."""
    from model_store.model_file import save_model

    d = tmp_path / "model"
    shutil.copytree(default_model_dir(), d)
    p = default_model.params
    save_model(d, p.with_values(k2=p.k2 * 1.3, k10=p.k10 * 0.8))
    return d


def test_traces_replay_the_torque_they_were_identified_with_after_the_gains_move(tmp_path, default_model):
    """eq. 42: the identified gust torque is k * u_d with the identifying model's k; a refreshed model's
    new gains must not rescale the gusts of earlier flights."""
    moved = load_env_model(_model_copy_with_moved_gains(tmp_path, default_model))
    assert moved.params.k2 == pytest.approx(default_model.params.k2 * 1.3)
    assert np.array_equal(moved.gains, default_model.gains)
    assert np.array_equal(moved.torque, default_model.torque)
    assert np.array_equal(HeliAttitudeEnv(model=moved).spec_.torque, default_model.torque)
    assert np.array_equal(default_model.gains, np.repeat(default_model.params.control_gains[:, None], 3, axis=1))


def test_a_trace_without_recorded_gains_takes_the_model_s(tmp_path, default_model):
    import json

    d = _model_copy_with_moved_gains(tmp_path, default_model)
    manifest = d / "disturbances" / "manifest-v0001.json"
    doc = json.loads(manifest.read_text())
    doc["traces"][1]["control_gains"] = None
    manifest.write_text(json.dumps(doc))
    moved = load_env_model(d)
    assert np.array_equal(moved.gains[:, 1], moved.params.control_gains)
    assert np.array_equal(moved.gains[:, [0, 2]], default_model.gains[:, [0, 2]])
    doc["traces"][2]["control_gains"] = {"roll": "stiff", "pitch": 1.0, "yaw": 1.0}
    manifest.write_text(json.dumps(doc))
    with pytest.raises(EnvModelError, match=r"records control_gains .*expected numbers for roll, pitch and yaw"):
        load_env_model(d)


def test_replayed_gusts_in_the_model_s_stick_units(tmp_path, default_model):
    """Spectra and gust statistics see the replayed torque over the current gains: unchanged ud where the
    gains are the model's, rescaled by k_trace / k_model after the gains move."""
    assert np.array_equal(default_model.replay_ud, default_model.ud)
    moved = load_env_model(_model_copy_with_moved_gains(tmp_path, default_model))
    assert_allclose(moved.replay_ud * moved.params.control_gains[:, None], default_model.torque, rtol=1e-14)
    assert_allclose(moved.replay_ud[0], default_model.ud[0] / 1.3, rtol=1e-14)
    assert np.array_equal(moved.replay_ud[1], default_model.ud[1])


def _model_with_sensors(tmp_path, sensors):
    """A copy of the shipped model directory whose model.json records ``sensors`` (one transaction)."""
    import json
    import shutil

    from heli_env.env_model import default_model_dir
    from model_store import ModelDir

    root = tmp_path / "model"
    shutil.copytree(default_model_dir(), root)
    doc = json.loads((root / "model.json").read_text())
    doc["sensors"] = sensors
    with ModelDir(root).transaction() as tx:
        tx.write_model_document(doc)
    return root


def test_the_env_measures_through_the_models_identified_sensors(tmp_path):
    from heli_core.sensors import GyroLine, SensorModel

    sensors = SensorModel((0.01, 0.02, 0.03), (0.004, 0.002, 0.001), (GyroLine("pitch", 30.0, 0.05),))
    root = _model_with_sensors(tmp_path, sensors.to_dict())
    env = HeliAttitudeEnv(model=root)  # obs_noise="model" by default
    assert env.spec_.sensors == sensors and env.model.sensors == sensors
    actions = _random_actions(2000, seed=3)
    clean = _rollout(HeliAttitudeEnv(model=root, obs_noise=0.0, episode_seconds=30.0), actions, seed=5)
    noisy = _rollout(HeliAttitudeEnv(model=root, episode_seconds=30.0), actions, seed=5)
    assert np.array_equal(np.array(clean["x"]), np.array(noisy["x"]))
    diff = np.array(noisy["obs"], dtype=float) - np.array(clean["obs"], dtype=float)
    assert_allclose(diff[:, 0:3].std(axis=0), [0.004, 0.002, 0.001], rtol=0.1)
    assert_allclose(diff[:, [3, 5]].std(axis=0), [0.01, 0.03], rtol=0.1)
    # pitch: white noise plus the 30 Hz line (a sinusoid of amplitude A has std A / sqrt(2))
    assert_allclose(diff[:, 4].std(), np.hypot(0.02, 0.05 / np.sqrt(2)), rtol=0.1)
    spectrum = np.abs(np.fft.rfft(diff[:, 4]))
    assert np.fft.rfftfreq(diff.shape[0], 0.01)[np.argmax(spectrum)] == pytest.approx(30.0, abs=0.1)
    # measured exactly when asked
    assert HeliAttitudeEnv(model=root, obs_noise=0.0).spec_.sensors.silent


def _model_with_servo_lag(tmp_path, lags):
    """A copy of the shipped model directory whose model.json records servo lags ``lags`` (roll, pitch, yaw)."""
    import json

    from heli_env.env_model import default_model_dir
    from model_store import ModelDir

    root = tmp_path / "lagged"
    shutil.copytree(default_model_dir(), root)
    doc = json.loads((root / "model.json").read_text())
    doc["servo_lag_s"] = dict(zip(("roll", "pitch", "yaw"), lags))
    with ModelDir(root).transaction() as tx:
        tx.write_model_document(doc)
    return root


def test_the_single_and_vector_envs_fly_the_models_servo_lag(tmp_path):
    # a servo lag identified into model.json (heli identify --servo-lag auto) is flown by both envs
    root = _model_with_servo_lag(tmp_path, (0.08, 0.0, 0.0))
    actions = np.zeros((60, 3))
    actions[5:, 0] = 0.5  # a roll step
    kw = dict(obs_noise=0.0, episode_seconds=5.0)
    lagged = _rollout(HeliAttitudeEnv(model=root, **kw), actions, seed=1)
    plain = _rollout(HeliAttitudeEnv(**kw), actions, seed=1)
    assert HeliAttitudeEnv(model=root, **kw).model.params.lag_roll == 0.08
    p_lag, p_plain = np.array(lagged["x"])[:, 0], np.array(plain["x"])[:, 0]
    rise_lag = p_lag[6:20] - p_lag[5]
    rise_plain = p_plain[6:20] - p_plain[5]
    assert np.all(np.abs(rise_lag[:2]) < 0.8 * np.abs(rise_plain[:2]))  # the servo lags the step
    vec = HeliAttitudeVectorEnv(1, model=root, **kw)
    vec.reset(seed=1)
    for a in actions:
        vec.step(a[None, :])
    assert np.array_equal(np.array(vec._x)[:, 0], np.array(lagged["x"][-1]))  # the vector env flies it alike


def test_a_malformed_sensors_entry_is_refused_naming_the_file(tmp_path):
    from heli_env.errors import EnvModelError

    root = _model_with_sensors(tmp_path, {"gyro_noise_rad_s": {"roll": -1.0}})
    with pytest.raises(EnvModelError, match=r"model\.json.*standard deviations >= 0"):
        HeliAttitudeEnv(model=root)
