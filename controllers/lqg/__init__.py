"""LQG (H2) attitude control designed with python-control on the identified model and its wind model.

The baseline a control engineer would try first, flown by the one evaluator beside the PDs and the RL agents:

* :mod:`controllers.lqg.plant` — each axis' design model: the identified airframe with its Padé servo
  (eq. 31), the identified Gauss-Markov gust states, the sensors' noise and the gyros' vibration lines;
* :mod:`controllers.lqg.design` — Bryson's weights, ``control.dlqr`` and ``control.dlqe`` at the control period,
  the loop-transfer-recovery weight searched to keep 6 dB and 45° at the plant input;
* :mod:`controllers.lqg.controller` — :class:`LQGController`, the policy with stable-baselines3's ``predict``
  (the filters' estimates in its ``state``), saved and loaded as JSON.
"""

from .controller import LQGController
from .design import AxisDesign, LQGDesign, LQGWeights, design_axis, design_lqg, loop_margins
from .plant import AxisModel, WindModel, axis_model

__all__ = ["AxisDesign", "AxisModel", "LQGController", "LQGDesign", "LQGWeights", "WindModel", "axis_model",
           "design_axis", "design_lqg", "loop_margins"]
