"""Errors of the model folder: its model file, its disturbance library, and a write in progress.

They derive from :class:`heli_core.errors.HeliError` and from ``ValueError``;
:mod:`identification.errors` re-exports them under the same names.
"""

from __future__ import annotations

from heli_core.errors import HeliError

__all__ = ["LibraryError", "ModelDirBusyError", "ModelDirError", "ModelFileError", "UnusableModelError"]


class ModelFileError(HeliError, ValueError):
    """A model file is missing, corrupt, of the wrong schema version or lacks parameters."""


class LibraryError(HeliError, ValueError):
    """A disturbance library is missing, corrupt, of an unknown version, or its traces do not match the manifest."""


class ModelDirError(ModelFileError):
    """A model directory is not one consistent state: an interrupted write that cannot be finished nor rolled
    back, an unreadable transaction journal, a committed model file that is missing or altered."""


class ModelDirBusyError(ModelDirError):
    """Another command is writing the model directory, and this one was asked not to wait (``--no-wait``)."""


class UnusableModelError(HeliError, ValueError):
    """A command was asked to build on a model whose verdict is ``unusable`` (:mod:`model_store.verdict`),
    without the option that accepts it."""
