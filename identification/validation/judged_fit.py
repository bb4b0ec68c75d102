"""Which R² judges whether a fitted model describes an axis: the figure :func:`~.fit_warnings.fit_warnings` and
the weak-fit warning are given.

For the integral method it is the regression R² of the rate derivative. For a maximum-likelihood model it is
the 0.5 s-ahead prediction's on the fitted flights, not the share the sticks explain alone (low for a correct
model when the wind dominates the axis) nor the one-step prediction's (near 1 for any model sampled fast): see
:mod:`identification.validation.fit_warnings`. Computing it runs the prediction, so it stands apart from the
warnings, which only read figures.
"""

from __future__ import annotations

import math

import numpy as np

AHEAD_LABEL = "0.5 s-ahead prediction"
"""How :func:`judged_r2` names the R² of a maximum-likelihood model in the warning."""


def judged_r2(identifier, flights) -> tuple[dict, str]:
    """The R² per axis that says whether a fitted model describes the axis, and its name for the warning.

    Parameters
    ----------
    identifier : MaximumLikelihoodIdentifier or IntegralIdentifier
        Fitted on ``flights``.
    flights : sequence of Flight
        The flights as given to ``fit``.

    Returns
    -------
    r2 : dict
        ``{axis: r2}``: for maximum likelihood the 0.5 s-ahead prediction's on the fitted flights
        (:func:`identification.likelihood.ahead_prediction.fitted_ahead_r2`; ``-inf`` where it diverged); for the
        integral method its regression R² of the rate derivative.
    label : str
        :data:`AHEAD_LABEL` or ``"fit"``.
    """
    from ..likelihood.estimator import MaximumLikelihoodIdentifier

    if not isinstance(identifier, MaximumLikelihoodIdentifier):
        return {a: f.r2 for a, f in identifier.axes_.items()}, "fit"
    from ..likelihood.ahead_prediction import fitted_ahead_r2

    ahead = fitted_ahead_r2(identifier, flights)
    return {a: (-math.inf if not np.isfinite(v) else v) for a, v in ahead.items()}, AHEAD_LABEL
