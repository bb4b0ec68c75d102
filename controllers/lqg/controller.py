"""The LQG attitude policy: a Kalman filter per axis and its regulator, behind stable-baselines3's ``predict``.

Per control period and axis, on the environment's observation (:class:`heli_env.env.HeliAttitudeEnv`)::

    y   = -(obs[i], obs[6 + i])            angle and rate in the airframe's signs (attitude hold: the
                                           observation holds reference - angle and reference rate - rate)
    x_f = x_p + M (y - C x_p)              the filter's update with this period's observation
    u   = clip(-K x_f, -1, 1)              the stick offset from trim, the action
    x_p = A x_f + B u                      the prediction for the next period, with the stick applied

``A``, ``B``, ``C``, ``K``, ``M`` are the axis' design (:mod:`controllers.lqg.design`); the prediction uses the
clipped stick, the one the aircraft gets, so a saturated stick does not wind the estimate up. The
estimates ``x_p`` of every axis travel in ``predict``'s ``state`` (shape ``(n, n_states)``), as a recurrent
policy's memory does in stable-baselines3; where ``episode_start`` is true (or with ``state=None``) an
episode starts from the prior: every state zero (level, at rest, servos on the trim, no gust, no line).
The law is deterministic: the same observations give the same actions, whatever ``deterministic`` says.

The design reads errors as the negatives of the state, which holds in the attitude hold the environment's
"hold" task asks for; under "track" or "rate" references the reference's motion enters the filter as a gust
would.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from heli_core.files import jsonable, write_text
from heli_core.terms import AXES

from ..errors import AgentError

SCHEMA = "heli-env/lqg-controller"
SCHEMA_VERSION = 1
OBS_DIM = 12
MEASURED = (0, 6, 1, 7, 2, 8)
"""Observation entries the filters read, in the order of ``y``: (attitude error, rate error) per axis."""


class LQGController:
    """Per-axis steady-state Kalman filter and LQR gain with stable-baselines3's ``predict`` interface.

    Parameters
    ----------
    axes : sequence of 3 dict
        Roll, pitch, yaw: each with ``A`` (n, n), ``B`` (n, 1), ``C`` (2, n), ``K`` (1, n), ``M`` (n, 2)
        (module docstring) and ``states`` (n names).
    dt : float
        The control period the matrices are sampled at [s] (the environment's step), in (0, 1).

    Raises
    ------
    AgentError
        Missing or mis-shaped matrices, non-finite entries, or a bad ``dt``.
    """

    def __init__(self, axes, dt: float = 0.01):
        if not (isinstance(dt, (int, float, np.floating)) and not isinstance(dt, bool) and np.isfinite(dt)
                and 0 < dt < 1):
            raise AgentError(f"dt must be a control period in (0, 1) s, got {dt!r}")
        axes = list(axes) if not isinstance(axes, (str, bytes, dict)) else []
        if len(axes) != 3:
            raise AgentError(f"axes must hold 3 axis designs (roll, pitch, yaw), got {len(axes)}")
        self.dt = float(dt)
        self.axes = tuple(_checked_axis(a, name) for a, name in zip(axes, AXES))
        sizes = [a["A"].shape[0] for a in self.axes]
        self.n_states = int(sum(sizes))
        N = self.n_states
        A, B, F, Mg, K = np.zeros((N, N)), np.zeros((N, 3)), np.zeros((N, N)), np.zeros((N, 6)), np.zeros((3, N))
        start = 0
        for i, (a, n) in enumerate(zip(self.axes, sizes)):
            s = slice(start, start + n)
            A[s, s] = a["A"]
            B[s, i] = a["B"][:, 0]
            F[s, s] = np.eye(n) - a["M"] @ a["C"]
            Mg[s, 2 * i:2 * i + 2] = a["M"]
            K[i, s] = a["K"][0]
            start += n
        # row-vector forms: x_f = x_p F' + y M', u = -x_f K', x_p = x_f A' + u B'
        self._Ft, self._Mt, self._Kt, self._At, self._Bt = F.T.copy(), Mg.T.copy(), K.T.copy(), A.T.copy(), B.T.copy()

    @classmethod
    def from_design(cls, design) -> "LQGController":
        """The policy of a :class:`controllers.lqg.design.LQGDesign`."""
        axes = [{"A": a.model.A, "B": a.model.B, "C": a.model.C, "K": a.K, "M": a.M, "states": a.model.states}
                for a in design.axes]
        return cls(axes, design.dt)

    def __repr__(self):
        return f"LQGController(states={[len(a['states']) for a in self.axes]}, dt={self.dt:g})"

    def describe(self) -> tuple[str, str]:
        """(kind, description) for reports (:func:`controllers.evaluate.describe_agent`): "lqg" and its states."""
        states = "/".join(str(len(a["states"])) for a in self.axes)
        return "lqg", f"LQG (Kalman filter + LQR, {states} states)"

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = False):
        """Actions for one observation ``(12,)`` or a batch ``(n, 12)``, and the filters' next state.

        Parameters
        ----------
        observation : array_like, shape (12,) or (n, 12)
            Observations of ``HeliAttitude-v0`` (attitude error [rad], rates [rad/s], rate error [rad/s],
            previous action).
        state : ndarray, shape (n_states,) or (n, n_states), optional
            The filters' predicted states as the last call returned them; None: every episode starts now.
        episode_start : array_like of bool, shape (n,), optional
            Copies whose episode starts at this observation: their filters restart from the prior.
        deterministic
            SB3's interface; unused (the law is deterministic).

        Returns
        -------
        action : ndarray of float32, shape (3,) or (n, 3)
            lat, lon, ped offsets from trim in [-1, 1].
        state : ndarray of float64, shape (n_states,) or (n, n_states)
            The filters' prediction for the next period: pass it back with the next observation.

        Raises
        ------
        AgentError
            An observation, state or ``episode_start`` of the wrong shape, or a non-finite observation.
        """
        obs = np.asarray(observation, dtype=np.float64)
        if obs.ndim not in (1, 2) or obs.shape[-1] != OBS_DIM:
            raise AgentError(f"observation must have shape ({OBS_DIM},) or (n, {OBS_DIM}), got {obs.shape}")
        if not np.all(np.isfinite(obs)):
            raise AgentError("observation must be finite, got NaN or inf")
        single = obs.ndim == 1
        obs = obs.reshape(-1, OBS_DIM)
        x_p = self._start(state, episode_start, obs.shape[0], single)
        y = -obs[:, MEASURED]
        x_f = x_p @ self._Ft + y @ self._Mt
        u = np.clip(-(x_f @ self._Kt), -1.0, 1.0)
        x_next = x_f @ self._At + u @ self._Bt
        action = u.astype(np.float32)
        return (action[0], x_next[0]) if single else (action, x_next)

    def _start(self, state, episode_start, rows: int, single: bool) -> np.ndarray:
        """The predicted states to update: ``state`` (copied), zero where an episode starts."""
        N = self.n_states
        if state is None:
            return np.zeros((rows, N))
        x = np.array(state, dtype=np.float64).reshape(-1, N) if np.size(state) == rows * N else None
        if x is None or (single and np.ndim(state) != 1) or (not single and np.shape(state) != (rows, N)):
            expected = f"({N},)" if single else f"({rows}, {N})"
            raise AgentError(f"state must be the filter state the last predict returned, shape {expected}, got "
                             f"{np.shape(state)} (pass state=None at the first observation)")
        if episode_start is not None:
            start = np.asarray(episode_start, dtype=bool).reshape(-1)
            if start.size != rows:
                raise AgentError(f"episode_start must hold one flag per observation ({rows}), got {start.size}")
            x[start] = 0.0
        return x

    # ----------------------------------------------------------------- files
    def document(self, metadata=None) -> dict:
        """The JSON document :meth:`save` writes."""
        return jsonable({
            "schema": SCHEMA, "schema_version": SCHEMA_VERSION, "dt": self.dt,
            "law": "per axis: y = -(obs[i], obs[6+i]); x_f = x_p + M (y - C x_p); u = clip(-K x_f, -1, 1); "
                   "x_p <- A x_f + B u; x_p = 0 at an episode's start",
            "units": {"dt": "s", "y": "rad, rad/s", "u": "stick"},
            "axes": [{"axis": name, "states": list(a["states"]),
                      **{k: a[k].tolist() for k in ("A", "B", "C", "K", "M")}} for name, a in zip(AXES, self.axes)],
            "metadata": dict(metadata or {})})

    @classmethod
    def from_document(cls, doc: dict) -> "LQGController":
        """The controller of a :meth:`document` (AgentError for a missing or bad entry)."""
        if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
            got = doc.get("schema") if isinstance(doc, dict) else type(doc).__name__
            raise AgentError(f"expected schema {SCHEMA!r}, got {got!r}")
        if doc.get("schema_version") != SCHEMA_VERSION:
            raise AgentError(f"expected schema_version {SCHEMA_VERSION}, got {doc.get('schema_version')!r}")
        missing = [k for k in ("dt", "axes") if k not in doc]
        if missing:
            raise AgentError(f"missing {', '.join(missing)}")
        return cls(doc["axes"], doc["dt"])

    def save(self, path, metadata=None) -> Path:
        """Write the controller as JSON, atomically (``metadata``, e.g. the design's figures, stored as is)."""
        return write_text(path, json.dumps(self.document(metadata), indent=1, allow_nan=False) + "\n")

    @classmethod
    def load(cls, path) -> "LQGController":
        """Read a controller written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            No such file.
        AgentError
            Not JSON, not an LQG controller file, another schema version, or bad matrices.
        """
        path = Path(path)
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise AgentError(f"{path}: not a JSON LQG controller file ({e})") from e
        try:
            return cls.from_document(doc)
        except AgentError as e:
            raise AgentError(f"{path}: {e}") from e


def _checked_axis(entry, name: str) -> dict:
    """One axis' matrices as float arrays of consistent shapes; AgentError naming the axis and the matrix."""
    if not isinstance(entry, dict):
        raise AgentError(f"{name}: expected a mapping of A, B, C, K, M and states, got {type(entry).__name__}")
    missing = [k for k in ("A", "B", "C", "K", "M") if k not in entry]
    if missing:
        raise AgentError(f"{name}: missing {', '.join(missing)}")
    out = {}
    for key in ("A", "B", "C", "K", "M"):
        try:
            out[key] = np.array(entry[key], dtype=np.float64, ndmin=2)
        except (TypeError, ValueError) as e:
            raise AgentError(f"{name}: {key} must be a matrix of numbers ({e})") from e
        if not np.all(np.isfinite(out[key])):
            raise AgentError(f"{name}: {key} must be finite")
    n = out["A"].shape[0]
    shapes = {"A": (n, n), "B": (n, 1), "C": (2, n), "K": (1, n), "M": (n, 2)}
    for key, shape in shapes.items():
        if out[key].shape != shape:
            raise AgentError(f"{name}: {key} must have shape {shape} for {n} states, got {out[key].shape}")
    states = entry.get("states") or [f"x{i}" for i in range(n)]
    if len(states) != n:
        raise AgentError(f"{name}: {n} states but {len(states)} state names")
    out["states"] = tuple(str(s) for s in states)
    return out
