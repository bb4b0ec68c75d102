"""Named exceptions of the controllers package.

Like :mod:`identification.errors`, each derives from the package-wide root
:class:`heli_core.errors.HeliError` and from the standard exception a caller
would otherwise catch, and says what was expected and what came.

:class:`TrainingInterrupted` is the exception: it is a ``KeyboardInterrupt``, not
an error, and stays outside ``HeliError`` (which is an ``Exception``), so that an
``except Exception`` or ``except HeliError`` never swallows a Ctrl-C.
"""

from __future__ import annotations

from heli_core.errors import HeliError


class SweepError(HeliError, ValueError):
    """A gain sweep cannot run as asked (empty, non-finite, reversed or negative gain range, bad axis,
    duration longer than the disturbance traces, missing model directory)."""


class AgentError(HeliError, ValueError):
    """An agent cannot be trained, loaded or evaluated as asked (unknown algorithm, bad timesteps or
    frequencies, an agent file that is neither a PD controller JSON nor a PPO/SAC zip, episodes longer
    than the gust segments)."""


class DesignError(HeliError, ValueError):
    """A PD or LQG design cannot meet the request (bandwidth beyond what the phase margin allows, margins no
    recovery weight keeps, a model without the identified wind model, bad weights); the message says what is
    achievable or what is missing."""


class TrainingInterrupted(KeyboardInterrupt):
    """Training was interrupted (Ctrl-C); ``checkpoint`` is the model saved at that moment."""

    def __init__(self, checkpoint, timesteps: int):
        super().__init__(f"training interrupted after {timesteps} timesteps; saved {checkpoint}")
        self.checkpoint = checkpoint
        self.timesteps = timesteps
