"""Named exceptions of the environments."""

from __future__ import annotations


class EnvModelError(ValueError):
    """A model directory cannot drive an environment (missing or corrupt model.json or disturbance library)."""


class ActionError(ValueError):
    """An action is not a finite vector of the action space's shape."""
