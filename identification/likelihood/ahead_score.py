"""The multi-step prediction's score as every report gives it: its horizon, and an R² that diverged.

:mod:`identification.likelihood.ahead_prediction` computes the R² of the prediction :data:`AHEAD_S` ahead; a
prediction whose error grows without bound (a model with negative damping, an unstable filter) has no R² and
is reported as *diverged* (:data:`DIVERGED`), never as a number like -10^42. The reports, the diagnosis and
the commands name the horizon and print the score from here, without importing the prediction itself.
"""

from __future__ import annotations

import numpy as np

AHEAD_S = 0.5
"""Horizon of the multi-step prediction the reports give [s]."""

DIVERGED = "diverged"
"""What a prediction whose error grows without bound reports instead of an R²."""

DIVERGED_R2 = -1e3
"""An R² below this (an error a thousand times the signal's variance) is a diverged prediction."""


def is_diverged(r2) -> bool:
    """True for an R² that is not a finite number above :data:`DIVERGED_R2`."""
    return r2 is None or not np.isfinite(r2) or r2 < DIVERGED_R2


def format_r2(r2, digits: int = 3) -> str:
    """An R² as text, :data:`DIVERGED` when the prediction diverged."""
    return DIVERGED if is_diverged(r2) else f"{r2:.{digits}f}"
