"""The physics core under its old name: a re-export of :mod:`heli_core`.

The model parameters, the RK4 and exact discrete steps, the servo model and the
quaternion conversion moved to the base layer (:mod:`heli_core.params`,
:mod:`heli_core.physics`, :mod:`heli_core.discrete`, :mod:`heli_core.servo`,
:mod:`heli_core.quaternion`), where :mod:`heli_env` and :mod:`controllers` use
them without importing the identification stage. This module keeps the names
users import from here, bound to the same objects
(``identification.model.ModelParams is heli_core.params.ModelParams``), so
``isinstance`` checks and cached kernels are shared. New code imports from
:mod:`heli_core`.
"""

from __future__ import annotations

from heli_core.discrete import (
    DISCRETE_INPUTS,
    DISCRETE_OUTPUTS,
    discrete_kernel,
    discrete_step,
    discrete_step_statements,
    linear_structure,
)
from heli_core.params import ModelParams
from heli_core.physics import (
    INPUT_NAMES,
    N_STATE,
    QUAT,
    RATES,
    SERVO,
    ZERO_DISTURBANCE,
    derivatives,
    forward_rates,
    initial_state,
    kernel,
    model_source,
    simulate,
    step,
    trim_sticks,
)
from heli_core.quaternion import euler_from_quaternion, quaternion_from_euler
from heli_core.servo import servo_coefficients
from heli_core.terms import STICK_ROW

# The private names this module had before the move, for users' imports.
_kernel = kernel
_discrete_kernel = discrete_kernel
_CMD_INPUT = STICK_ROW
_STICK_INPUT = STICK_ROW
_ZERO_D = ZERO_DISTURBANCE

__all__ = [
    "DISCRETE_INPUTS", "DISCRETE_OUTPUTS", "INPUT_NAMES", "N_STATE", "QUAT", "RATES", "SERVO", "ModelParams",
    "derivatives", "discrete_step", "discrete_step_statements", "euler_from_quaternion", "forward_rates",
    "initial_state", "linear_structure", "model_source", "quaternion_from_euler", "servo_coefficients", "simulate",
    "step", "trim_sticks",
]
