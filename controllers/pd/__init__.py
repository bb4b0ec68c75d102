"""Per-axis PD attitude controllers designed on the identified model with python-control.

One concept per module, each standing on the ones before it:

* :mod:`~controllers.pd.law`: the PD law (:func:`~controllers.pd.law.pd_command`) and
  the sign of an axis' control gain (:func:`control_sign`);
* :mod:`~controllers.pd.linearisation`: the design model, the decoupled linearisation of
  one axis at rest (eqs. 18, 21 and the Padé servo of eq. 31), continuous and as
  the environment samples it (:func:`plant`);
* :mod:`~controllers.pd.controller`: the control law, :class:`PDGains` and the
  policy :class:`PDController` with stable-baselines3's ``predict``;
* :mod:`~controllers.pd.analysis`: margins, bandwidth, poles and disturbance
  responses of the sampled loop (:func:`loop_analysis`, :class:`LoopAnalysis`);
* :mod:`~controllers.pd.design`: gains for a bandwidth and a phase margin
  (:func:`propose_gains`, :func:`design_gains`);
* :mod:`~controllers.pd.figures`: step responses and Bode plots (matplotlib).

Every name below is importable from ``controllers.pd`` as well::

    from controllers.pd import PDController, design_gains, loop_analysis
"""

from .analysis import LoopAnalysis, closed_loop_bandwidth, loop_analysis
from .controller import OBS_DIM, SCHEMA, SCHEMA_VERSION, PDController, PDGains
from .design import D_FILTER_RATIO, DEFAULT_D_FILTER, design_gains, propose_gains
from .figures import plot_bode, plot_step_responses
from .law import control_sign
from .linearisation import plant

__all__ = ["D_FILTER_RATIO", "DEFAULT_D_FILTER", "OBS_DIM", "SCHEMA", "SCHEMA_VERSION", "LoopAnalysis", "PDController", "PDGains", "closed_loop_bandwidth",
           "control_sign", "design_gains", "loop_analysis", "plant", "plot_bode", "plot_step_responses",
           "propose_gains"]
