"""The Gymnasium vector env seen through SB3's ``VecEnv``, now :mod:`controllers.rl.vec_env`; this name stays
importable."""

from .rl.vec_env import GymnasiumVecEnv  # noqa: F401
