"""Named exceptions of the identification package.

Every error says what was expected and what came, so a user can fix the input
without reading a traceback. Each derives from the package-wide root
:class:`heli_core.errors.HeliError` and from the standard exception that a
caller would otherwise catch (``ValueError``, ``ImportError``).
The errors of the base layer (:mod:`heli_core.errors`: the root, :class:`MissingDependency`, ...) and of
the model folder (:mod:`model_store.errors`) are imported from there; their old names here are deprecated
(:mod:`identification._deprecated`).
"""

from __future__ import annotations

from heli_core.deprecation import module_getattr
from heli_core.errors import HeliError



class FlightLogError(HeliError, ValueError):
    """A flight log or in-memory flight is malformed (columns, NaNs, time base, units, ranges)."""


class UnitError(FlightLogError):
    """A column is in another unit than the canonical one (deg/s for rad/s, ms for s, PWM us for [-1, 1]).

    The message names the suspected unit and the conversion that fixes it.
    """


class IdentifiabilityError(HeliError, ValueError):
    """The data cannot determine the requested parameters (too short, no excitation, ill-conditioned)."""


class SimulationDivergedError(IdentifiabilityError):
    """A fitted model, simulated from the flight's sticks alone, diverges (its rates leave every finite bound).

    The usual causes: an unmodelled servo delay (identify with ``--delay auto``), a log whose
    input column lags the response, or a log of an aircraft flown by a rate controller, whose
    recorded command is not the input of an open-loop plant.
    """


class NotFittedError(HeliError, ValueError, AttributeError):
    """An estimator was used before ``fit`` (as scikit-learn's ``NotFittedError``)."""


class DisturbanceError(HeliError, ValueError):
    """Disturbance identification cannot run as asked (Δt out of range, bad smoothing, axis without a control gain)."""


__all__ = ["DisturbanceError", "FlightLogError", "IdentifiabilityError", "NotFittedError", "SimulationDivergedError",
           "UnitError"]


__getattr__ = module_getattr(__name__)
"""The errors of other layers this module re-exported (deprecated: :mod:`identification._deprecated`)."""
