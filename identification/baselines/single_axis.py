"""The decoupled single-axis model both baseline identifiers fit.

The paper's baselines (Sections 2.6, 3.5 and 3.6) identify the roll model of
eq. (18) with ``k1 = k4 = 0``::

    p' = -k3*p + k2*u_lat + kd1                                        (18)

and the pitch / yaw analogues of eq. (21) with the coupling terms at zero
(``q' = -k7*q + k6*u_lon + kd2``, ``r' = -k11*r + k10*u_ped [- k12*col] + kd3``).

Parameter order. The paper's EKF and NLR sections write the roll parameters as
``k1`` (damping), ``k2`` (gain) and ``kd`` (offset), eqs. (48), (49) and (71),
and give start vectors in that order (eq. 73, Table 3, Table 4's ``m_o``). This
package keeps that *order* but uses the names of eq. (18):

* roll:  ``(k3, k2, kd1)``
* pitch: ``(k7, k6, kd2)``
* yaw:   ``(k11, k10, kd3)``, plus ``k12`` last when the collective term is on.

Forward simulations go through the one physics core,
:func:`heli_core.physics.simulate`; this module only builds the
:class:`~heli_core.params.ModelParams` and guards against simulations that
blow up for absurd parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from heli_core.params import ModelParams
from heli_core.physics import initial_state, simulate
from heli_core.terms import AXES, STICK_ROW

from ..errors import NotFittedError
from ..flight import Flight
from ..percentile import PERCENTILE_METHOD

AXIS_PARAMS: dict[str, tuple[str, str, str]] = {
    "roll": ("k3", "k2", "kd1"),
    "pitch": ("k7", "k6", "kd2"),
    "yaw": ("k11", "k10", "kd3"),
}
"""Identified parameters per axis in the paper's order (damping, gain, offset)."""

COLLECTIVE_PARAM = "k12"
"""The yaw model's optional main-rotor reaction term ``-k12*col`` (eqs. 21, 70)."""

MAX_DAMPING_STEP = 0.5
"""Largest ``|k_damp| * h`` of one RK4 sub-step in :func:`simulate_rate`.

Fixed-step RK4 maps the continuous pole ``-k_damp`` to ``R(-k_damp*h)`` with
``R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24``. Near the stability limit
(``k_damp*h ~ 2.7``) ``R`` comes back up to ``exp(-2.4*h)``-like values, so a
fast model (``k3 ~ 138``) and the slow true one (``k3 ~ 2.4``) simulate alike
at 50 Hz and nonlinear regression happily reports the fast one. Sub-stepping
to ``k_damp*h <= 0.5`` keeps the per-step pole error below 3e-4."""

MAX_SUBSTEPS = 64
"""Cap on the automatic sub-steps (absurd damping is then left to the divergence guard)."""

RATE_CAP = 1.0e3
"""rad/s. Simulated rates beyond this (or non-finite) are clipped to it, so a
diverging simulation (e.g. negative damping) yields large finite residuals."""


def axis_index(axis: str) -> int:
    """Index 0/1/2 of ``"roll"``/``"pitch"``/``"yaw"``; ValueError otherwise."""
    if axis not in AXIS_PARAMS:
        raise ValueError(f"axis must be one of {', '.join(map(repr, AXES))}, got {axis!r}")
    return AXES.index(axis)


def parameter_names(axis: str, collective: bool = False) -> tuple[str, ...]:
    """Names of the identified parameters in the paper's order.

    Parameters
    ----------
    axis : {"roll", "pitch", "yaw"}
    collective : bool
        Add ``k12`` (yaw only), the ``-k12*col`` term of eq. (21).

    Returns
    -------
    tuple of str
        ``(damping, gain, offset)`` or ``(damping, gain, offset, "k12")``.
    """
    axis_index(axis)
    if collective and axis != "yaw":
        raise ValueError(f"collective=True adds the yaw term -k12*col; it needs axis='yaw', got {axis!r}")
    return AXIS_PARAMS[axis] + ((COLLECTIVE_PARAM,) if collective else ())


def check_vector(name: str, values, names: tuple[str, ...]) -> np.ndarray:
    """A finite float vector with one value per parameter in ``names``."""
    v = np.asarray(values, dtype=float).reshape(-1)
    if v.size != len(names):
        raise ValueError(
            f"{name} must hold {len(names)} values in the order ({', '.join(names)}), got {v.size}"
        )
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v.tolist()}")
    return v


def make_params(names: tuple[str, ...], values) -> ModelParams:
    """:class:`ModelParams` with ``names`` set to ``values`` and every other parameter 0."""
    return ModelParams(**{n: float(v) for n, v in zip(names, values)})


