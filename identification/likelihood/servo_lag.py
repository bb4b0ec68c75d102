"""The servo's first-order lag as a profile of the likelihood, kept only where the data support it.

A servo that lags its command by a time constant ``T`` is eq. (31) with ``T`` added to ``d1``
(:func:`heli_core.servo.servo_coefficients`): ``(1 - s tau/2) / (1 + s (tau/2 + T))``. At low
frequency a lag and a transport delay shape the phase alike (``tau + T`` of lag), so on most flights
the delay alone explains the timing; what only a lag explains is the gain it takes off above
``1/(2 pi T)``, which sweeps up to 2-3 Hz reach for servos of 30 ms and more.

:func:`profile_lag` fits the axis at every lag of :data:`LAG_GRID` (the delay searched with it when
the identifier profiles the delay, else held), refines the best by a bounded search between its neighbours,
fits there with every gust model, and keeps the lag when the likelihood-ratio statistic against no lag
exceeds ``max(chi2_1(1 - ALPHA), MIN_LR_LAG)`` and the lag is not at the top of the grid. It is how
:class:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier` runs ``servo_lag="auto"``.
"""

from __future__ import annotations

import numpy as np
from scipy import optimize, stats

from .axis_search import WindFit
from .state_space import concentrated_nll

LAG_GRID = (0.01, 0.02, 0.03, 0.05, 0.08, 0.12, 0.2)
"""Servo lags profiled [s]; the best is refined between its neighbours."""
ALPHA = 0.01
"""Level of the likelihood-ratio test of a lag against none."""
MIN_LR_LAG = 10.0
"""Smallest likelihood-ratio statistic of a lag kept (calibrated on flights whose servo has none)."""
NFEV = 30
"""Likelihood evaluations per grid point (each warm-started from the fit without a lag)."""
REFINE_XATOL = 0.001
"""The lag's refinement between the best grid point's neighbours stops within this [s]."""
REFINE_ITER = 8
"""At most this many fits of the refinement (each as a grid point's)."""


def threshold() -> float:
    """The statistic a lag must exceed to be kept."""
    return max(float(stats.chi2.ppf(1.0 - ALPHA, 1)), MIN_LR_LAG)


def bracketed_minimum(nll, profile: list) -> tuple[float, list]:
    """The lag of least ``nll(lag)`` between the neighbours of ``profile``'s best point ((lag, nll), increasing
    lag), by a bounded scalar search (:func:`scipy.optimize.minimize_scalar`, :data:`REFINE_XATOL`, at most
    :data:`REFINE_ITER` evaluations), and the profile with the points it evaluated. A parabola through the three
    points missed the minimum where the delay searched with the lag reaches zero between them (the profile has a
    kink there): a 40 ms lag came out 31.5 ms beside a 6.5 ms delay, 2.8 in NLL short of the truth's fit, and
    the gains 2-4 % low."""
    lags = [p[0] for p in profile]
    i = int(np.argmin([p[1] for p in profile]))
    if i in (0, len(profile) - 1):  # no lag, or the top of the grid (refused by the caller)
        return lags[i], profile
    seen = {}

    def recorded(lag):
        seen[float(lag)] = nll(lag)
        return seen[float(lag)]

    optimize.minimize_scalar(recorded, bounds=(lags[i - 1], lags[i + 1]), method="bounded",
                             options={"xatol": REFINE_XATOL, "maxiter": REFINE_ITER})
    profile = sorted(profile + [(lag, v) for lag, v in seen.items() if lag not in lags])
    best = min(profile, key=lambda p: p[1])[0]
    return best, profile


def profile_lag(problem, base: WindFit, models, free_tau: bool) -> tuple:
    """Profile the servo lag of ``problem``'s axis from ``base``, its fit without one.

    Parameters
    ----------
    problem : identification.likelihood.axis_search.AxisProblem
        The axis' likelihood.
    base : WindFit
        Its optimum without a lag.
    models : sequence of str
        The gust models the best lag's fit chooses from.
    free_tau : bool
        Whether the delay is searched with the rest (``delay="auto"``).

    Returns ``(lag, fit, profile, lr)``: the lag kept (0 when the data do not support one, with ``base``),
    the fit at it (a :class:`WindFit`), ``(lag, nll)`` over the grid (the refined lag included) and the
    statistic of the best lag against none.
    """
    cost0, x0, kind0, tau0 = base
    n = int(sum(f.n - problem.burn for f in problem.flights))
    def nll(lag):
        return concentrated_nll(problem.best(tau0, x0, (kind0,), NFEV, free_tau, float(lag))[0], n)

    profile = [(0.0, concentrated_nll(cost0, n))] + [(float(lag), nll(lag)) for lag in LAG_GRID]
    best, profile = bracketed_minimum(nll, profile)
    if best <= 0.0:
        return 0.0, base, tuple(profile), 0.0
    fit = problem.best(tau0, x0, models, None, free_tau, best)
    nll = concentrated_nll(fit[0], n)
    profile = sorted([p for p in profile if p[0] != best] + [(best, nll)])  # the refined lag's full fit
    lr = 2.0 * (concentrated_nll(cost0, n) - nll)
    if lr > threshold() and best < LAG_GRID[-1] - 1e-9:
        return best, fit, tuple(profile), float(lr)
    return 0.0, base, tuple(profile), float(lr)
