"""What an agent is, in words, for reports: asked of the agent.

Every controller the evaluator flies says what it is through a ``describe()`` method returning ``(kind,
description)`` — the PD its gains, the LQG its states, a residual its policy and base, a firmware loop its
firmware and rate — so that reports never test for classes; an agent without one (an SB3 model) is named by its
class. A leaf of the controllers package: the agents' own modules import it (a residual describes its parts).
"""

from __future__ import annotations


def describe_agent(agent) -> tuple[str, str]:
    """(kind, description) of an agent, asked of the agent: its ``describe()`` returns the pair (the PD's
    ("pd", "PD kp=.. kd=.."), the LQG's ("lqg", "LQG (Kalman filter + LQR, 11/11/11 states)"), a residual's
    ("ppo-residual", "PPO ±0.05 stick on PD kp=.. kd=.."), a firmware loop's ...); an agent without one (an SB3
    model) is named by its class: ("ppo", "PPO")."""
    describe = getattr(agent, "describe", None)
    if callable(describe):
        kind, description = describe()
        return str(kind), str(description)
    return type(agent).__name__.lower(), type(agent).__name__
