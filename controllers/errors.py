"""Named exceptions of the controllers package.

Like :mod:`identification.errors`, each subclasses the standard exception a
caller would otherwise catch and says what was expected and what came.
"""

from __future__ import annotations


class SweepError(ValueError):
    """A gain sweep cannot run as asked (empty, non-finite, reversed or negative gain range, bad axis,
    duration longer than the disturbance traces, missing model directory)."""


class AgentError(ValueError):
    """An agent cannot be trained, loaded or evaluated as asked (unknown algorithm, bad timesteps or
    frequencies, an agent file that is neither a PD controller JSON nor a PPO/SAC zip, episodes longer
    than the gust segments)."""


class DesignError(ValueError):
    """A PD design cannot meet the request (bandwidth beyond what the phase margin allows); the message
    says what is achievable."""


class TrainingInterrupted(KeyboardInterrupt):
    """Training was interrupted (Ctrl-C); ``checkpoint`` is the model saved at that moment."""

    def __init__(self, checkpoint, timesteps: int):
        super().__init__(f"training interrupted after {timesteps} timesteps; saved {checkpoint}")
        self.checkpoint = checkpoint
        self.timesteps = timesteps
