"""The observation and action layout both environments share, and the compiled kernels write into.

An observation is :data:`OBS_DIM` float32 values: attitude errors (roll, pitch, yaw) [rad], body rates [rad/s],
rate errors [rad/s] and the previous action [stick], rates bounded by :data:`MAX_RATE`; an action is three
stick offsets from trim in [-1, 1] (lat, lon, ped). A leaf of the package: the single env, the vector env, the
spec and the kernels' generated source (:mod:`heli_env.kernels`) read the layout from here, and none of them
needs another to know it.
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

MAX_RATE = 35.0
"""Observation bound of body rates and rate errors [rad/s]."""
OBS_DIM = 12
"""Length of an observation: attitude errors, rates, rate errors, previous action."""


def observation_space() -> spaces.Box:
    """The observation space (see :class:`heli_env.env.HeliAttitudeEnv`)."""
    high = np.array([math.pi] * 3 + [MAX_RATE] * 6 + [1.0] * 3, dtype=np.float32)
    return spaces.Box(-high, high, dtype=np.float32)


def action_space() -> spaces.Box:
    """lat, lon, ped offsets from trim in stick units."""
    return spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
