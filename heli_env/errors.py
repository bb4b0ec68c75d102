"""Named exceptions of the environments.

Each derives from the package-wide root :class:`heli_core.errors.HeliError` and
from the standard exception a caller would otherwise catch.
"""

from __future__ import annotations

from heli_core.errors import HeliError


class EnvModelError(HeliError, ValueError):
    """A model directory cannot drive an environment (missing or corrupt model.json or disturbance library)."""


class ActionError(HeliError, ValueError):
    """An action is not a finite vector of the action space's shape."""


class OptionError(HeliError, ValueError):
    """A setting of an environment or an option of ``reset`` has the wrong type or lies outside its range."""
