"""Residual RL on a PD or LQG controller: ``action = clip(base(obs) + scale · π(obs), -1, 1)``.

Residual policy learning (Silver et al. 2018, "Residual Policy Learning";
Johannink et al. 2019, "Residual Reinforcement Learning for Robot Control"): the
agent learns a bounded correction on top of a working controller instead of the
whole control law. Here the base is a :class:`controllers.pd.PDController`,
typically a pair from a gain sweep, or the LQG baseline
(:class:`controllers.lqg.controller.LQGController`, whose Kalman filters are told
the stick the aircraft got, correction included: :func:`base_applied`), and the
policy is a PPO or SAC network whose action in [-1, 1] is scaled to ±``scale`` stick.

Why it is needed here: swept PDs of the shipped model hold attitude to a few
thousandths of a degree (p90) with gains of hundreds to thousands of stick/rad.
A policy learnt from scratch has to reproduce such a law closely before it can
improve on it, which PPO does not reach in 15 minutes on 2 cores (0.2–1.1° p90).
A residual starts at the PD (the policy's output layer starts near zero) and only
has to learn what the PD lacks; the observation carries the previous action, so a
correction that behaves like integral action is within its reach.

The scales of training follow the base's own error level, measured by flying it
on windows of the training gusts (:func:`controllers.rl.train.residual_setup`), so
the same settings carry over to a model whose PD errors are degrees rather than
hundredths:

* reward: attitude errors scaled by ``2·E_i`` and rate errors by ``2·E_i·ω_c``, where
  ``E_i`` is the base's p90 |attitude error| on axis ``i`` (at least a tenth of the
  largest, ``E``; with ``axis_balance=False`` every axis takes ``E``) and ``ω_c`` the
  largest ``kp/kd`` of its axes (the PD's corner frequency, where a rate error
  weighs as much as an attitude error in its own command; for an LQG base its p90 rate error over its
  p90 attitude error, the largest of its axes); written as
  ``attitude_scale = 2·E`` with ``axis_weights = (E/E_i)²``;
* observations (:class:`controllers.sb3_training.ObservationScaler`): attitude
  errors by ``4·E_i``, rates and rate errors by ``4·E_i·ω_c``, the previous action by
  ``1.5 ×`` the base's largest p99 |stick| (at least 0.05);
* starts: roll and pitch within ±0.5°, rates within ±0.5°/s (the regime the base
  holds; a 5° start would dominate rewards scaled to hundredths of a degree).

The saved agent is the SB3 zip with the base PD and the scale inside its
``heli_agent.json`` (:func:`residual_metadata`); :func:`controllers.rl.load_agent`
returns a :class:`ResidualAgent`, which ``heli evaluate`` flies like any agent.
"""

from __future__ import annotations

import numpy as np

from ..errors import AgentError
from ..pd.controller import PDController

RESIDUAL_SCALE = 0.3
"""Default bound of the residual [stick]: the policy's action in [-1, 1] times this. 0.05 left the residual
too little room where the robust PD is near its best (pitch); with 0.15 the best swept pair's roll command
differed from the robust PD's by more than the bound 57 % of the time, and 0.3 flew closer to the best PD on
every axis in the seed x held-out-trace cells of docs/controllers.md (sixth session)."""
RESIDUAL_INIT_DEG = 0.5
"""Default initial roll/pitch range [deg] and rate range [deg/s] of residual training episodes."""


def as_base(base, name: str = "residual"):
    """A base controller from a :class:`PDController`, an :class:`~controllers.lqg.controller.LQGController`
    or the path of either's JSON (``heli design``, ``heli design --lqg``, a sweep); ``name`` is the setting's,
    for the messages.

    Raises
    ------
    AgentError
        Anything else, or a file that is neither controller.
    """
    from ..lqg.controller import SCHEMA as LQG_SCHEMA
    from ..lqg.controller import LQGController

    if isinstance(base, (PDController, LQGController)):
        return base
    if isinstance(base, (str, bytes)) or hasattr(base, "__fspath__"):
        try:
            if _schema_of(base) == LQG_SCHEMA:
                return LQGController.load(base)
            return PDController.load(base)
        except (ValueError, UnicodeDecodeError) as e:  # AgentError is a ValueError
            raise AgentError(f"{name} must be a PD controller JSON or an LQG controller JSON: {e}") from e
    raise AgentError(f"{name} must be a PDController or the path of a PD controller JSON, or an LQGController or "
                     f"its JSON, got {base!r}")


def _schema_of(path) -> str | None:
    """The ``schema`` entry of a JSON file, None when it is not JSON or has none (its loader then says why)."""
    import json
    from pathlib import Path

    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None
    return doc.get("schema") if isinstance(doc, dict) else None


def base_from_document(doc: dict):
    """The base controller of a residual's metadata entry (:meth:`document` of a PD or an LQG)."""
    from ..lqg.controller import SCHEMA as LQG_SCHEMA
    from ..lqg.controller import LQGController

    if isinstance(doc, dict) and doc.get("schema") == LQG_SCHEMA:
        return LQGController.from_document(doc)
    return PDController.from_document(doc)


