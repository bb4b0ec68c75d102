"""One batched closed loop: per-axis PD attitude hold of many gain pairs against many gust windows.

The gain sweep (:mod:`controllers.sweep`, the identified model replaying the
library's gusts) and the flight tests (:mod:`controllers.flight_test`, the
truth model in fresh wind) fly the same loop; this module writes it once.

At every control period ``dt`` the PD law (:func:`controllers.pd.law.pd_command`)
computes a stick offset per axis from the attitude and rates the autopilot sees
(the true state, plus sensor noise where given; reference 0: attitude hold),
clipped to [-1, 1]; the applied stick is ``clip(trim + offset, -1, 1)``, exactly
as the environments apply an action. The sticks, the recorded collective and the
gust torque ``k·u_d`` [rad/s²] are held over the period (zero-order hold) while
the physics core advances the state: its exact discrete step
(:func:`zoh_step`, the environments' integrator) or RK4 with sub-steps
(:func:`rk4_step`, the synthetic flight generator's). The state starts level at
rest, servos settled on the first trim.

All three axes fly: the swept axis with the pair under test, the other two with
the ``nominal`` gains. An autopilot with a derivative filter (``Autopilot.d_poles``)
passes each axis' rate error through the D term's low-pass first
(:func:`controllers.pd.law.filtered_rate`, its state starting at the first period's rate error),
as :class:`controllers.pd.PDController` does. The state is a tuple of arrays of shape (pairs in a
chunk, windows); the per-period inputs, of shape (windows,), broadcast over the
pairs. Records are taken on the swept axis at the start of each period (the
state the controller acts on), so the first sample of every window is the start.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from heli_core.discrete import discrete_kernel
from heli_core.physics import kernel
from heli_core.quaternion import euler_from_quaternion
from heli_core.terms import AXES

from .pd.law import filtered_rate, pd_command

PROGRESS_EVERY = 200
"""Control periods between two updates of the progress bar."""


@dataclass(frozen=True, eq=False)
class LoopInputs:
    """What is held over each control period, shared by every gain pair of a batch.

    Attributes
    ----------
    trim : ndarray, shape (3, n, W)
        Trim sticks (lat, lon, ped) for the period's collective [stick]; the PD offset is added to it.
    col : ndarray, shape (n, W)
        Collective stick [stick].
    torque : ndarray, shape (3, n, W)
        Gust torque ``k·u_d`` per axis [rad/s²].
    att_noise, rate_noise : ndarray, shape (3, n, W), optional
        Sensor errors added to the Euler angles [rad] and the body rates [rad/s] the autopilot
        sees; None: it sees the true state.
    """

    trim: np.ndarray
    col: np.ndarray
    torque: np.ndarray
    att_noise: np.ndarray | None = None
    rate_noise: np.ndarray | None = None

    @property
    def steps(self) -> int:
        return int(self.col.shape[0])

    @property
    def windows(self) -> int:
        return int(self.col.shape[1])


@dataclass(eq=False)
class LoopRecord:
    """What one chunk of gain pairs did, on the swept axis.

    Attributes
    ----------
    att, rate : ndarray of float32, shape (g, n, W)
        Attitude error [rad] and rate error [rad/s] (reference 0: ``-angle``, ``-rate``) of the
        true state at the start of each period; laid out (pair, period, window) so each pair's
        samples are contiguous.
    act : ndarray of float32, shape (g, n, W)
        Applied stick offset from trim [stick].
    sat : ndarray, shape (g, W)
        Periods where the PD command or the stick (trim + offset) was clipped.
    omax : ndarray, shape (g, W)
        Largest |angle| of the two held axes [rad].
    axes : ndarray of float32, shape (3, g, n, W), optional
        Attitude error of every axis at the start of each period [rad]: recorded by loops that keep memory
        and run at their own rate (:func:`_fly_substeps`), whose sets fly all three axes at once; None else.
    """

    att: np.ndarray
    rate: np.ndarray
    act: np.ndarray
    sat: np.ndarray
    omax: np.ndarray
    axes: np.ndarray | None = None


def zoh_step(params, dt: float):
    """``step(x, u, d)``: the physics core's exact discrete step over one period (the environments')."""
    return discrete_kernel(params, float(dt))[0]


def rk4_step(params, dt: float, substeps: int):
    """``step(x, u, d)``: ``substeps`` RK4 steps of the physics core over one period (the flight generator's)."""
    rk4 = kernel(params)[0]["rk4"]
    h = dt / substeps

    def step(x, u, d):
        for _ in range(substeps):
            x = rk4(x, u, d, h)
        return x

    return step


def _progress(total, show, desc):
    if hasattr(show, "update"):  # a bar the caller owns over several replays (a sweep's rounds)
        from heli_core.backends import _Grown

        return _Grown(show, total)
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="step", unit_scale=True, leave=False, file=sys.stderr,
                disable=not show or not sys.stderr.isatty())


