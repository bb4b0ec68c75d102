"""The library of named model terms under its old name: a re-export of :mod:`heli_core.terms`.

The term table (the model's only definition, eqs. 18-24 and the candidate
effects), the axis names and the stick of each axis moved to the base layer.
The names users import from here are the same objects; new code imports from
:mod:`heli_core.terms`.
"""

from __future__ import annotations

from heli_core.terms import (
    AXES,
    BASE_PARAMS,
    COUPLED,
    DECOUPLED,
    EXTRA_PARAMS,
    FEATURE_EXPRESSIONS,
    FEATURE_NAMES,
    FEATURES,
    INPUT_FOR_AXIS,
    RATE_DEPENDENCE,
    STICK_ROW,
    STICKS,
    TERMS,
    FeatureFn,
    Term,
    evaluate_features,
    terms_for_axis,
)

__all__ = [
    "AXES", "BASE_PARAMS", "COUPLED", "DECOUPLED", "EXTRA_PARAMS", "FEATURE_EXPRESSIONS", "FEATURE_NAMES", "FEATURES",
    "INPUT_FOR_AXIS", "RATE_DEPENDENCE", "STICKS", "STICK_ROW", "TERMS", "FeatureFn", "Term", "evaluate_features",
    "terms_for_axis",
]