def has_memory(base) -> bool:
    """Whether the base carries a state from one period to the next (an LQG's filters, a PD's D filter)."""
    return not isinstance(base, PDController) or base.filtered


def base_step(base, observation, state=None, episode_start=None):
    """The base's command and its new state for ``observation`` (12,) or (n, 12).

    A PD's is :meth:`PDController.step` (unclipped); an LQG's is its ``predict`` (clipped, float64 here).
    After the residual is added, pass the state through :func:`base_applied`, so that an LQG's filter
    predicts with the stick the aircraft got.
    """
    if isinstance(base, PDController):
        return base.step(observation, state, episode_start)
    command, state = base.predict(observation, state, episode_start)
    return np.asarray(command, dtype=np.float64), state


def base_applied(base, state, command, applied):
    """The base's state after the aircraft got ``applied`` instead of the base's own ``command``.

    An LQG predicts its next state with its own stick (``x_p = A x_f + B u``); with a residual on top the
    aircraft got another, and without this correction the filter would read the residual's effect as a
    gust and work against it. A PD's state (its D filter's) does not depend on the stick.
    """
    if isinstance(base, PDController) or state is None:
        return state
    return state + (np.asarray(applied, dtype=np.float64) - command) @ _input_matrix(base)


def _input_matrix(lqg) -> np.ndarray:
    """(3, n_states): how each stick enters an LQG's stacked filter states (the axes' ``B`` blocks, in the
    order of :class:`~controllers.lqg.controller.LQGController`'s state)."""
    cached = getattr(lqg, "_residual_input_matrix", None)
    if cached is None:
        cached = np.zeros((3, lqg.n_states))
        start = 0
        for i, a in enumerate(lqg.axes):
            n = a["A"].shape[0]
            cached[i, start:start + n] = a["B"][:, 0]
            start += n
        lqg._residual_input_matrix = cached
    return cached


def check_scale(scale) -> float:
    """The residual bound as a float in (0, 2]; AgentError otherwise."""
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not (0.0 < scale <= 2.0):
        raise AgentError(f"residual_scale must be a number in (0, 2] stick, got {scale!r}")
    return float(scale)


class ResidualAgent:
    """A PD controller plus a learnt, bounded correction, with SB3's ``predict`` interface.

    Parameters
    ----------
    base : PDController or LQGController
        The controller the residual corrects (:func:`as_base`).
    policy : object with SB3's ``predict``
        The residual policy (a PPO or SAC model); its action in [-1, 1] is scaled by ``scale``.
    scale : float
        Bound of the residual [stick].
    history : int
        Observations the policy sees, the newest last (1: the current one). With more than one the
        agent keeps them in ``predict``'s ``state`` as SB3's ``VecFrameStack`` stacks them in training
        (zeros before an episode's first observation); pass ``episode_start`` at each episode's first
        step, as SB3's ``evaluate_policy`` and :func:`controllers.evaluate.evaluate_agent` do.

    A base with a memory (an LQG's filters, a PD's derivative filter) keeps its state beside the policy's:
    ``state`` is then the pair ``(policy or history state, base state)``.
    """

    def __init__(self, base: PDController, policy, scale: float = RESIDUAL_SCALE, history: int = 1):
        self.base, self.policy, self.scale = base, policy, check_scale(scale)
        self.history = check_history(history)

    def __repr__(self):
        seen = f", {self.history} observations" if self.history > 1 else ""
        return f"ResidualAgent({type(self.policy).__name__} ±{self.scale:g} stick on {self.base!r}{seen})"

    def describe(self) -> tuple[str, str]:
        """(kind, description) for reports (:func:`controllers.evaluate.describe_agent`): the policy's kind with
        "-residual", and the correction's bound on the base's description."""
        from ..agent_description import describe_agent

        kind, desc = describe_agent(self.policy)
        return f"{kind}-residual", f"{desc} ±{self.scale:g} stick on {describe_agent(self.base)[1]}"

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = False):
        """Actions for one observation ``(12,)`` or a batch ``(n, 12)``: the PD's command plus the
        scaled residual, clipped to [-1, 1]. ``state`` and ``episode_start`` go to the policy, or with
        ``history`` > 1 carry the stacked observations (returned as the new ``state``)."""
        obs = np.asarray(observation, dtype=np.float64)
        seen = np.asarray(observation, dtype=np.float32)
        d_state = None
        memory = has_memory(self.base)
        if memory and state is not None:
            state, d_state = state
        if self.history > 1:
            state = stack_observations(seen, state, episode_start, self.history)
            seen, policy_state = (state[0] if obs.ndim == 1 else state), None
        else:
            policy_state = state
        residual, policy_state = self.policy.predict(seen, policy_state, episode_start, deterministic)
        command, d_state = base_step(self.base, obs, d_state, episode_start)
        act = np.clip(command + self.scale * np.clip(residual, -1.0, 1.0), -1.0, 1.0)
        d_state = base_applied(self.base, d_state, command, act)
        state = state if self.history > 1 else policy_state
        return act.astype(np.float32), ((state, d_state) if memory else state)


