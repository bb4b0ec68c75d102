"""Named exceptions of the identification package.

Every error says what was expected and what came, so a user can fix the input
without reading a traceback. They subclass the standard exception that a
caller would otherwise catch (``ValueError``, ``ImportError``).
"""

from __future__ import annotations


class FlightLogError(ValueError):
    """A flight log or in-memory flight is malformed (columns, NaNs, time base, units, ranges)."""


class UnitError(FlightLogError):
    """A column is in another unit than the canonical one (deg/s for rad/s, ms for s, PWM us for [-1, 1]).

    The message names the suspected unit and the conversion that fixes it.
    """


class IdentifiabilityError(ValueError):
    """The data cannot determine the requested parameters (too short, no excitation, ill-conditioned)."""


class SimulationDivergedError(IdentifiabilityError):
    """A fitted model, simulated from the flight's sticks alone, diverges (its rates leave every finite bound).

    The usual causes: an unmodelled servo delay (identify with ``--delay auto``), a log whose
    input column lags the response, or a log of an aircraft flown by a rate controller, whose
    recorded command is not the input of an open-loop plant.
    """


class ModelFileError(ValueError):
    """A model file is missing, corrupt, of the wrong schema version or lacks parameters."""


class NotFittedError(ValueError, AttributeError):
    """An estimator was used before ``fit`` (as scikit-learn's ``NotFittedError``)."""


class MissingDependency(ImportError):
    """An optional dependency (an extra of ``heli-env``) is not installed."""


def require(module: str, extra: str):
    """Import an optional module lazily, naming the extra that provides it.

    Parameters
    ----------
    module : str
        Importable module name, e.g. ``"pyulog"``.
    extra : str
        The ``heli-env`` extra that installs it, e.g. ``"logs"``.
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise MissingDependency(
            f"'{module}' is needed for this and is not installed; "
            f"install it with: pip install 'heli-env[{extra}]'"
        ) from e


class DisturbanceError(ValueError):
    """Disturbance identification cannot run as asked (Δt out of range, bad smoothing, axis without a control gain)."""


class LibraryError(ValueError):
    """A disturbance library is missing, corrupt, of an unknown version, or its traces do not match the manifest."""


class BackendError(ValueError):
    """A compute backend cannot be made as asked (unknown name, a worker count < 1, bad retry settings)."""


class TaskFailed(RuntimeError):
    """A task of a backend could not finish: its worker died more often than the retries allow.

    ``index`` is the task's position among the mapped items.
    """

    def __init__(self, message: str, index: int = -1):
        super().__init__(message)
        self.index = index