def simulate_rate(params: ModelParams, flight: Flight, axis: str, substeps: int = 1,
                  rate_cap: float = RATE_CAP) -> np.ndarray:
    """Forward-simulate the model on a flight's sticks and return one body rate.

    The simulation starts from the measured rate of ``axis`` at the first
    sample (the other rates at 0, servo states settled on the first sticks) and
    runs through :func:`heli_core.physics.simulate` (eq. 72: the numerical
    solution of eq. 18). The RK4 sub-steps are raised so that one sub-step
    spans at most ``MAX_DAMPING_STEP / |k_damp|`` (up to ``MAX_SUBSTEPS``),
    keeping the solution accurate for strongly damped parameter sets.

    Parameters
    ----------
    params : ModelParams
    flight : Flight
    axis : {"roll", "pitch", "yaw"}
    substeps : int
        Minimum RK4 sub-steps per sample interval.
    rate_cap : float
        Values beyond ``±rate_cap`` [rad/s] or non-finite are replaced by
        ``±rate_cap`` (NaN by ``+rate_cap``): a diverging simulation gives a
        large finite result instead of NaN/inf.

    Returns
    -------
    ndarray, shape (n,)
        Simulated rate [rad/s].
    """
    i = axis_index(axis)
    rates0 = [0.0, 0.0, 0.0]
    rates0[i] = float(flight.rates[i, 0])
    x0 = initial_state(rates=rates0, sticks=flight.sticks[list(STICK_ROW), 0])
    damping = abs(params.get(AXIS_PARAMS[axis][0]))
    substeps = int(min(max(substeps, math.ceil(damping * flight.dt / MAX_DAMPING_STEP)), MAX_SUBSTEPS))
    try:
        rate = simulate(params, flight.time, flight.sticks, x0=x0, substeps=substeps)[i]
    except ArithmeticError:  # overflow / zero division inside a blown-up simulation
        return np.full(flight.n, float(rate_cap))
    rate = np.nan_to_num(rate, nan=rate_cap, posinf=rate_cap, neginf=-rate_cap)
    return np.clip(rate, -rate_cap, rate_cap)


@dataclass(frozen=True)
class RateErrors:
    """Error statistics of a simulated against a measured rate (Tables 1, 3, 4, 5).

    Attributes
    ----------
    mae : float
        Mean absolute error [deg/s].
    p90 : float
        90th percentile of the absolute error [deg/s], interpolated as Matlab's
        ``prctile`` (:data:`identification.percentile.PERCENTILE_METHOD`).
    """

    mae: float
    p90: float


def rate_errors(simulated, measured) -> RateErrors:
    """Mean absolute error and 90th percentile of ``|simulated - measured|``.

    The single-axis counterpart of :func:`identification.validation.forward_simulation.rate_error_stats`.

    Parameters
    ----------
    simulated, measured : ndarray, shape (n,)
        Rates [rad/s].

    Returns
    -------
    RateErrors
        In deg/s, the unit of the paper's tables.
    """
    err = np.degrees(np.abs(np.asarray(simulated, dtype=float) - np.asarray(measured, dtype=float)))
    return RateErrors(mae=float(err.mean()), p90=float(np.percentile(err, 90.0, method=PERCENTILE_METHOD)))


class SingleAxisEstimator:
    """Shared ``predict`` / ``score`` / ``errors`` of the baseline estimators.

    Subclasses set ``axis``, ``collective`` and ``substeps`` in ``__init__`` and
    ``params_`` in ``fit``.
    """

    axis: str
    collective: bool
    substeps: int

    def _check_fitted(self) -> None:
        if not hasattr(self, "params_"):
            raise NotFittedError(
                f"this {type(self).__name__} is not fitted yet; call fit(flight) before using it"
            )

    @property
    def param_names_(self) -> tuple[str, ...]:
        """Identified parameter names in the paper's order (damping, gain, offset[, k12])."""
        self._check_fitted()
        return parameter_names(self.axis, self.collective)

    @property
    def coef_(self) -> np.ndarray:
        """Identified values in the order of :attr:`param_names_`."""
        self._check_fitted()
        return np.array([self.params_.get(n) for n in self.param_names_])

    def predict(self, flight: Flight) -> np.ndarray:
        """Simulated rate of :attr:`axis` [rad/s], shape (n,), on ``flight``'s sticks.

        Forward simulation of the identified model through
        :func:`heli_core.physics.simulate` from the measured initial rate;
        a diverging simulation is clipped to ``±RATE_CAP``.
        """
        self._check_fitted()
        return simulate_rate(self.params_, flight, self.axis, self.substeps)

    def errors(self, flight: Flight) -> RateErrors:
        """MAE and 90th percentile [deg/s] of :meth:`predict` against the measured rate."""
        return rate_errors(self.predict(flight), flight.rates[axis_index(self.axis)])

    def score(self, flight: Flight) -> float:
        """Coefficient of determination R^2 of :meth:`predict` (1 is a perfect fit)."""
        measured = flight.rates[axis_index(self.axis)]
        resid = self.predict(flight) - measured
        total = float(np.sum((measured - measured.mean()) ** 2))
        return 1.0 - float(resid @ resid) / total if total > 0 else float("nan")
