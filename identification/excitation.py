"""Whether a flight's inputs can identify an axis at all: a stick that never moves, a collective that does not
vary, and whether a flight came from a flight controller's log.

An estimator refuses an axis whose stick is constant (:func:`require_moving_sticks`: its gain and offset are
then one column) and leaves out the terms of an input that does not vary (:func:`static_collective`,
:func:`on_static_input`); the warnings of a fit that the data support only weakly are
:mod:`identification.validation.fit_warnings`', which share these thresholds.
"""

from __future__ import annotations

import numpy as np

from heli_core.terms import TERMS

from .errors import IdentifiabilityError

AXIS_STICK = {"roll": ("lat", 0), "pitch": ("lon", 1), "yaw": ("ped", 3)}
"""The stick driving each axis and its row in ``Flight.sticks``."""

MIN_STICK_STD = 0.01
"""Least standard deviation of an axis' stick (the range is [-1, 1])."""

CONSTANT_STICK_STD = 1e-9
"""A stick whose standard deviation is below this [stick units] is constant: its axis cannot be identified."""


def require_moving_sticks(flights, axes) -> None:
    """Refuse to fit an axis whose stick never moves (a barely moving one only warns, :func:`fit_warnings`).

    Raises
    ------
    IdentifiabilityError
        Names the axis, the stick and its constant value: with a constant input the gain and the
        offset of eq. (18) are the same column, and the fit would return a gain of 0 and a damping of
        whatever sign fits the wind.
    """
    flights = [flights] if hasattr(flights, "time") else list(flights)
    for axis in axes:
        stick, row = AXIS_STICK[axis]
        values = np.concatenate([np.asarray(f.sticks[row], dtype=float) for f in flights])
        if values.size and float(np.std(values)) < CONSTANT_STICK_STD:
            raise IdentifiabilityError(
                f"the {stick} stick is constant ({float(values[0]):.4g} over the whole flight): {axis}'s gain and "
                f"damping cannot be identified without input changes; fly sweeps on {stick}"
                + (", or check the input source (heli import --inputs)" if from_a_log(flights) else ""))


STATIC_INPUT_STD = MIN_STICK_STD
"""A modulating input (the collective) whose standard deviation within every flight is below this [stick
units] does not vary: a term it multiplies is the offset (``k12·col``) or the control gain (``gs·u·col``)
under another name, and is not fitted."""


LOG_FORMATS_OF_ONE_SOURCE = ("csv", "synthetic")
"""Flight formats whose inputs are what they are: a CSV the user wrote, a synthetic flight."""


def from_a_log(flights) -> bool:
    """Whether any flight was read from a flight controller's log, directly or as the CSV ``heli import`` wrote
    (its ``.meta.json`` beside it): only then can importing it again with another input source
    (``heli import --inputs``) change a fit, so only then is it advised."""
    flights = [flights] if hasattr(flights, "time") else list(flights)
    for f in flights:
        meta = dict(getattr(f, "metadata", {}) or {})
        if meta.get("imported_from") or meta.get("format") not in (None, *LOG_FORMATS_OF_ONE_SOURCE):
            return True
    return False


def static_collective(flights) -> float | None:
    """The collective's largest within-flight standard deviation when it is below :data:`STATIC_INPUT_STD`
    in every flight (it does not vary), else None. Within each flight, since a collective constant in each
    but different between flights is the flights' own offsets again."""
    flights = [flights] if hasattr(flights, "time") else list(flights)
    stds = [float(np.std(np.asarray(f.sticks[2], dtype=float))) for f in flights]
    worst = max(stds, default=0.0)
    return worst if worst < STATIC_INPUT_STD else None


def on_static_input(term: str, collective_static: bool) -> bool:
    """Whether ``term`` multiplies an input that does not vary (its feature uses the collective)."""
    return collective_static and "col" in TERMS[term].feature.split("*")
