"""Rotorflight's attitude loop in angle mode with ``pid_mode 3``, tick by tick.

One :meth:`Rotorflight.tick` is one pass of the PID loop (the gyro rate over ``pid_process_denom``; 1 kHz at
Rotorflight's defaults, 8 kHz / 8), per axis (rotorflight-firmware src/main/flight/pid.c
``pidApplyCyclicMode3``/``pidApplyYawMode3``, leveling.c ``angleModeApply``, filter.c; units deg/s as the
firmware's):

1. the gyro: ``gyro_lpf1`` (a PT1 at ``gyro_lpf1_static_hz``; the firmware runs it and the decimation filter
   at the gyro's rate, here at the loop rate) then the per-axis bandwidth limiter ``*_gyro_cutoff``
   (``pidApplyGyroRate``; a first-order low-pass, :func:`~controllers.firmware.filters.rf_first_order`);
2. the set-point: roll and pitch in angle mode ``sp = (angle_level_strength/10)·(θ_ref − θ)`` [deg/s] with the
   reference limited to ±``angle_level_limit`` (``angleModeApply``; the on-ground quartering is left out); yaw
   the pilot's rate (0 in a hold), so heading is held only by the I-term, as the firmware's (the caller
   keeps the reference within ±``angle_level_limit``: the loop reads only the error);
3. ``P = Kp·(sp − g)`` (yaw: times the stop gain of the error's side, ``yaw_cw_stop_gain`` for a positive
   error and ``yaw_ccw_stop_gain`` for a negative one, blended over ±10 °/s as ``transition`` does);
   ``D = Kd·dif(−g, *_d_cutoff)`` (D on the gyro only); the I-term's accumulated error
   ``E = clamp(E + relax(e)·dt, ±error_limit)`` (not grown while the mixer saturates and ``E·e > 0``), where
   ``relax`` (``iterm_relax_type`` RPY) multiplies the error by ``max(0, 1 − |sp − PT1(sp)|/level)``;
   ``I = Ki·E``; then the decay ``E −= clamp(E·r, ±l)·dt`` (roll, pitch: ``r = 10/error_decay_time_cyclic ·
   12 · 0.08``, ``l = error_decay_limit_cyclic · 12 · 0.08``: the curves' value at zero collective, see
   below; yaw: ``error_decay_time_yaw``/``_limit_yaw``);
   ``F = Kf·sp``; ``B = Kb·dif(sp, *_b_cutoff)``;
4. ``pidSum = P + I + D + F + B``, clamped to ±``output_limit`` (the mixer's input limit; saturation flags
   the next tick's I-term).

``K = SCALE·gain`` with the scales of pid.h (roll P 6.66666e-6, I 2e-4, D 1e-7, F 2.5e-5, B 1e-7; pitch D
1e-6; yaw P 6.6667e-5, I 5e-4, D 1e-6, F 2.5e-5, B 1e-6), so ``pidSum`` is in mixer units.

Checked against rotorflight-firmware's source as read for this module (pid.c pidApplyCyclicMode3 and
pidApplyYawMode3, pid.h scales, pg/pid.c defaults, leveling.c, filter.c difFilter/firstOrderFilter/pt1).
Left out or simplified, and said here: the collective offset term ``O`` (``*_o_gain``, 0 in a tune) and the
cross-coupling, pre-compensation and rescue paths; the decay curves are read at zero collective (the
firmware interpolates tables over ``|collective|``: at hover collective the cyclic decay is 1.1-1.7 times
faster, a time constant of tens of seconds either way); ``gyro_lpf1``'s type is taken as PT1 and the
decimation filter is not modelled. **Not verified**: the mixer input limit (``output_limit`` 1.25, from the
research notes) and ``transition``'s exact blend.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from .filters import rf_dif, rf_first_order, rf_pt1
from .loop import FirmwareLoop, check_axes, check_scalar

SCALES = {
    "p": (6.66666e-6, 6.66666e-6, 6.666666e-5),
    "i": (2e-4, 2e-4, 5e-4),
    "d": (1e-7, 1e-6, 1e-6),
    "f": (2.5e-5, 2.5e-5, 2.5e-5),
    "b": (1e-7, 1e-7, 1e-6),
}
"""pid.h ``{ROLL,PITCH,YAW}_{P,I,D,F,B}_TERM_SCALE``: mixer units per (gain unit · deg/s), per axis."""
DECAY_CURVE_AT_ZERO = 12 * 0.08
"""``error_decay_rate_curve[0]·0.08`` (= ``error_decay_limit_curve[0]·0.08``): the cyclic decay factor at zero
collective (pid.c)."""
_RAD = 180.0 / math.pi


@dataclass(frozen=True)
class RotorflightParams:
    """The gains of Rotorflight's pid_mode 3 loop, per axis (roll, pitch, yaw), in the firmware's units.

    Defaults are Rotorflight's (src/main/pg/pid.c ``resetPidProfile``; loop rate 1 kHz, the PID denominator 8
    at an 8 kHz gyro).

    Attributes
    ----------
    p, i, d, f, b : 3 floats
        ``{roll,pitch,yaw}_{p,i,d,f,b}_gain`` [0…1000, integers].
    error_limit : 3 floats
        ``error_limit`` [deg]: the I-term's accumulated error limit.
    d_cutoff, b_cutoff : 3 floats
        ``*_d_cutoff``, ``*_b_cutoff`` [Hz]: bandwidth of the D and B differentiators.
    gyro_cutoff : 3 floats
        ``*_gyro_cutoff`` [Hz]: the per-axis gyro bandwidth limiter; 0 off.
    level_strength : float
        ``angle_level_strength`` [0…200]: set-point per attitude error, in 0.1 (deg/s)/deg.
    level_limit : float
        ``angle_level_limit`` [deg]: the largest attitude reference.
    decay_time_cyclic, decay_limit_cyclic : float
        ``error_decay_time_cyclic`` [0.1 s] and ``error_decay_limit_cyclic`` [deg/s]; 0 off / no limit.
    decay_time_yaw, decay_limit_yaw : float
        ``error_decay_time_yaw`` [0.1 s], ``error_decay_limit_yaw`` [deg/s]; 0 off / no limit.
    yaw_cw_stop_gain, yaw_ccw_stop_gain : float
        ``yaw_cw_stop_gain``, ``yaw_ccw_stop_gain`` [%]: the yaw P gain's factor per error side.
    relax_level, relax_cutoff : 3 floats
        ``iterm_relax_level`` [deg/s] and ``iterm_relax_cutoff`` [Hz]; ``relax`` False switches relax off
        (``iterm_relax_type`` OFF).
    relax : bool
    loop_rate_hz : float
        The PID loop's rate [Hz] (gyro rate / ``pid_process_denom``).
    gyro_lpf1_hz : float
        ``gyro_lpf1_static_hz`` [Hz]; 0 off.
    output_limit : float
        The mixer's input limit on the PID sum [mixer units].
    """

    p: tuple = (50.0, 50.0, 80.0)
    i: tuple = (100.0, 100.0, 120.0)
    d: tuple = (10.0, 40.0, 40.0)
    f: tuple = (100.0, 100.0, 0.0)
    b: tuple = (0.0, 0.0, 0.0)
    error_limit: tuple = (30.0, 30.0, 45.0)
    d_cutoff: tuple = (15.0, 15.0, 20.0)
    b_cutoff: tuple = (15.0, 15.0, 20.0)
    gyro_cutoff: tuple = (50.0, 50.0, 100.0)
    level_strength: float = 40.0
    level_limit: float = 55.0
    decay_time_cyclic: float = 250.0
    decay_limit_cyclic: float = 12.0
    decay_time_yaw: float = 0.0
    decay_limit_yaw: float = 0.0
    yaw_cw_stop_gain: float = 120.0
    yaw_ccw_stop_gain: float = 80.0
    relax_level: tuple = (40.0, 40.0, 40.0)
    relax_cutoff: tuple = (10.0, 10.0, 10.0)
    relax: bool = True
    loop_rate_hz: float = 1000.0
    gyro_lpf1_hz: float = 100.0
    output_limit: float = 1.25

    def __post_init__(self):
        for name in ("p", "i", "d", "f", "b"):
            object.__setattr__(self, name, check_axes(getattr(self, name), f"{name} gain", 0.0, 1000.0))
        for name in ("error_limit", "d_cutoff", "b_cutoff", "gyro_cutoff", "relax_level", "relax_cutoff"):
            object.__setattr__(self, name, check_axes(getattr(self, name), name, 0.0, 3600.0))
        for name, hi in (("level_strength", 200.0), ("level_limit", 90.0), ("decay_time_cyclic", 250.0),
                         ("decay_limit_cyclic", 250.0), ("decay_time_yaw", 250.0), ("decay_limit_yaw", 250.0),
                         ("yaw_cw_stop_gain", 250.0), ("yaw_ccw_stop_gain", 250.0), ("gyro_lpf1_hz", 1e4),
                         ("output_limit", 10.0)):
            object.__setattr__(self, name, check_scalar(getattr(self, name), name, 0.0, hi))
        object.__setattr__(self, "loop_rate_hz", check_scalar(self.loop_rate_hz, "loop_rate_hz", 0.0, 1e5, True))
        object.__setattr__(self, "relax", bool(self.relax))
        if self.output_limit <= 0:
            raise ValueError(f"output_limit must be > 0 mixer units, got {self.output_limit}")

    def k(self, term: str) -> tuple:
        """``K = SCALE·gain`` per axis of a term ``"p"``, ``"i"``, ``"d"``, ``"f"``, ``"b"`` [mixer units per deg/s
        (P, D per deg/s², I per deg, F per deg/s, B per deg/s²)]."""
        return tuple(s * g for s, g in zip(SCALES[term], getattr(self, term)))


def _decay(t_tenths: float, limit: float, factor: float) -> tuple:
    """(rate [1/s], limit [deg/s]) of an error decay from its parameters (pid.c ``pidLoadProfile``)."""
    rate = (10.0 / t_tenths) * factor if t_tenths else 0.0
    return rate, (limit * factor if limit else 3600.0)


class Rotorflight(FirmwareLoop):
    """Rotorflight's pid_mode 3 loop in angle mode over a batch (module docstring).

    Parameters
    ----------
    params : RotorflightParams or sequence of them
    scale, signs
        See :class:`~controllers.firmware.loop.FirmwareLoop`.

    Memory rows (per axis): ``gyro_lpf1`` state; the bandwidth limiter's ``x₁, y₁``; the D differentiator's
    ``x₁, y₁``; the B differentiator's ``x₁, y₁``; the accumulated error ``E`` [deg]; the relax PT1 state;
    the mixer's saturation flag of the last tick.
    """

    firmware = "rotorflight"
    memory_rows = 10

    def _coefficients(self) -> dict:
        fs = self.params[0].loop_rate_hz
        c = {t: np.array([p.k(t) for p in self.params]).T for t in ("p", "i", "d", "f", "b")}
        c["error_limit"] = self.axes_array("error_limit")
        c["relax_level"] = self.axes_array("relax_level")
        c["relax_on"] = np.array([[float(p.relax)] * 3 for p in self.params]).T
        c["relax_a"] = np.array([[rf_pt1(f, fs) for f in p.relax_cutoff] for p in self.params]).T
        for name in ("d", "b"):
            coefs = [[rf_dif(f, fs) for f in getattr(p, f"{name}_cutoff")] for p in self.params]
            c[f"{name}_a"] = np.array([[x[0] for x in row] for row in coefs]).T
            c[f"{name}_b"] = np.array([[x[1] for x in row] for row in coefs]).T
        g = [[rf_first_order(f, fs) for f in p.gyro_cutoff] for p in self.params]
        c["g_on"] = np.array([[float(x is not None) for x in row] for row in g]).T
        c["g_b"] = np.array([[x[0] if x else 1.0 for x in row] for row in g]).T
        c["g_a1"] = np.array([[x[2] if x else 0.0 for x in row] for row in g]).T
        decays = [[_decay(p.decay_time_cyclic, p.decay_limit_cyclic, DECAY_CURVE_AT_ZERO)] * 2
                  + [_decay(p.decay_time_yaw, p.decay_limit_yaw, 1.0)] for p in self.params]
        c["decay_rate"] = np.array([[d[0] for d in row] for row in decays]).T
        c["decay_limit"] = np.array([[d[1] for d in row] for row in decays]).T
        c["level"] = np.array([[p.level_strength / 10.0] * 2 + [0.0] for p in self.params]).T
        c["cw"] = self.scalar_array("yaw_cw_stop_gain") / 100.0
        c["ccw"] = self.scalar_array("yaw_ccw_stop_gain") / 100.0
        c["limit"] = self.scalar_array("output_limit")
        c["yaw"] = np.array([[0.0, 0.0, 1.0] for _ in self.params]).T
        self.lpf1 = rf_pt1(self.params[0].gyro_lpf1_hz, fs)
        if any(rf_pt1(p.gyro_lpf1_hz, fs) != self.lpf1 for p in self.params):
            raise ValueError("the parameter sets of one loop must share gyro_lpf1_static_hz (one gyro)")
        return c

    coef_order = ("p", "i", "d", "f", "b", "error_limit", "relax_level", "relax_on", "relax_a", "d_a", "d_b", "b_a",
                  "b_b", "g_on", "g_b", "g_a1", "decay_rate", "decay_limit", "level", "cw", "ccw", "limit", "yaw")

    def tick(self, memory, att_error, gyro, ff_rate=None):
        """One pass of the loop (module docstring; :meth:`FirmwareLoop.tick` for the arguments).

        The statements are :func:`_tick_kernel`'s, compiled by numba and run element by element over the batch.
        """
        mem, e, g, ff, shape = self.flat_inputs(memory, att_error, gyro, ff_rate)
        out, new, sat = np.empty_like(e), np.empty_like(mem), np.empty(e.shape, dtype=np.bool_)
        _tick_kernel(mem, e, g, ff, self.kernel_coef(shape), self.lpf1, self.dt, out, new, sat)
        return out.reshape((3,) + shape), new.reshape(new.shape[:2] + shape), sat.reshape((3,) + shape)


@numba.njit(cache=True)
def _tick_kernel(mem, e, gyro, ff, k, lpf1, dt, out, new, sat):  # pragma: no cover (compiled)
    """One tick of every loop of a flattened batch, in the order of pid.c's statements (module docstring).

    ``mem``/``new`` (10, 3, B) memory in and out; ``e``, ``gyro``, ``ff`` (3, B) in rad and rad/s; ``k``
    (23, 3, B) the coefficients of :attr:`Rotorflight.coef_order`; ``lpf1`` the gyro_lpf1 PT1 gain; ``out``
    (3, B) the PID sum after the mixer's limit, ``sat`` (3, B) where it was limited.
    """
    rad = 180.0 / math.pi
    B = e.shape[1]
    for b in range(B):
        for i in range(3):
            lp, gx1, gy1, dx1, dy1, bx1, by1, E, relax, saturated = (
                mem[0, i, b], mem[1, i, b], mem[2, i, b], mem[3, i, b], mem[4, i, b], mem[5, i, b], mem[6, i, b],
                mem[7, i, b], mem[8, i, b], mem[9, i, b])
            lp = lp + lpf1 * (gyro[i, b] * rad - lp)
            if k[13, i, b] > 0.0:  # the per-axis bandwidth limiter: y = b0·x + b1·x1 − a1·y1 (b0 = b1)
                g = k[14, i, b] * (lp + gx1) - k[15, i, b] * gy1
            else:
                g = lp
            sp = k[18, i, b] * e[i, b] * rad + ff[i, b] * rad  # angle mode: L·(ref − θ)
            err = sp - g
            if k[22, i, b] > 0.0:  # the tail's stop gains: transition(err, -10, 10, ccw, cw)
                x = min(max((err + 10.0) / 20.0, 0.0), 1.0)
                P = k[0, i, b] * err * (k[20, i, b] + (k[19, i, b] - k[20, i, b]) * x)
            else:
                P = k[0, i, b] * err
            dterm = k[10, i, b] * (-g) - k[10, i, b] * dx1 - k[9, i, b] * dy1  # D on the gyro only
            relax = relax + k[8, i, b] * (sp - relax)
            ierr = err
            if k[7, i, b] > 0.0:
                ierr = err * max(0.0, 1.0 - abs(sp - relax) / k[6, i, b])
            if not (saturated > 0.0 and E * ierr > 0.0):
                E = E + ierr * dt
            E = min(max(E, -k[5, i, b]), k[5, i, b])
            I = k[1, i, b] * E
            E = E - min(max(E * k[16, i, b], -k[17, i, b]), k[17, i, b]) * dt
            bterm = k[12, i, b] * sp - k[12, i, b] * bx1 - k[11, i, b] * by1
            total = P + I + k[2, i, b] * dterm + k[3, i, b] * sp + k[4, i, b] * bterm
            c = min(max(total, -k[21, i, b]), k[21, i, b])
            out[i, b] = c
            sat[i, b] = c != total
            new[0, i, b], new[1, i, b], new[2, i, b] = lp, lp, g
            new[3, i, b], new[4, i, b], new[5, i, b], new[6, i, b] = -g, dterm, sp, bterm
            new[7, i, b], new[8, i, b], new[9, i, b] = E, relax, 1.0 if c != total else 0.0
