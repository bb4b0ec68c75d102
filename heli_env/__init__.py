"""Gymnasium environments driven by identified helicopter attitude models.

Importing the package registers ``HeliAttitude-v0``: the single environment
(:class:`heli_env.env.HeliAttitudeEnv`) and, as its vector entry point, the
native numpy-batched :class:`heli_env.vector_env.HeliAttitudeVectorEnv`::

    import gymnasium as gym
    import heli_env  # noqa: F401  (registers the environments)

    env = gym.make("HeliAttitude-v0", model="out/model")      # a 'heli identify' output directory
    envs = gym.make_vec("HeliAttitude-v0", num_envs=64, vectorization_mode="vector_entry_point")

Both step the identified model with the physics core of :mod:`heli_core`
and replay the disturbance library that ``heli identify`` writes.
"""

import gymnasium

from heli_core.deprecation import install

from .env import HeliAttitudeEnv
from .env_model import default_model_dir, load_env_model
from .errors import ActionError, EnvModelError
from .tasks import TaskConfig

install(__name__)

ENV_ID = "HeliAttitude-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="heli_env.env:HeliAttitudeEnv",
        vector_entry_point="heli_env.vector_env:HeliAttitudeVectorEnv",
    )

__all__ = ["ENV_ID", "ActionError", "EnvModelError", "HeliAttitudeEnv", "TaskConfig", "default_model_dir",
           "load_env_model"]