def check_history(history) -> int:
    """The number of stacked observations as an int in [1, 16]; AgentError otherwise."""
    if isinstance(history, bool) or not isinstance(history, (int, np.integer)) or not 1 <= history <= 16:
        raise AgentError(f"history must be a whole number of observations in [1, 16], got {history!r}")
    return int(history)


def stack_observations(obs, stacked, episode_start, history: int) -> np.ndarray:
    """The last ``history`` observations side by side, newest last, as SB3's ``VecFrameStack`` keeps them.

    ``obs`` (12,) or (n, 12); ``stacked`` the previous result (n, 12·history) or None; rows where
    ``episode_start`` is true (and all rows when ``stacked`` is None) start again from zeros.
    """
    obs = np.atleast_2d(obs)
    n, d = obs.shape
    if stacked is None or np.shape(stacked) != (n, d * history):
        out = np.zeros((n, d * history), dtype=np.float32)
    else:
        out = np.roll(np.asarray(stacked, dtype=np.float32), -d, axis=1)
        if episode_start is not None:
            out[np.asarray(episode_start, dtype=bool).reshape(n)] = 0.0
    out[:, -d:] = obs
    return out


def residual_env(venv, base, scale: float, paired: bool = False):
    """SB3 ``VecEnv`` whose action is the residual: the base's (a PD's or an LQG's) command on the last observation plus
    ``scale`` times the action, clipped to [-1, 1], is what the wrapped env receives.

    With ``paired=True``, ``venv`` is a :class:`controllers.rl.vec_env.GymnasiumVecEnv` with
    ``twins=True`` (2h copies) and the wrapper shows its first h copies: copy ``h + i``, the twin of
    copy ``i`` (same gusts, start and sensor noise), flies the base PD alone, and copy ``i``'s reward
    is its own minus its twin's — what the residual gained over the PD on the same gust. The gust's
    share of the return, which no observation predicts and which left PPO's value function
    explaining nothing of the returns, cancels; the twin's reward does not depend on the residual's
    actions, so the policy gradient keeps its expectation (a control variate). Observations, episode
    ends and infos are copy ``i``'s.
    """
    from stable_baselines3.common.vec_env import VecEnvWrapper
    from stable_baselines3.common.vec_env.base_vec_env import VecEnv

    if paired and not getattr(venv, "twins", False):
        raise AgentError("a paired residual needs a GymnasiumVecEnv with twins=True")
    half = venv.num_envs // 2 if paired else venv.num_envs

    class ResidualVecEnv(VecEnvWrapper):
        def __init__(self):
            super().__init__(venv)
            if paired:  # SB3 sees the first half; the wrapper's own bookkeeping is per shown copy
                VecEnv.__init__(self, half, venv.observation_space, venv.action_space)
            self._obs = None
            self._filter, self._starts = None, None  # the base's derivative filter state, copies just reset

        def reset(self):
            self._obs = self.venv.reset()
            self._filter = self._starts = None
            return self._obs[:half]

        def step_async(self, actions):
            command, self._filter = base_step(base, np.asarray(self._obs, dtype=np.float64), self._filter,
                                              self._starts)
            act = command[:half] + scale * np.clip(actions, -1.0, 1.0)
            if paired:
                act = np.concatenate([act, command[half:]])
            act = np.clip(act, -1.0, 1.0)
            self._filter = base_applied(base, self._filter, command, act)
            self.venv.step_async(act.astype(np.float32))

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            self._obs = obs  # after a done: the next episode's first observation, what the next action sees
            self._starts = np.asarray(dones, dtype=bool)  # those copies' filters restart at it
            if paired:
                rewards = (rewards[:half] - rewards[half:]).astype(np.float32)
            return obs[:half], rewards, dones[:half], infos[:half]

    return ResidualVecEnv()


def residual_metadata(base: PDController, scale: float, setup: dict, history: int = 1) -> dict:
    """What a residual agent's ``heli_agent.json`` carries under ``"residual"``."""
    return {"base": base.document(), "scale": scale, "setup": setup, "history": history}


def residual_from_metadata(meta: dict, policy, path) -> ResidualAgent:
    """The :class:`ResidualAgent` of a loaded policy and its metadata's ``"residual"`` entry.

    Raises
    ------
    AgentError
        The entry lacks the base PD or the scale, or they are malformed.
    """
    entry = meta.get("residual")
    try:
        base = base_from_document(entry["base"])
        return ResidualAgent(base, policy, entry["scale"], entry.get("history", 1))
    except (TypeError, KeyError, ValueError, AgentError) as e:
        raise AgentError(f"{path}: the residual entry of its metadata is not a base PD and a scale ({e!r})") from e


__all__ = ["RESIDUAL_INIT_DEG", "RESIDUAL_SCALE", "ResidualAgent", "as_base", "base_applied", "base_from_document",
           "base_step", "check_history", "check_scale", "has_memory",
           "residual_env", "residual_from_metadata", "residual_metadata", "stack_observations"]
