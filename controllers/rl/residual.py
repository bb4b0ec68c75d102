"""Residual RL on a PD controller under the module name users import: a re-export.

The residual agent, its bounds, its ``VecEnv`` wrapper and its metadata are
:mod:`controllers.rl.residual_agent` (the method is described there);
:func:`residual_setup`, which flies the base PD to scale the training, is
:mod:`controllers.rl.train`'s, beside the training that uses it. The names are
bound to the same objects, so ``isinstance`` checks hold. Code of this project
imports them from where they are defined, so that loading an agent does not
import the training.
"""

from .residual_agent import (  # noqa: F401
    RESIDUAL_INIT_DEG,
    RESIDUAL_SCALE,
    ResidualAgent,
    as_base,
    check_history,
    check_scale,
    residual_env,
    residual_from_metadata,
    residual_metadata,
    stack_observations,
)
from .train import residual_setup  # noqa: F401

__all__ = ["RESIDUAL_INIT_DEG", "RESIDUAL_SCALE", "ResidualAgent", "as_base", "check_history", "check_scale",
           "residual_env", "residual_from_metadata", "residual_metadata", "residual_setup", "stack_observations"]
