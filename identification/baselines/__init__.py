"""The paper's two baseline identifiers, against which the integral method is judged.

* :class:`NonlinearRegression` — output-error least squares over forward
  simulations, eqs. (71)-(73), Table 3.
* :class:`ParameterEKF` — joint state/parameter extended Kalman filter,
  eqs. (48)-(64), Tables 4-5, Figs. 22-23; :func:`ekf_sample_length_study`
  reproduces Table 5.

Both fit the decoupled single-axis model (roll: eq. 18 with ``k1 = k4 = 0``,
parameters ``(k3, k2, kd1)`` = the paper's EKF/NLR ``(k1, k2, kd)``: damping,
gain, offset) and both are scikit-learn style estimators: the constructor
stores its arguments, ``fit(flight)`` returns ``self``, learned attributes end
in ``_`` and ``predict(flight)`` forward-simulates the identified model through
:func:`heli_core.physics.simulate`.
"""

from ..errors import NotFittedError
from .ekf import (
    P0_EQ74,
    EKFHistory,
    ParameterEKF,
    SampleLengthResult,
    ekf_sample_length_study,
    estimate_noise_variance,
)
from .nlr import NLRHistory, NonlinearRegression
from .paper_tables import TABLE3_STARTS, TABLE4_M0, TABLE4_Q, TABLE5_LENGTHS
from .single_axis import AXIS_PARAMS, RATE_CAP, RateErrors, parameter_names, rate_errors, simulate_rate

__all__ = [
    "AXIS_PARAMS", "EKFHistory", "NLRHistory", "NonlinearRegression", "NotFittedError",
    "P0_EQ74", "ParameterEKF", "RATE_CAP", "RateErrors", "SampleLengthResult", "TABLE3_STARTS",
    "TABLE4_M0", "TABLE4_Q", "TABLE5_LENGTHS", "ekf_sample_length_study", "estimate_noise_variance",
    "parameter_names", "rate_errors", "simulate_rate",
]
