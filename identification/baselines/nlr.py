"""Nonlinear regression over forward simulations, the paper's NLR baseline (Section 3.5).

The parameters of the decoupled model (eq. 18 with ``k1 = k4 = 0`` for roll)
minimise the output error of eq. (71)::

    F(k_damp, k_gain, kd) = sum_i (p_numerical(t_i) - p_data(t_i))^2         (71)

where ``p_numerical`` is the numerical solution of the model on the measured
sticks (eq. 72). The paper used Matlab's ``lsqnonlin`` (trust-region
reflective) around ``ode45``; here :func:`scipy.optimize.least_squares`
(``method="trf"``, the same algorithm) drives :func:`heli_core.physics.simulate`
(fixed-step RK4 at the data's sample interval). Every residual evaluation,
including those of the finite-difference Jacobian, is one forward simulation,
which is what makes the method slow (Table 3).
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..flight import Flight
from .paper_tables import TABLE3_STARTS
from .single_axis import (
    RATE_CAP,
    SingleAxisEstimator,
    axis_index,
    check_vector,
    make_params,
    parameter_names,
    simulate_rate,
)


@dataclass(frozen=True)
class NLRHistory:
    """Every forward simulation of a :class:`NonlinearRegression` fit, in call order.

    Attributes
    ----------
    names : tuple of str
        Parameter names, e.g. ``("k3", "k2", "kd1")``.
    params : ndarray, shape (n_simulations, n_params)
        Parameters of each simulation (objective and Jacobian evaluations).
    cost : ndarray, shape (n_simulations,)
        ``0.5 * sum(residual**2)`` of each simulation [(rad/s)^2], i.e. half eq. (71).
    """

    names: tuple[str, ...]
    params: np.ndarray
    cost: np.ndarray


class NonlinearRegression(SingleAxisEstimator):
    """Output-error least squares over forward simulations, eqs. (71)-(73).

    Parameters
    ----------
    axis : {"roll", "pitch", "yaw"}
        Axis to identify. Roll fits ``(k3, k2, kd1)``, pitch ``(k7, k6, kd2)``,
        yaw ``(k11, k10, kd3)``.
    start : sequence of float, shape (3,) or (4,)
        Start point in the paper's order ``(k_damp, k_gain, kd)``: for roll the
        paper's ``(k1, k2, kd)`` of eq. (73) are our ``(k3, k2, kd1)``. Units
        [1/s, rad/s^2 per unit stick, rad/s^2]. Eq. (73) is ``(5, 5, 5)``; Table 3
        adds ``(50, 50, 50)`` and ``(100, 100, 100)``
        (:data:`~identification.baselines.paper_tables.TABLE3_STARTS`). With ``collective=True`` a fourth value starts ``k12``.
    collective : bool
        Yaw only: include the ``-k12*col`` term of eq. (21) (as in eq. 70).
    bounds : (lower, upper) or None
        Bounds on the parameters, each a float or a sequence in the order of
        ``start``; ``None`` is unbounded, as the paper's ``lsqnonlin`` call.
    ftol, xtol, gtol : float
        Termination tolerances of :func:`scipy.optimize.least_squares`.
    max_nfev : int or None
        Maximum objective evaluations (``None``: scipy's default, 100 * n_params).
    diff_step : float or None
        Relative step of the finite-difference Jacobian (``None``: scipy's default).
    substeps : int
        RK4 sub-steps per sample interval of each forward simulation.

    Attributes
    ----------
    params_ : ModelParams
        Identified model (other parameters 0).
    coef_ : ndarray, shape (n_params,)
        Identified values in the order of ``param_names_``.
    cost_ : float
        Final ``0.5 * sum(residual**2)`` [(rad/s)^2] (half eq. 71).
    residual_ : ndarray, shape (n,)
        Final simulated minus measured rate [rad/s].
    converged_ : bool
        ``least_squares`` stopped on a tolerance (not on ``max_nfev``) and the
        final simulation did not diverge.
    diverged_ : bool
        The final simulation hit the divergence guard (``±RATE_CAP``).
    status_ : int
        ``least_squares`` status; ``message_`` : str, its message.
    nfev_, njev_ : int
        Objective and Jacobian evaluations reported by ``least_squares``.
    n_simulations_ : int
        Forward simulations run in total (objective + finite-difference Jacobian).
    cpu_time_ : float
        CPU time of the fit [s] (:func:`time.process_time`), the Table 3 figure.
    history_ : NLRHistory
        Parameters and cost of every forward simulation.

    Notes
    -----
    Absurd parameters (negative damping) make the simulation blow up; the
    simulated rate is then clipped to ``±RATE_CAP`` (1000 rad/s) so the residual
    stays large and finite and the optimiser never sees NaN. The objective is
    flat there, so a start inside a diverging region may stop at once.

    Examples
    --------
    >>> nlr = NonlinearRegression(axis="roll", start=(5, 5, 5)).fit(flight)  # doctest: +SKIP
    >>> nlr.params_.k2, nlr.params_.k3, nlr.params_.kd1                      # doctest: +SKIP
    """

    def __init__(self, axis="roll", start=(5.0, 5.0, 5.0), collective=False, bounds=None,
                 ftol=1e-8, xtol=1e-8, gtol=1e-8, max_nfev=None, diff_step=None, substeps=1):
        self.axis = axis
        self.start = start
        self.collective = collective
        self.bounds = bounds
        self.ftol = ftol
        self.xtol = xtol
        self.gtol = gtol
        self.max_nfev = max_nfev
        self.diff_step = diff_step
        self.substeps = substeps

    def fit(self, flight: Flight) -> "NonlinearRegression":
        """Minimise eq. (71) on ``flight``; returns ``self``.

        Parameters
        ----------
        flight : Flight
            Measured rates [rad/s] and sticks; the sticks drive the simulation.
        """
        names = parameter_names(self.axis, self.collective)
        x0 = check_vector("start", self.start, names)
        measured = np.asarray(flight.rates[axis_index(self.axis)], dtype=float)
        bounds = (-np.inf, np.inf) if self.bounds is None else self.bounds
        seen_params: list[np.ndarray] = []
        seen_cost: list[float] = []

        def residual(theta):
            sim = simulate_rate(make_params(names, theta), flight, self.axis, self.substeps)
            res = sim - measured
            seen_params.append(np.array(theta, dtype=float))
            seen_cost.append(0.5 * float(res @ res))
            return res

        t0 = _time.process_time()
        result = least_squares(
            residual, x0, bounds=bounds, method="trf", ftol=self.ftol, xtol=self.xtol,
            gtol=self.gtol, max_nfev=self.max_nfev, diff_step=self.diff_step,
        )
        self.cpu_time_ = _time.process_time() - t0

        self.params_ = make_params(names, result.x)
        self.cost_ = float(result.cost)
        self.residual_ = np.asarray(result.fun, dtype=float)
        self.diverged_ = bool(np.any(np.abs(self.residual_ + measured) >= RATE_CAP))
        self.converged_ = bool(result.status > 0) and not self.diverged_
        self.status_ = int(result.status)
        self.message_ = str(result.message)
        self.nfev_ = int(result.nfev)
        self.njev_ = int(result.njev or 0)
        self.n_simulations_ = len(seen_cost)
        self.history_ = NLRHistory(names, np.array(seen_params), np.array(seen_cost))
        return self
