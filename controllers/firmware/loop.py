"""What the two firmware loops share: per-axis gains over a batch, the command scale, the policy interface.

A firmware loop (:class:`~controllers.firmware.ardupilot.ArduPilotHeli`,
:class:`~controllers.firmware.rotorflight.Rotorflight`) runs at its own rate: one :meth:`FirmwareLoop.tick`
is one pass of the firmware's attitude and rate controllers, every ``1/loop_rate_hz`` seconds. It reads the
attitude error (reference − attitude) [rad] and the body rates its gyro measures [rad/s] of every loop of a
batch at once, and returns the firmware's own output (ArduPilot: the normalised swash command −1…1;
Rotorflight: the PID sum in mixer units). :meth:`FirmwareLoop.sticks` turns that output into the model's
stick offsets from trim::

    stick_i = sign_i · scale_i · output_i

``sign_i`` is the sign of the model's control gain (k2, k6, k10), so that an output that asks for a
positive rate drives one (both firmwares' convention, and the logs' as :mod:`identification.io` imports
them); ``scale_i`` [model stick per firmware unit] is the command scale, measured from the log where it can
be (:mod:`controllers.firmware.scale`), 1 where the model was identified on the firmware's own output.

Gains over a batch
------------------
A loop is built from one parameter set or from a sequence of ``G`` sets (the gain sets of a sweep). With
``G`` sets every array the loop steps has the shape ``(3, G, ...)`` — axis, set, and whatever else the
caller batches (gust windows) — and each set's gains broadcast over the trailing axes. With one set, arrays
are ``(3, ...)`` of any trailing shape. The memory of the loop (filter states, integrators, the saturation
flag of the last tick) is one float array ``(rows, 3, ...)`` the caller keeps and passes back: the loops
themselves hold no state between calls, so one object flies any number of batches.

The policy interface
--------------------
:meth:`FirmwareLoop.predict` is SB3's ``predict(observation, state=None, episode_start=None,
deterministic=False) -> (action, state)`` on the environment's observation (attitude error obs[0:3], body
rates obs[3:6], see :class:`heli_env.env.HeliAttitudeEnv`), so a firmware loop flies through the evaluator as
PD and RL agents do. The environment holds an action for its control period ``dt`` (0.01 s), longer than a
tick: ``predict`` runs ``loop_rate_hz·dt`` ticks on the observation it got (the gyro and the attitude
sampled once per period) and returns the last output, the memory as ``state``. In the project's batched
closed loop (:func:`controllers.replay.fly`) the physics is instead sub-stepped to the loop rate, so every
tick sees the state of its own instant; the environments and the evaluator do the same on the library held at the
loop's rate, with ``control_dt`` the tick (:mod:`controllers.firmware.loop_rate_env`: held at 0.01 s the
loop is a 100 Hz one, and on the bench's agile aircraft Rotorflight's yaw p90 came out twice the tick's).
"""

from __future__ import annotations

import math
import numpy as np

from .errors import FirmwareMappingError

OBS_DIM = 12
"""Length of the environment's observation (:class:`heli_env.env.HeliAttitudeEnv`)."""


def check_axes(values, name: str, lo: float = 0.0, hi: float = math.inf, integer: bool = False) -> tuple:
    """Three finite numbers (roll, pitch, yaw) in ``[lo, hi]`` as a tuple of floats; a scalar is broadcast.

    Raises
    ------
    ValueError
        Not three numbers, not finite, outside the range, or not whole where ``integer``.
    """
    try:
        v = np.broadcast_to(np.asarray(values, dtype=float), (3,))
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be a number or 3 numbers (roll, pitch, yaw), got {values!r}") from e
    if not np.all(np.isfinite(v)) or np.any(v < lo) or np.any(v > hi):
        raise ValueError(f"{name} must be finite and in [{lo:g}, {hi:g}], got {tuple(v.tolist())}")
    if integer and np.any(v != np.round(v)):
        raise ValueError(f"{name} must be whole numbers (the firmware stores integers), got {tuple(v.tolist())}")
    return tuple(float(x) for x in v)


def check_scalar(value, name: str, lo: float = 0.0, hi: float = math.inf, open_lo: bool = False) -> float:
    """One finite number in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``) as a float, else ``ValueError``."""
    try:
        v = float(value)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be a number, got {value!r}") from e
    if not math.isfinite(v) or v < lo or v > hi or (open_lo and v == lo):
        where = f"({lo:g}, {hi:g}]" if open_lo else f"[{lo:g}, {hi:g}]"
        raise ValueError(f"{name} must be finite and in {where}, got {value!r}")
    return v


