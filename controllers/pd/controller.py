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
(kp + kd s)`` acting on the attitude error.

With a derivative filter (``PDGains.d_filter_hz``) the rate error passes a
first-order low-pass of that cutoff before ``kd`` (sampled at the controller's
``dt``, :func:`controllers.pd.law.filtered_rate`), ``C(s) = s_i (kp + kd s / (1 + tau s))``:
the gyro noise and the gusts' fast part no longer reach the stick at full ``kd``.
The filter's state travels in ``predict``'s ``state`` (shape of ``obs[..., 6:9]``), as a
recurrent policy's does in stable-baselines3, and restarts where ``episode_start`` is true.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from heli_core.files import jsonable, write_text
from heli_core.params import ModelParams
from heli_core.terms import AXES

from .law import _axis_index, check_cutoff, control_sign, derivative_pole, filtered_rate, pd_command

SCHEMA = "heli-env/pd-controller"
SCHEMA_VERSION = 2
"""Written for a controller with a derivative filter; one without is written as version 1, which every
reader of this schema takes (a reader that knows no filter refuses version 2 instead of flying it unfiltered)."""
OBS_DIM = 12
DT = 0.01
"""Control period [s] a controller's derivative filter is sampled at unless told (the environment's)."""


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
    d_filter_hz : tuple of 3 (float or None)
        Cutoff of each axis' derivative low-pass [Hz], > 0; None: no filter (the default, on every axis).
        One value is broadcast to the three axes.
    """

    kp: tuple = (0.0, 0.0, 0.0)
    kd: tuple = (0.0, 0.0, 0.0)
    d_filter_hz: tuple = (None, None, None)

    def __post_init__(self):
        raw = self.d_filter_hz
        cut = [raw] * 3 if raw is None or np.ndim(raw) == 0 else list(raw)
        if len(cut) != 3:
            raise ValueError(f"d_filter_hz must be None, a cutoff in Hz or 3 of them (roll, pitch, yaw), got {raw!r}")
        object.__setattr__(self, "d_filter_hz", tuple(check_cutoff(c) for c in cut))
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

    @property
    def filtered(self) -> bool:
        """Whether any axis has a derivative filter."""
        return any(c is not None for c in self.d_filter_hz)


class PDController:
    """Discrete PD attitude policy with stable-baselines3's ``predict`` interface.

    Per step and axis ``action = clip(s * (kp * obs[0:3] + kd * y), -1, 1)`` with ``y``
    the rate error ``obs[6:9]``, low-passed where the gains carry a derivative filter (see the
    module docstring). Without a filter the law is memoryless: ``state`` is passed through and
    ``episode_start`` ignored. PD and RL agents go through one evaluator
    (``stable_baselines3.common.evaluation.evaluate_policy``, :func:`controllers.evaluate.evaluate_agent`).

    Parameters
    ----------
    gains : PDGains
    signs : sequence of 3 float
        Control-gain signs (+1 or -1) of roll, pitch, yaw; :meth:`from_model`
        takes them from the model's k2, k6, k10.
    dt : float
        Control period [s] the derivative filter is sampled at (the environment's step), > 0.
    """

    def __init__(self, gains: PDGains, signs=(1.0, 1.0, 1.0), dt: float = DT):
        if not isinstance(gains, PDGains):
            raise ValueError(f"gains must be a PDGains, got {type(gains).__name__}")
        sg = np.asarray(signs, dtype=float)
        if sg.shape != (3,) or not np.all(np.abs(sg) == 1.0):
            raise ValueError(f"signs must be three values of +1 or -1 (roll, pitch, yaw), got {signs!r}")
        if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and 0 < dt < 1):
            raise ValueError(f"dt must be a control period in (0, 1) s, got {dt!r}")
        self.gains = gains
        self.signs = tuple(float(v) for v in sg)
        self.dt = float(dt)
        self._kp, self._kd, self._sign = np.array(gains.kp, dtype=float), np.array(gains.kd, dtype=float), sg
        self._poles = np.array([derivative_pole(c, self.dt) for c in gains.d_filter_hz])

    @classmethod
    def from_model(cls, params: ModelParams, gains: PDGains, dt: float = DT) -> "PDController":
        """The controller for a model: signs of its control gains (k2, k6, k10)."""
        return cls(gains, [control_sign(params, a) for a in AXES], dt)

    @property
    def filtered(self) -> bool:
        """Whether the D term of any axis is low-passed (the law then has memory)."""
        return self.gains.filtered

    def __repr__(self):
        cut = f", d_filter_hz={self.gains.d_filter_hz}, dt={self.dt:g}" if self.filtered else ""
        return f"PDController(kp={self.gains.kp}, kd={self.gains.kd}, signs={self.signs}{cut})"

    def describe(self) -> tuple[str, str]:
        """(kind, description) for reports (:func:`controllers.evaluate.describe_agent`): "pd" and the gains."""
        kp = ", ".join(f"{v:.3g}" for v in self.gains.kp)
        kd = ", ".join(f"{v:.3g}" for v in self.gains.kd)
        cut = ", ".join("none" if v is None else f"{v:.3g}" for v in self.gains.d_filter_hz)
        return "pd", f"PD kp=({kp}) kd=({kd})" + (f" D-filter=({cut}) Hz" if self.filtered else "")

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = False):
        """Actions for one observation ``(12,)`` or a batch ``(n, 12)``.

        Parameters
        ----------
        observation : array_like, shape (12,) or (n, 12)
            Observations of ``HeliAttitude-v0`` (attitude error [rad], rates
            [rad/s], rate error [rad/s], previous action).
        state : ndarray, shape (3,) or (n, 3), optional
            With a derivative filter: the filtered rate errors of the previous period [rad/s], as the
            last call returned them; None: every episode starts now. Without one: passed through.
        episode_start : array_like of bool, shape (n,), optional
            Copies whose episode starts at this observation: their filter restarts (SB3's meaning).
        deterministic
            SB3's interface; unused (the law is deterministic).

        Returns
        -------
        action : ndarray of float32, shape (3,) or (n, 3)
            lat, lon, ped offsets from trim in [-1, 1].
        state
            With a filter: the new filter state (pass it back next period); without one ``state`` unchanged.
        """
        if not self.filtered:
            return np.clip(self.command(observation), -1.0, 1.0).astype(np.float32), state
        command, state = self.step(observation, state, episode_start)
        return np.clip(command, -1.0, 1.0).astype(np.float32), state

    def command(self, observation) -> np.ndarray:
        """The unclipped command of the unfiltered law ``sign * (kp * attitude_error + kd * rate_error)``
        [stick], float64, shape (3,) or (n, 3); :meth:`predict` clips it (:meth:`step` is the law with the
        filter)."""
        obs = self._checked(observation)
        return pd_command(self._kp, self._kd, self._sign, obs[..., 0:3], obs[..., 6:9])  # the one PD law

    def step(self, observation, state=None, episode_start=None):
        """The unclipped command with the derivative filter, and the filter's new state.

        Parameters and ``state`` as :meth:`predict`. Returns ``(command, state)``: float64 of shape
        (3,) or (n, 3) [stick], and the filtered rate errors [rad/s] (None without a filter, where
        the command is :meth:`command`'s). A residual agent adds its correction to this command.
        """
        obs = self._checked(observation)
        if not self.filtered:
            return pd_command(self._kp, self._kd, self._sign, obs[..., 0:3], obs[..., 6:9]), None
        e_rate = obs[..., 6:9]
        previous, start = self._memory(state, episode_start, e_rate.shape)
        y = np.where(self._poles > 0, filtered_rate(previous, e_rate, self._poles, start), e_rate)
        return pd_command(self._kp, self._kd, self._sign, obs[..., 0:3], y), y

    @staticmethod
    def _checked(observation) -> np.ndarray:
        obs = np.asarray(observation, dtype=np.float64)
        if obs.ndim not in (1, 2) or obs.shape[-1] != OBS_DIM:
            raise ValueError(f"observation must have shape ({OBS_DIM},) or (n, {OBS_DIM}), got {obs.shape}")
        return obs

    @staticmethod
    def _memory(state, episode_start, shape):
        """(previous filter output or None, per-row restart mask or None) for rate errors of ``shape``."""
        if state is None:
            return None, None
        previous = np.asarray(state, dtype=np.float64)
        if previous.shape != shape:
            raise ValueError(f"state must be the filter state the last predict returned, shape {shape}, got "
                             f"{previous.shape} (pass state=None at the first observation)")
        if episode_start is None:
            return previous, None
        start = np.asarray(episode_start, dtype=bool).reshape(-1)
        rows = shape[0] if len(shape) == 2 else 1
        if start.size != rows:
            raise ValueError(f"episode_start must hold one flag per observation ({rows}), got {start.size}")
        return previous, (start[:, None] if len(shape) == 2 else bool(start[0]))

    def document(self, metadata=None) -> dict:
        """The JSON document :meth:`save` writes (schema version 1 without a filter, 2 with one)."""
        doc = {"schema": SCHEMA, "schema_version": SCHEMA_VERSION if self.filtered else 1,
               "law": "action = clip(sign * (kp * attitude_error + kd * rate_error), -1, 1) per axis",
               "axes": list(AXES), "kp": self.gains.kp, "kd": self.gains.kd, "signs": self.signs,
               "units": {"kp": "stick/rad", "kd": "stick/(rad/s)", "signs": "-"}}
        if self.filtered:
            doc["law"] = ("action = clip(sign * (kp * attitude_error + kd * y), -1, 1) per axis, y = a * y_prev "
                          "+ (1 - a) * rate_error, a = exp(-2 pi d_filter_hz dt) (y = rate_error at an episode's "
                          "start; no filter where d_filter_hz is null)")
            doc.update(d_filter_hz=self.gains.d_filter_hz, dt=self.dt)
            doc["units"].update(d_filter_hz="Hz", dt="s")
        doc["metadata"] = dict(metadata or {})
        return jsonable(doc)

    @classmethod
    def from_document(cls, doc: dict) -> "PDController":
        """The controller of a :meth:`document` (KeyError for a missing entry, ValueError for a bad one)."""
        if doc.get("schema_version", 1) == 1:
            return cls(PDGains(doc["kp"], doc["kd"]), doc["signs"])
        return cls(PDGains(doc["kp"], doc["kd"], doc["d_filter_hz"]), doc["signs"], doc["dt"])

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
        version = doc.get("schema_version")
        if version not in (1, SCHEMA_VERSION):
            raise ValueError(f"{path}: expected schema_version 1 or {SCHEMA_VERSION}, got {version!r}")
        missing = [k for k in ("kp", "kd", "signs") + (("d_filter_hz", "dt") if version == 2 else ()) if k not in doc]
        if missing:
            raise ValueError(f"{path}: missing {', '.join(missing)}")
        try:
            return cls.from_document(doc)
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from e
