"""The PD control law and its gains: :class:`PDGains` and the policy :class:`PDController`.

On the environment's observation (:class:`heli_env.env.HeliAttitudeEnv`) the
policy sets, per axis ``i`` (roll, pitch, yaw)::

    action_i = clip(s_i * (kp_i * obs[i] + kd_i * obs[6 + i]), -1, 1)

where ``obs[0:3]`` is the attitude error (reference - attitude) [rad],
``obs[6:9]`` the rate error (reference rate - rate) [rad/s], ``kp`` is in
stick/rad, ``kd`` in stick/(rad/s) and ``s_i`` = sign of the axis' control gain
(k2, k6, k10) so that positive gains stabilise (the paper's pitch gain k6 is
negative, eq. 69). The derivative is the *measured* rate error, not a finite
difference: on the continuous model the controller is exactly ``C(s) = s_i
(kp + kd s)`` acting on the attitude error, with no derivative filter.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from heli_core.files import jsonable, write_text
from heli_core.params import ModelParams
from heli_core.terms import AXES

from .law import _axis_index, control_sign, pd_command

SCHEMA = "heli-env/pd-controller"
SCHEMA_VERSION = 1
OBS_DIM = 12


@dataclass(frozen=True)
class PDGains:
    """Per-axis PD gains (roll, pitch, yaw).

    A scalar is broadcast to the three axes.

    Attributes
    ----------
    kp : tuple of 3 float
        Proportional gains on the attitude error [stick/rad], >= 0.
    kd : tuple of 3 float
        Derivative gains on the rate error [stick/(rad/s)], >= 0.
    """

    kp: tuple = (0.0, 0.0, 0.0)
    kd: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        for name in ("kp", "kd"):
            raw = getattr(self, name)
            try:
                v = np.broadcast_to(np.asarray(raw, dtype=float), (3,))
            except (TypeError, ValueError) as e:
                raise ValueError(f"{name} must be a number or 3 numbers (roll, pitch, yaw), got {raw!r}") from e
            if not np.all(np.isfinite(v)):
                raise ValueError(f"{name} must be finite, got {raw!r}")
            if np.any(v < 0):
                raise ValueError(f"{name} must be >= 0 (the control-gain sign is applied by the law), got {raw!r}")
            object.__setattr__(self, name, tuple(float(x) for x in v))

    def axis(self, axis) -> tuple[float, float]:
        """(kp, kd) of one axis."""
        i = _axis_index(axis)
        return self.kp[i], self.kd[i]


class PDController:
    """Discrete PD attitude policy with stable-baselines3's ``predict`` interface.

    Per step and axis ``action = clip(s * (kp * obs[0:3] + kd * obs[6:9]), -1, 1)``
    (see the module docstring): memoryless, so ``state`` is passed through and
    ``episode_start`` and ``deterministic`` are ignored. PD and RL agents go
    through one evaluator (``stable_baselines3.common.evaluation.evaluate_policy``).

    Parameters
    ----------
    gains : PDGains
    signs : sequence of 3 float
        Control-gain signs (+1 or -1) of roll, pitch, yaw; :meth:`from_model`
        takes them from the model's k2, k6, k10.
    """

    def __init__(self, gains: PDGains, signs=(1.0, 1.0, 1.0)):
        if not isinstance(gains, PDGains):
            raise ValueError(f"gains must be a PDGains, got {type(gains).__name__}")
        sg = np.asarray(signs, dtype=float)
        if sg.shape != (3,) or not np.all(np.abs(sg) == 1.0):
            raise ValueError(f"signs must be three values of +1 or -1 (roll, pitch, yaw), got {signs!r}")
        self.gains = gains
        self.signs = tuple(float(v) for v in sg)
        self._kp, self._kd, self._sign = np.array(gains.kp, dtype=float), np.array(gains.kd, dtype=float), sg

    @classmethod
    def from_model(cls, params: ModelParams, gains: PDGains) -> "PDController":
        """The controller for a model: signs of its control gains (k2, k6, k10)."""
        return cls(gains, [control_sign(params, a) for a in AXES])

    def __repr__(self):
        return f"PDController(kp={self.gains.kp}, kd={self.gains.kd}, signs={self.signs})"

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = False):
        """Actions for one observation ``(12,)`` or a batch ``(n, 12)``.

        Parameters
        ----------
        observation : array_like, shape (12,) or (n, 12)
            Observations of ``HeliAttitude-v0`` (attitude error [rad], rates
            [rad/s], rate error [rad/s], previous action).
        state, episode_start, deterministic
            SB3's interface; unused (the law has no memory).

        Returns
        -------
        action : ndarray of float32, shape (3,) or (n, 3)
            lat, lon, ped offsets from trim in [-1, 1].
        state
            ``state`` unchanged.
        """
        return np.clip(self.command(observation), -1.0, 1.0).astype(np.float32), state

    def command(self, observation) -> np.ndarray:
        """The unclipped command ``sign * (kp * attitude_error + kd * rate_error)`` [stick], float64,
        shape (3,) or (n, 3); :meth:`predict` clips it (a residual agent adds to it first)."""
        obs = np.asarray(observation, dtype=np.float64)
        if obs.ndim not in (1, 2) or obs.shape[-1] != OBS_DIM:
            raise ValueError(f"observation must have shape ({OBS_DIM},) or (n, {OBS_DIM}), got {obs.shape}")
        return pd_command(self._kp, self._kd, self._sign, obs[..., 0:3], obs[..., 6:9])  # the one PD law

    def document(self, metadata=None) -> dict:
        """The JSON document :meth:`save` writes."""
        return jsonable({
            "schema": SCHEMA, "schema_version": SCHEMA_VERSION,
            "law": "action = clip(sign * (kp * attitude_error + kd * rate_error), -1, 1) per axis",
            "axes": list(AXES), "kp": self.gains.kp, "kd": self.gains.kd, "signs": self.signs,
            "units": {"kp": "stick/rad", "kd": "stick/(rad/s)", "signs": "-"},
            "metadata": dict(metadata or {}),
        })

    def save(self, path, metadata=None) -> Path:
        """Write the controller as JSON, atomically. Returns the path.

        Parameters
        ----------
        path : str or Path
        metadata : dict, optional
            Stored as is (e.g. the model directory and the design margins).
        """
        return write_text(path, json.dumps(self.document(metadata), indent=2, allow_nan=False) + "\n")

    @classmethod
    def load(cls, path) -> "PDController":
        """Read a controller written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            No such file.
        ValueError
            Not a PD controller file, another schema version, or bad gains.
        """
        path = Path(path)
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: not a JSON PD controller file ({e})") from e
        if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
            got = doc.get("schema") if isinstance(doc, dict) else type(doc).__name__
            raise ValueError(f"{path}: expected schema {SCHEMA!r}, got {got!r}")
        if doc.get("schema_version") != SCHEMA_VERSION:
            raise ValueError(f"{path}: expected schema_version {SCHEMA_VERSION}, got {doc.get('schema_version')!r}")
        missing = [k for k in ("kp", "kd", "signs") if k not in doc]
        if missing:
            raise ValueError(f"{path}: missing {', '.join(missing)}")
        try:
            return cls(PDGains(doc["kp"], doc["kd"]), doc["signs"])
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from e