@dataclass(frozen=True, eq=False)
class Autopilot:
    """The PD attitude hold flown: gain pairs on one axis, nominal gains on the other two, the control signs.

    Attributes
    ----------
    axis : int
        Swept axis, 0 roll, 1 pitch, 2 yaw.
    kp, kd : ndarray, shape (G,)
        Gains of the swept axis [stick/rad], [stick/(rad/s)]; pair ``g`` is ``(kp[g], kd[g])``.
    nominal : array (3, 2)
        (kp, kd) of the held axes.
    signs : array (3,)
        Signs of the control gains (k2, k6, k10) the autopilot assumes.
    d_poles : array (3,), optional
        Pole ``a`` of each axis' derivative filter at the control period
        (:func:`controllers.pd.law.derivative_pole`); 0 or None: no filter.
    """

    axis: int
    kp: np.ndarray
    kd: np.ndarray
    nominal: object
    signs: object
    d_poles: object = None

    @property
    def pairs(self) -> int:
        return int(self.kp.size)

    def gains(self, pairs: slice) -> list:
        """(kp, kd) of each axis flying ``pairs``: the swept axis' as columns (pairs, 1), the held axes' numbers."""
        gains = [(self.nominal[i][0], self.nominal[i][1]) for i in range(3)]
        gains[self.axis] = (self.kp[pairs][:, None], self.kd[pairs][:, None])
        return gains


