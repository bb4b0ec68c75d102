"""What the maximum-likelihood fit learned about one axis (the result of :mod:`identification.likelihood.estimator`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class MLAxisFit:
    """What the maximum-likelihood fit learned about one axis.

    Attributes
    ----------
    axis : str
    params : dict of str to float
        Identified parameters; the offset is the mean of the flights' offsets.
    std_errors : dict of str to float
        Standard errors from the Fisher information of the innovations.
    delay : float
        Servo delay used [s] (eq. 31).
    condition : float
        Condition number of the column-normalised Fisher information.
    r2 : float
        Share of the rate's variance the model explains from the sticks alone
        (simulation without wind, over the flights).
    history : tuple of float
        Mean squared innovation at the start and at the end of the search [(rad/s)^2].
    wind : dict
        ``time_constants_s`` (slow, fast), ``torque_std`` (slow, fast) [rad/s^2],
        ``ud_std`` (slow, fast) [stick units: torque over the control gain] and
        their standard errors.
    noise_std : float
        Gyro white-noise standard deviation [rad/s].
    nll : float
        Negative log-likelihood of the innovations (constants included).
    n_samples : int
        Samples in the likelihood.
    flight_offsets : tuple of float
        Offset kd of each flight [rad/s^2] (trim plus that day's mean wind).
    prediction_r2 : float
        Share of the rate's variance the one-step prediction explains.
    dropped : tuple of str
        Terms left out because the data did not support them (``select_terms``).
    delay_profile : tuple of (float, float)
        ``(delay, nll)`` over the grid when the delay was profiled (damping and wind held at the
        undelayed fit, linear parameters solved), else empty.
    lag : float
        Servo first-order lag used [s] (eq. 31's ``d1`` grows by it; 0: none).
    lag_profile : tuple of (float, float)
        ``(lag, nll)`` when the lag was profiled (``servo_lag="auto"``, :mod:`identification.likelihood.servo_lag`).
    lag_lr : float or None
        Likelihood-ratio statistic of the best lag against none, when profiled.
    input_hold : float
        The input's hold fraction (0 held over the sample, 1 linearly interpolated), estimated or set.
    input_hold_se : float or None
        Its standard error when estimated.
    input_shift : float
        The shift of the axis' stick found by ``delay="auto"`` [s]: negative for a log whose input lags.
    undelayed_nll : float or None
        Where the delay was profiled, the negative log-likelihood of the same axis fitted without a delay (the
        profile's start: the likelihood ratio of the delay needs no second fit); else None.
    """

    axis: str
    params: dict
    std_errors: dict
    delay: float
    condition: float
    r2: float
    history: tuple
    wind: dict
    noise_std: float
    nll: float
    n_samples: int
    flight_offsets: tuple
    prediction_r2: float
    delay_profile: tuple = ()
    dropped: tuple = ()
    interval_offsets: np.ndarray = field(default_factory=lambda: np.empty(0))
    interval_starts: np.ndarray = field(default_factory=lambda: np.empty(0))
    residual: np.ndarray | None = None
    state: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)
    lag: float = 0.0
    lag_profile: tuple = ()
    lag_lr: float | None = None
    input_hold: float = 1.0
    input_hold_se: float | None = None
    input_shift: float = 0.0
    undelayed_nll: float | None = None


def model_values(fits: dict) -> dict:
    """The model's values from axis fits ``{axis: MLAxisFit}``: each fit's parameters with its delay and lag
    (``tau_<axis>``, ``lag_<axis>``), as :class:`heli_core.params.ModelParams` names them."""
    values = {}
    for axis, fit in fits.items():
        values.update(fit.params)
        values[f"tau_{axis}"], values[f"lag_{axis}"] = fit.delay, fit.lag
    return values
