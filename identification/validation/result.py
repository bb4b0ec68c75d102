"""The result of a validation: the simulated histories and the error statistics of models on one flight.

:func:`identification.validation.forward_simulation.validate_models` builds it; its tables and
figures are drawn from it by :mod:`identification.reports.validation`, which it does not import (a result
never imports its report). It stands apart from the simulation so that the report, which only reads it,
does not import the simulation and the flight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from heli_core.files import jsonable

from ..attitude import DETREND_PERIOD


@dataclass(eq=False)
class ValidationResult:
    """Simulated histories and error statistics of one or more models on one flight.

    Built by :func:`~identification.validation.forward_simulation.validate_models`.

    Attributes
    ----------
    time : ndarray, shape (n,)
        Sample times [s].
    measured_rates : ndarray, shape (3, n)
        The measured p, q, r the models are compared with [rad/s].
    simulated : dict of str to ndarray, shape (3, n)
        Model label -> simulated p, q, r [rad/s].
    simulated_attitude : dict of str to ndarray, shape (3, n)
        Model label -> roll, pitch, yaw from the simulated quaternion,
        eqs. (25)-(29) [rad] (wrapped, not detrended).
    rate_stats : dict
        Model label -> :func:`~identification.validation.forward_simulation.rate_error_stats` (Tables 1-2).
    attitude_stats : dict
        Model label -> :func:`~identification.validation.forward_simulation.attitude_error_stats` (Section 3.2).
    between : dict of str to float or None
        :func:`~identification.validation.forward_simulation.between_models_mae` of the two models when exactly two were
        compared (Table 2), else None.
    measured_attitude : ndarray, shape (3, n), optional
        Measured roll, pitch, yaw [rad]; needed by
        :func:`~identification.reports.validation.plot_attitude_fit`.
    period : float
        Length of the pieces of the attitude detrend [s].
    """

    time: np.ndarray
    measured_rates: np.ndarray
    simulated: dict
    simulated_attitude: dict
    rate_stats: dict
    attitude_stats: dict
    between: dict | None = None
    measured_attitude: np.ndarray | None = None
    period: float = DETREND_PERIOD

    @property
    def labels(self) -> list[str]:
        """Model labels in the order they were given."""
        return list(self.simulated)

    def to_dict(self) -> dict:
        """Statistics as plain JSON-ready values (non-finite numbers become None).

        The histories are left out; the dictionary holds ``models``,
        ``n_samples``, ``duration_s``, ``detrend_period_s``, ``rate_stats``,
        ``attitude_stats`` and ``between``.
        """
        return jsonable({
            "models": self.labels,
            "n_samples": int(np.size(self.time)),
            "duration_s": float(self.time[-1] - self.time[0]),
            "detrend_period_s": float(self.period),
            "rate_stats": self.rate_stats,
            "attitude_stats": self.attitude_stats,
            "between": self.between,
        })