def fly(step, inputs: LoopInputs, autopilot: Autopilot, max_batch: int = 4096, progress: bool = True,
        desc: str | None = None):
    """Fly the autopilot's gain pairs against every window; yield ``(slice, LoopRecord)`` per chunk of pairs.

    Parameters
    ----------
    step : callable
        ``step(x, u, d)`` advancing the state one period (:func:`zoh_step` or :func:`rk4_step`).
    inputs : LoopInputs
    autopilot : Autopilot
        The pairs flown on the swept axis, the held axes' gains and the signs assumed; or a loop that keeps
        memory and runs ``substeps`` ticks per period (:class:`controllers.firmware.autopilot.FirmwareAutopilot`,
        flown by :func:`_fly_substeps`; ``step`` then advances one tick, ``dt / substeps``).
    max_batch : int
        Pair × window states stepped at once; chunks hold ``max(1, max_batch // W)`` pairs.
    progress : bool
        tqdm bar on stderr (when it is a terminal).
    desc : str, optional
        Label of the bar.

    Yields
    ------
    slice, LoopRecord
        The chunk's pairs and what they did. Every pair's states are independent of the
        others in its chunk (element-wise numpy), so the split changes no number.
    """
    G, W, n = autopilot.pairs, inputs.windows, inputs.steps
    cp = max(1, max_batch // W)
    ins = _contiguous(inputs)
    with _progress(G * W * n, progress, desc or f"replay {AXES[autopilot.axis]}") as bar, \
            np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        for c0 in range(0, G, cp):
            sl = slice(c0, min(G, c0 + cp))
            if getattr(autopilot, "substeps", None):  # a loop with memory at its own rate (controllers.firmware)
                yield sl, _fly_substeps(step, ins, autopilot, sl, bar)
                continue
            yield sl, _fly_chunk(step, ins, autopilot.axis, autopilot.gains(sl), autopilot.signs,
                                 sl.stop - sl.start, bar, autopilot.d_poles)


def _contiguous(inputs: LoopInputs) -> dict:
    """Per-axis rows of the inputs as contiguous arrays (the loop reads one period of one axis at a time)."""
    def rows(a):
        return None if a is None else [np.ascontiguousarray(a[i]) for i in range(3)]

    return {"trim": rows(inputs.trim), "torque": rows(inputs.torque), "col": inputs.col,
            "att_noise": rows(inputs.att_noise), "rate_noise": rows(inputs.rate_noise)}


def _fly_chunk(step, ins: dict, ax: int, gains, signs, g: int, bar, d_poles=None) -> LoopRecord:
    """One chunk of ``g`` pairs over every period; see :func:`fly`."""
    trim, torque, col = ins["trim"], ins["torque"], ins["col"]
    att_noise, rate_noise = ins["att_noise"], ins["rate_noise"]
    n, W = col.shape
    clip = np.clip
    z = np.zeros((g, W))
    x = (z, z, z, z + trim[0][0], z + trim[1][0], z + trim[2][0], z + 1.0, z, z, z)
    rec = LoopRecord(np.empty((g, n, W), dtype=np.float32), np.empty((g, n, W), dtype=np.float32),
                     np.empty((g, n, W), dtype=np.float32), np.zeros((g, W)), np.zeros((g, W)))
    others = [i for i in range(3) if i != ax]
    poles = [0.0] * 3 if d_poles is None else [float(a) for a in d_poles]
    d_state = [None] * 3  # each filtered axis' last output; None: its first period is next
    for k in range(n):
        ang = euler_from_quaternion(x[6:10])
        sticks = []
        for i in range(3):
            e_ang = -ang[i] if att_noise is None else -(ang[i] + att_noise[i][k])
            e_rate = -x[i] if rate_noise is None else -(x[i] + rate_noise[i][k])
            if poles[i]:
                e_rate = d_state[i] = filtered_rate(d_state[i], e_rate, poles[i])
            u = pd_command(gains[i][0], gains[i][1], signs[i], e_ang, e_rate)
            a = clip(u, -1.0, 1.0)
            t_i = trim[i][k]
            s = clip(t_i + a, -1.0, 1.0)
            sticks.append(s)
            if i == ax:
                rec.att[:, k] = -ang[i]
                rec.rate[:, k] = -x[i]
                rec.act[:, k] = s - t_i
                rec.sat += (a != u) | (s != t_i + a)
        rec.omax = np.maximum(rec.omax, np.maximum(np.abs(ang[others[0]]), np.abs(ang[others[1]])))
        x = step(x, (sticks[0], sticks[1], col[k], sticks[2]), (torque[0][k], torque[1][k], torque[2][k]))
        if k % PROGRESS_EVERY == PROGRESS_EVERY - 1:
            bar.update(PROGRESS_EVERY * g * W)
    bar.update((n % PROGRESS_EVERY) * g * W)
    return rec


def _fly_substeps(step, ins: dict, autopilot, sl: slice, bar) -> LoopRecord:
    """One chunk of a loop with memory at its own rate: ``autopilot.substeps`` ticks per period.

    ``step`` advances the physics one tick; the sticks change every tick (``autopilot.command`` on the state
    of that instant), the gust, the collective, the trim and the sensor errors are held over the period.
    ``autopilot.start(sl, W)`` gives the loops' memory at rest, ``autopilot.command(memory, e_ang, rates, sl)``
    the stick offsets (3, g, W) before the clip to [-1, 1], the new memory and where the loop clamped its
    output. Records are taken at the first tick of each period, the swept axis' as :func:`_fly_chunk` takes
    them and every axis' attitude error in ``axes``.
    """
    trim, torque, col = ins["trim"], ins["torque"], ins["col"]
    att_noise, rate_noise = ins["att_noise"], ins["rate_noise"]
    n, W = col.shape
    g, ax, m = sl.stop - sl.start, autopilot.axis, int(autopilot.substeps)
    z = np.zeros((g, W))
    x = (z, z, z, z + trim[0][0], z + trim[1][0], z + trim[2][0], z + 1.0, z, z, z)
    rec = LoopRecord(np.empty((g, n, W), dtype=np.float32), np.empty((g, n, W), dtype=np.float32),
                     np.empty((g, n, W), dtype=np.float32), np.zeros((g, W)), np.zeros((g, W)),
                     np.empty((3, g, n, W), dtype=np.float32))
    others = [i for i in range(3) if i != ax]
    memory = autopilot.start(sl, W)
    for k in range(n):
        t_k = np.stack([trim[i][k] for i in range(3)])[:, None, :]
        d_k = (torque[0][k], torque[1][k], torque[2][k])
        an = 0.0 if att_noise is None else np.stack([att_noise[i][k] for i in range(3)])[:, None, :]
        rn = 0.0 if rate_noise is None else np.stack([rate_noise[i][k] for i in range(3)])[:, None, :]
        clipped = np.zeros((g, W), dtype=bool)
        for j in range(m):
            ang = np.stack(euler_from_quaternion(x[6:10]))
            u, memory, sat = autopilot.command(memory, -(ang + an), np.stack(x[0:3]) + rn, sl)
            a = np.clip(u, -1.0, 1.0)
            s = np.clip(t_k + a, -1.0, 1.0)
            clipped |= sat[ax] | (a[ax] != u[ax]) | (s[ax] != t_k[ax] + a[ax])
            if j == 0:
                rec.axes[:, :, k] = -ang
                rec.att[:, k] = -ang[ax]
                rec.rate[:, k] = -x[ax]
                rec.act[:, k] = s[ax] - t_k[ax]
                rec.omax = np.maximum(rec.omax, np.maximum(np.abs(ang[others[0]]), np.abs(ang[others[1]])))
            x = step(x, (s[0], s[1], col[k], s[2]), d_k)
        rec.sat += clipped
        if k % PROGRESS_EVERY == PROGRESS_EVERY - 1:
            bar.update(PROGRESS_EVERY * g * W)
    bar.update((n % PROGRESS_EVERY) * g * W)
    return rec