class FirmwareLoop:
    """Base of the firmware loops (module docstring): gains over a batch, the scale, ``predict``.

    Parameters
    ----------
    params : dataclass or sequence of dataclasses
        One parameter set or ``G`` sets of the firmware (same loop rate: it is the physics' sub-step).
    scale : float or 3 floats
        Command scale per axis [model stick per firmware output unit], > 0.
    signs : 3 floats of +1 or -1
        Signs of the model's control gains (k2, k6, k10).
    """

    firmware = "firmware"
    """Short name, used in files and reports."""

    def __init__(self, params, scale=1.0, signs=(1.0, 1.0, 1.0)):
        sets = tuple(params) if isinstance(params, (list, tuple)) else (params,)
        if not sets:
            raise FirmwareMappingError("a firmware loop needs at least one parameter set, got none")
        kind = type(sets[0])
        if any(type(p) is not kind for p in sets):
            raise FirmwareMappingError(f"every parameter set must be a {kind.__name__}, got "
                                       f"{sorted({type(p).__name__ for p in sets})}")
        rates = {p.loop_rate_hz for p in sets}
        if len(rates) != 1:
            raise FirmwareMappingError(f"the parameter sets of one loop must share a loop rate, got {sorted(rates)} Hz")
        sc = np.broadcast_to(np.asarray(scale, dtype=float), (3,))
        if not np.all(np.isfinite(sc)) or np.any(sc <= 0):
            raise FirmwareMappingError(f"the command scale must be 3 finite numbers > 0 (model stick per firmware "
                                       f"unit), got {np.asarray(scale).tolist()}")
        sg = np.asarray(signs, dtype=float)
        if sg.shape != (3,) or not np.all(np.abs(sg) == 1.0):
            raise FirmwareMappingError(f"signs must be three values of +1 or -1 (roll, pitch, yaw), got {signs!r}")
        self.params = sets
        self.single = not isinstance(params, (list, tuple))
        self.scale = tuple(float(v) for v in sc)
        self.signs = tuple(float(v) for v in sg)
        self.loop_rate_hz = float(sets[0].loop_rate_hz)
        self.dt = 1.0 / self.loop_rate_hz
        self._stick = (sg * sc)
        self._shaped: dict = {}  # kernel coefficients per batch shape
        self.coef = self._coefficients()

    # ----------------------------------------------------------------- batching
    @property
    def sets(self) -> int:
        """Number of parameter sets ``G``."""
        return len(self.params)

    def axes_array(self, name: str) -> np.ndarray:
        """A per-axis field of every set as an array (3, G)."""
        return np.array([getattr(p, name) for p in self.params], dtype=float).T

    def scalar_array(self, name: str) -> np.ndarray:
        """A scalar field of every set as an array (G,)."""
        return np.array([getattr(p, name) for p in self.params], dtype=float)

    def shaped(self, arr: np.ndarray, ndim: int) -> np.ndarray:
        """``arr`` (3, G) or (G,) shaped to broadcast over arrays of ``ndim`` dimensions (axis, batch...).

        One set: ``(3, 1, ...)``; ``G`` sets: ``(3, G, 1, ...)`` (the batch's first axis is the set).
        """
        a = np.asarray(arr, dtype=float)
        if a.ndim == 1:  # a scalar field (G,): the same on every axis
            a = a[None, :]
        if self.single:
            return a[:, 0].reshape((a.shape[0],) + (1,) * (ndim - 1))
        if ndim < 2:
            raise FirmwareMappingError(f"a loop of {self.sets} parameter sets steps arrays (3, {self.sets}, ...), "
                                       f"got arrays of {ndim} dimension(s)")
        return a.reshape(a.shape[:2] + (1,) * (ndim - 2))

    def _coefficients(self) -> dict:
        """Arrays the tick reads, (3, G) or (G,), keyed by name (filled by the subclasses)."""
        return {}

    coef_order = ()
    """The coefficients the compiled tick reads, in the order of its rows (subclasses)."""

    def kernel_coef(self, batch_shape: tuple) -> np.ndarray:
        """:attr:`coef` in :attr:`coef_order` broadcast over a batch and flattened: ``(K, 3, B)``, cached."""
        key = ("kernel", tuple(batch_shape))
        if key not in self._shaped:
            ndim = 1 + len(batch_shape)
            rows = [np.broadcast_to(self.shaped(self.coef[name], ndim), (3,) + tuple(batch_shape)).reshape(3, -1)
                    for name in self.coef_order]
            self._shaped[key] = np.ascontiguousarray(np.stack(rows))
        return self._shaped[key]

    def flat_inputs(self, memory, att_error, gyro, ff_rate):
        """The tick's inputs as contiguous float arrays over a flattened batch: memory (R, 3, B), error, gyro and
        feed-forward (3, B); and the batch's shape."""
        e = np.asarray(att_error, dtype=float)
        shape = e.shape[1:]
        flat = (3, int(np.prod(shape, dtype=int)))
        mem = np.ascontiguousarray(np.asarray(memory, dtype=float).reshape((self.memory_rows,) + flat))
        ff = np.zeros(flat) if ff_rate is None else np.broadcast_to(np.asarray(ff_rate, float), e.shape).reshape(flat)
        return (mem, np.ascontiguousarray(e.reshape(flat)), np.ascontiguousarray(
            np.broadcast_to(np.asarray(gyro, dtype=float), e.shape).reshape(flat)), np.ascontiguousarray(ff), shape)

    # ----------------------------------------------------------------- stepping
    memory_rows = 0
    """Rows of the memory array (filter states, integrators, flags) per axis."""

    def initial_memory(self, shape=()) -> np.ndarray:
        """The memory of loops at rest (filters and integrators 0, not saturated): ``(rows, 3, *shape)``."""
        return np.zeros((self.memory_rows, 3) + tuple(shape))

    def tick(self, memory: np.ndarray, att_error, gyro, ff_rate=None):
        """One pass of the firmware's loops; implemented by the subclasses.

        Parameters
        ----------
        memory : ndarray (rows, 3, ...)
        att_error : ndarray (3, ...)
            Reference − attitude as the autopilot estimates it [rad].
        gyro : ndarray (3, ...)
            Body rates as the gyro measures them [rad/s].
        ff_rate : ndarray (3, ...), optional
            Rate feed-forward of a shaped reference [rad/s] (a commanded move; None in attitude hold).

        Returns
        -------
        output : ndarray (3, ...)
            The firmware's output (firmware units), after its clamps.
        memory : ndarray (rows, 3, ...)
            The new memory (a new array; the one passed in is not changed).
        saturated : ndarray of bool (3, ...)
            Where the output was clamped this tick.
        """
        raise NotImplementedError

    def sticks(self, output) -> np.ndarray:
        """Stick offsets from trim (3, ...) for firmware outputs (3, ...): ``sign·scale·output``."""
        out = np.asarray(output, dtype=float)
        return self._stick.reshape((3,) + (1,) * (out.ndim - 1)) * out

    def substeps(self, control_dt: float) -> int:
        """Ticks per control period ``control_dt`` [s]; :class:`FirmwareMappingError` unless a whole number."""
        ratio = float(control_dt) * self.loop_rate_hz
        m = int(round(ratio))
        if m < 1 or abs(ratio - m) > 1e-6 * max(1.0, ratio):
            raise FirmwareMappingError(
                f"the loop rate {self.loop_rate_hz:g} Hz must be a whole multiple of the control rate "
                f"{1.0 / control_dt:g} Hz (control period {control_dt:g} s), got {ratio:g} ticks per period")
        return m

    # ------------------------------------------------------------ policy interface
    def predict(self, observation, state=None, episode_start=None, deterministic: bool = False,
                control_dt: float = 0.01):
        """SB3's ``predict`` on the environment's observation (module docstring).

        Parameters
        ----------
        observation : array_like (12,) or (n, 12)
            Attitude error [rad] at 0:3, body rates [rad/s] at 3:6 (as :class:`heli_env.env.HeliAttitudeEnv`).
        state : ndarray, optional
            The memory a previous call returned (None: loops at rest).
        episode_start : array_like of bool (n,), optional
            Loops whose episode starts: their memory is reset.
        deterministic : bool
            Unused (the loops are deterministic).
        control_dt : float
            The environment's control period [s]; ``loop_rate_hz·control_dt`` ticks are run.

        Returns
        -------
        action : ndarray of float32 (3,) or (n, 3)
            Stick offsets from trim, clipped to [-1, 1].
        state : ndarray
            The memory after the ticks.
        """
        obs = np.asarray(observation, dtype=np.float64)
        if obs.ndim not in (1, 2) or obs.shape[-1] != OBS_DIM:
            raise ValueError(f"observation must have shape ({OBS_DIM},) or (n, {OBS_DIM}), got {obs.shape}")
        err, rate = obs[..., 0:3].T, obs[..., 3:6].T  # (3,) or (3, n)
        memory = self.initial_memory(err.shape[1:]) if state is None else np.array(state, dtype=float)
        if episode_start is not None and obs.ndim == 2:
            reset = np.asarray(episode_start, dtype=bool)
            memory[..., reset] = 0.0
        out = None
        for _ in range(self.substeps(control_dt)):
            out, memory, _ = self.tick(memory, err, rate)
        action = np.clip(self.sticks(out), -1.0, 1.0).T.astype(np.float32)
        return action, memory
