"""Residual RL on a PD controller, now :mod:`controllers.rl.residual`; this name stays importable."""

from .rl.residual import *  # noqa: F401,F403
from .rl.residual import __all__  # noqa: F401
