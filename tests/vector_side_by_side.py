"""Helpers of the vector env's tests: a vector env stepped beside single environments, one per copy.

:func:`run_side_by_side` runs ``num_envs`` single environments seeded ``seed + i`` beside one vector
environment seeded ``seed`` under the same actions, through terminations, truncations and autoresets, and
requires the same state bit for bit and the same observations, rewards and infos.
"""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose

from heli_env import HeliAttitudeEnv
from heli_env.vector_env import HeliAttitudeVectorEnv

INFO_KEYS = ("time", "disturbance", "attitude_error_deg", "rate_error_deg_s", "trace")


def random_actions(n_steps, n, seed=0):
    """Random actions, some beyond [-1, 1]; copy 0 holds full right stick (it terminates), copy 1 full left."""
    a = np.random.default_rng(seed).uniform(-1.3, 1.3, (n_steps, n, 3)).astype(np.float32)
    a[:, 0] = (1.0, 0.0, 0.0)
    a[:, 1] = (-1.0, 0.3, 0.0)
    return a


def run_side_by_side(kwargs, n=4, n_steps=600, seed=100, options=None, watch=None):
    """Step a vector env of n copies and a single env for each copy of ``watch`` (all by default) with the same
    actions; check they agree; return event counts."""
    venv = HeliAttitudeVectorEnv(n, **kwargs)
    watch = list(range(n)) if watch is None else list(watch)
    envs = {i: HeliAttitudeEnv(**kwargs) for i in watch}
    vobs, vinfo = venv.reset(seed=seed, options=options)
    singles = [env.reset(seed=seed + i, options=options) for i, env in envs.items()]
    check_same(venv, envs, vobs, vinfo, [o for o, _ in singles], [i for _, i in singles])
    done = dict.fromkeys(watch, False)
    counts = {"terminated": 0, "truncated": 0, "autoreset": 0}
    for actions in random_actions(n_steps, n):
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(actions)
        obs, infos = [], []
        for i, env in envs.items():
            if done[i]:  # NEXT_STEP autoreset: this step resets the copy, reward 0, not done
                o, info = env.reset()
                r, te, tr = 0.0, False, False
                counts["autoreset"] += 1
            else:
                o, r, te, tr, info = env.step(actions[i])
            done[i] = te or tr
            counts["terminated"] += te
            counts["truncated"] += tr
            assert vterm[i] == te and vtrunc[i] == tr
            assert_allclose(vrew[i], r, rtol=1e-12, atol=1e-12)
            obs.append(o)
            infos.append(info)
        check_same(venv, envs, vobs, vinfo, obs, infos)
    return counts


def check_same(venv, envs, vobs, vinfo, obs, infos):
    x = np.array(venv._x)
    for (i, env), o, info in zip(envs.items(), obs, infos):
        assert np.array_equal(np.array(env._x), x[:, i]), f"state of copy {i}"
        assert_allclose(vobs[i], o, rtol=1e-12, atol=1e-12)
        for key in INFO_KEYS:
            assert_allclose(vinfo[key][i], info[key], rtol=1e-12, atol=1e-12, err_msg=key)
            assert vinfo[f"_{key}"][i]
