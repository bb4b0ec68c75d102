"""ArduPilot's traditional-helicopter attitude loop (ArduCopter Heli, AC_AttitudeControl_Heli), tick by tick.

One :meth:`ArduPilotHeli.tick` is one pass of ``SCHED_LOOP_RATE`` (400 Hz by default) through, per axis:

1. the gyro's 2-pole low-pass ``INS_GYRO_FILTER`` (libraries/Filter/LowPassFilter2p.cpp; the firmware runs
   it at the IMU's sample rate, here at the loop rate, and its notches are left out);
2. the angle loop: ``rate_target = sqrt_controller(e, ATC_ANG_*_P, a/2, dt)`` with ``e`` the attitude error
   [rad] and ``a`` the axis' ``ATC_ACCEL_*_MAX`` [rad/s²] limited to 40…720 °/s² (roll, pitch) or
   10…120 °/s² (yaw) (libraries/AC_AttitudeControl/AC_AttitudeControl.cpp
   ``update_ang_vel_target_from_att_error``; ``sqrt_controller`` in libraries/AP_Math/control.cpp: linear
   ``e·P`` while ``|e| <= (a/2)/P²``, the square-root branch ``sqrt(2·(a/2)·(|e| − (a/2)/(2P²)))`` beyond,
   limited to ``|e|/dt``), plus the rate feed-forward of a shaped reference (:func:`input_shaping_angle`,
   ``ATC_INPUT_TC``) when a move is commanded;
3. the rate PID of AC_PID::update_all with the target, error and derivative low-passes
   ``T += α(FLTT)(rate_target − T)``, ``E += α(FLTE)((T − gyro) − E)``, ``D += α(FLTD)((E − E₋₁)/dt − D)``
   (``α = dt/(dt + 1/(2πf))``, 1 for ``f = 0``), the integrator ``I = clamp(I + RAT_I·E·dt, ±IMAX)`` updated
   unless the last output was limited and ``E`` would grow ``I`` (AC_PID::update_i), before it on roll and
   pitch the leak of AC_HELI_PID::update_leaky_i (``I −= (I − sign(I)·ILMI)·0.02`` per tick while
   ``|I| > ILMI``; AC_ATTITUDE_HELI_RATE_INTEGRATOR_LEAK_RATE; ArduCopter leaks only outside dynamic flight,
   i.e. in hover, which is what is flown here), and the output ``P·E + I + D·D + FF·T + D_FF·dT/dt``
   (AC_AttitudeControl_Heli::rate_bf_to_motor_roll_pitch: ``update_all`` plus ``get_ff()`` on the filtered
   target);
4. the output clamp ±1 (AC_ATTITUDE_RATE_RP_CONTROLLER_OUT_MAX, _YAW_) and the swash's cyclic limit: when
   ``|(roll, pitch)| > H_CYC_MAX/4500`` both are scaled onto that circle and the motors' limit flags are set
   for the next tick's integrator (AP_MotorsHeli_Single::move_actuators).

Checked against ArduPilot's source (AC_AttitudeControl_Heli.cpp/.h, AC_PID.cpp update_all/update_i/get_ff,
AC_HELI_PID.cpp update_leaky_i, AP_Math control.cpp sqrt_controller, LowPassFilter2p.cpp) on the copies read
for this module. **Not verified** in the source: the D_FF term's exact form (taken as ``D_FF·(T − T₋₁)/dt``
on the filtered target; 0 by default, so it changes nothing unless set), the yaw acceleration default
``ATC_ACCEL_Y_MAX`` 27000 cdeg/s² (Copter's), and the input shaping's details (:func:`input_shaping_angle`,
used only for the step response of the flight-test card). The rate controller's slew limiter (``SMAX``) and
the notch filters are left out (off by default).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from .filters import ap_alpha, biquad_lpf2p
from .loop import FirmwareLoop, check_axes, check_scalar

LEAK_RATE = 0.02
"""AC_ATTITUDE_HELI_RATE_INTEGRATOR_LEAK_RATE: the fraction of ``I − ILMI`` removed per tick."""
ACCEL_LIMITS_DEG = ((40.0, 720.0), (40.0, 720.0), (10.0, 120.0))
"""AC_ATTITUDE_ACCEL_{RP,Y}_CONTROLLER_{MIN,MAX}_RADSS in deg/s²: the range of ``ATC_ACCEL_*_MAX/2``."""
_DEG = math.pi / 180.0


@dataclass(frozen=True)
class ArduPilotHeliParams:
    """The gains of ArduPilot's heli attitude loop, per axis (roll, pitch, yaw), in the firmware's units.

    Defaults are ArduCopter Heli's (AC_AttitudeControl_Heli.h ``AC_ATC_HELI_RATE_*``, AC_AttitudeControl.h).

    Attributes
    ----------
    ang_p : 3 floats
        ``ATC_ANG_{RLL,PIT,YAW}_P`` [(rad/s)/rad]: rate target per attitude error.
    rat_p, rat_i, rat_d : 3 floats
        ``ATC_RAT_*_P`` [1/(rad/s)], ``_I`` [1/rad], ``_D`` [1/(rad/s²)]: output per rate error, its integral,
        its derivative (output normalised −1…1).
    rat_ff : 3 floats
        ``ATC_RAT_*_FF`` [1/(rad/s)]: output per (filtered) rate target.
    rat_d_ff : 3 floats
        ``ATC_RAT_*_D_FF`` [1/(rad/s²)]: output per rate of change of the target.
    rat_imax, rat_ilmi : 3 floats
        ``ATC_RAT_*_IMAX`` and ``_ILMI`` [output]: the integrator's limit and the level below which it does not
        leak (the leak acts on roll and pitch).
    rat_fltt, rat_flte, rat_fltd : 3 floats
        ``ATC_RAT_*_FLTT``, ``_FLTE``, ``_FLTD`` [Hz]: low-passes of the target, the error, the derivative;
        0 switches one off.
    accel_max : 3 floats
        ``ATC_ACCEL_{R,P,Y}_MAX`` [cdeg/s²]; 0 makes the angle loop linear (no square-root branch).
    input_tc : float
        ``ATC_INPUT_TC`` [s]: time constant of the shaped reference of a commanded move.
    loop_rate_hz : float
        ``SCHED_LOOP_RATE`` [Hz].
    gyro_filter_hz : float
        ``INS_GYRO_FILTER`` [Hz]; 0 off.
    cyc_max : float
        ``H_CYC_MAX`` [cdeg]: the swash's cyclic limit (output circle of radius ``cyc_max/4500``).
    leaky_i : bool
        Whether the roll and pitch integrators leak (ArduCopter does outside dynamic flight: hover).
    """

    ang_p: tuple = (4.5, 4.5, 4.5)
    rat_p: tuple = (0.024, 0.024, 0.18)
    rat_i: tuple = (0.15, 0.15, 0.12)
    rat_d: tuple = (0.001, 0.001, 0.003)
    rat_ff: tuple = (0.15, 0.15, 0.024)
    rat_d_ff: tuple = (0.0, 0.0, 0.0)
    rat_imax: tuple = (0.4, 0.4, 0.4)
    rat_ilmi: tuple = (0.05, 0.05, 0.0)
    rat_fltt: tuple = (20.0, 20.0, 20.0)
    rat_flte: tuple = (20.0, 20.0, 20.0)
    rat_fltd: tuple = (0.0, 0.0, 0.0)
    accel_max: tuple = (110000.0, 110000.0, 27000.0)
    input_tc: float = 0.15
    loop_rate_hz: float = 400.0
    gyro_filter_hz: float = 20.0
    cyc_max: float = 2500.0
    leaky_i: bool = True

    def __post_init__(self):
        for name in ("ang_p", "rat_p", "rat_i", "rat_d", "rat_ff", "rat_d_ff", "rat_imax", "rat_ilmi", "rat_fltt",
                     "rat_flte", "rat_fltd", "accel_max"):
            object.__setattr__(self, name, check_axes(getattr(self, name), name))
        object.__setattr__(self, "input_tc", check_scalar(self.input_tc, "input_tc", 0.0, 10.0))
        object.__setattr__(self, "loop_rate_hz", check_scalar(self.loop_rate_hz, "loop_rate_hz", 0.0, 1e5, True))
        object.__setattr__(self, "gyro_filter_hz", check_scalar(self.gyro_filter_hz, "gyro_filter_hz", 0.0,
                                                                0.5 * self.loop_rate_hz))
        object.__setattr__(self, "cyc_max", check_scalar(self.cyc_max, "cyc_max", 0.0, 4500.0, True))
        for name in ("rat_fltt", "rat_flte", "rat_fltd"):
            if max(getattr(self, name)) >= 0.5 * self.loop_rate_hz:
                raise ValueError(f"{name} must be below the Nyquist frequency {0.5 * self.loop_rate_hz:g} Hz of the "
                                 f"loop, got {getattr(self, name)}")
        object.__setattr__(self, "leaky_i", bool(self.leaky_i))


def sqrt_controller(error, p, second_ord_lim, dt):
    """AP_Math ``sqrt_controller``: a P controller with square-root branches that bound the deceleration.

    Element by element over arrays (the compiled tick's own :func:`_sqrt_scalar`).

    Parameters
    ----------
    error : float or ndarray
        Error [rad].
    p : float or ndarray
        Gain [1/s].
    second_ord_lim : float or ndarray
        Acceleration limit [rad/s²]; <= 0 gives the linear ``error·p``.
    dt : float
        Tick [s]: the result is limited to ``|error|/dt`` (no overshoot within one tick).
    """
    return np.vectorize(_sqrt_scalar, otypes=[float])(error, p, second_ord_lim, float(dt))


def input_shaping_angle(error_angle, input_tc, accel_max, target_ang_vel, dt):
    """The shaped reference's rate for a commanded angle (AC_AttitudeControl ``input_shaping_angle``, simplified).

    ``desired = sqrt_controller(error, 1/max(tc, 0.01), accel_max, dt)``, then the change of the rate limited
    to ``accel_max·dt`` (``input_shaping_ang_vel``). Not verified line by line against the source (see the
    module docstring); used for the step response of the flight-test card only.
    """
    desired = sqrt_controller(error_angle, 1.0 / max(float(input_tc), 0.01), accel_max, dt)
    step = np.asarray(accel_max, dtype=float) * dt
    return np.where(step > 0, np.clip(desired, target_ang_vel - step, target_ang_vel + step), desired)


class ArduPilotHeli(FirmwareLoop):
    """ArduPilot's heli attitude loop at ``SCHED_LOOP_RATE`` over a batch (module docstring).

    Parameters
    ----------
    params : ArduPilotHeliParams or sequence of them
    scale, signs
        See :class:`~controllers.firmware.loop.FirmwareLoop`.

    Memory rows (per axis): gyro filter ``d1, d2``; filtered target ``T``; filtered error ``E``; filtered
    derivative ``D``; integrator ``I``; the motors' limit flag of the last tick (1 limited, 0 free).
    """

    firmware = "ardupilot"
    memory_rows = 7

    def _coefficients(self) -> dict:
        dt = 1.0 / self.params[0].loop_rate_hz
        c = {n: self.axes_array(n) for n in ("ang_p", "rat_p", "rat_i", "rat_d", "rat_ff", "rat_d_ff", "rat_imax",
                                              "rat_ilmi")}
        for src, dst in (("rat_fltt", "at"), ("rat_flte", "ae"), ("rat_fltd", "ad")):
            c[dst] = np.array([[ap_alpha(f, dt) for f in getattr(p, src)] for p in self.params]).T
        lims = []
        for p in self.params:
            row = []
            for i in range(3):
                half = p.accel_max[i] * 0.01 * _DEG / 2.0  # cdeg/s² -> rad/s², then a/2
                lo, hi = ACCEL_LIMITS_DEG[i]
                row.append(min(max(half, lo * _DEG), hi * _DEG) if p.accel_max[i] > 0 else 0.0)
            lims.append(row)
        c["accel_lim"] = np.array(lims).T
        c["leak"] = np.array([[float(p.leaky_i and i < 2) for i in range(3)] for p in self.params]).T
        c["cyc_radius"] = np.array([p.cyc_max / 4500.0 for p in self.params])
        self.gyro_coef = biquad_lpf2p(self.params[0].loop_rate_hz, self.params[0].gyro_filter_hz)
        if any(biquad_lpf2p(p.loop_rate_hz, p.gyro_filter_hz) != self.gyro_coef for p in self.params):
            raise ValueError("the parameter sets of one loop must share INS_GYRO_FILTER (one gyro)")
        return c

    coef_order = ("ang_p", "rat_p", "rat_i", "rat_d", "rat_ff", "rat_d_ff", "rat_imax", "rat_ilmi", "at", "ae",
                  "ad", "accel_lim", "leak", "cyc_radius")

    def tick(self, memory, att_error, gyro, ff_rate=None):
        """One pass of the loop (module docstring; :meth:`FirmwareLoop.tick` for the arguments).

        The statements are :func:`_tick_kernel`'s, compiled by numba and run element by element over the
        batch (as fast for one loop as for thousands; no Python per element).
        """
        mem, e, g, ff, shape = self.flat_inputs(memory, att_error, gyro, ff_rate)
        out, new, sat = np.empty_like(e), np.empty_like(mem), np.empty(e.shape, dtype=np.bool_)
        gc = np.zeros(6) if self.gyro_coef is None else np.array((1.0,) + tuple(self.gyro_coef))
        _tick_kernel(mem, e, g, ff, self.kernel_coef(shape), gc, self.dt, out, new, sat)
        return out.reshape((3,) + shape), new.reshape(new.shape[:2] + shape), sat.reshape((3,) + shape)


@numba.njit(cache=True)
def _sqrt_scalar(error, p, lim, dt):
    """:func:`sqrt_controller` of one error."""
    if lim > 0.0 and p == 0.0:
        rate = math.copysign(math.sqrt(2.0 * lim * abs(error)), error) if error != 0.0 else 0.0
    elif lim > 0.0:
        linear_dist = lim / (p * p)
        if abs(error) > linear_dist:
            rate = math.copysign(math.sqrt(2.0 * lim * (abs(error) - 0.5 * linear_dist)), error)
        else:
            rate = error * p
    else:
        rate = error * p
    if dt > 0.0:
        bound = abs(error) / dt
        rate = min(max(rate, -bound), bound)
    return rate


@numba.njit(cache=True)
def _tick_kernel(mem, e, gyro, ff, k, gc, dt, out, new, sat):  # pragma: no cover (compiled)
    """One tick of every loop of a flattened batch (module docstring, in the order of the firmware's statements).

    ``mem``/``new`` (7, 3, B) memory in and out; ``e``, ``gyro``, ``ff`` (3, B); ``k`` (14, 3, B) the
    coefficients of :attr:`ArduPilotHeli.coef_order`; ``gc`` the gyro biquad ``(on, b0, b1, b2, a1, a2)``;
    ``out`` (3, B) the output after the clamps, ``sat`` (3, B) where it was clamped.
    """
    B = e.shape[1]
    raw = np.empty(3)
    for b in range(B):
        for i in range(3):
            d1, d2, T, E, D, I, limited = (mem[0, i, b], mem[1, i, b], mem[2, i, b], mem[3, i, b], mem[4, i, b],
                                           mem[5, i, b], mem[6, i, b])
            x = gyro[i, b]
            if gc[0] > 0.0:  # LowPassFilter2p::apply
                d0 = x - gc[4] * d1 - gc[5] * d2
                g = gc[1] * d0 + gc[2] * d1 + gc[3] * d2
                d2 = d1
                d1 = d0
            else:
                g = x
            target = _sqrt_scalar(e[i, b], k[0, i, b], k[11, i, b], dt) + ff[i, b]
            Tn = T + k[8, i, b] * (target - T)
            En = E + k[9, i, b] * ((Tn - g) - E)
            Dn = D + k[10, i, b] * ((En - E) / dt - D)
            ki, ilmi = k[2, i, b], k[7, i, b]
            if k[12, i, b] > 0.0 and ki != 0.0:  # AC_HELI_PID::update_leaky_i
                if I > ilmi:
                    I = I - (I - ilmi) * LEAK_RATE
                elif I < -ilmi:
                    I = I - (I + ilmi) * LEAK_RATE
            if ki == 0.0:  # AC_PID::update_i
                I = 0.0
            elif limited == 0.0 or (I > 0.0 and En < 0.0) or (I < 0.0 and En > 0.0):
                I = min(max(I + En * ki * dt, -k[6, i, b]), k[6, i, b])
            raw[i] = k[1, i, b] * En + I + k[3, i, b] * Dn + k[4, i, b] * Tn + k[5, i, b] * (Tn - T) / dt
            new[0, i, b], new[1, i, b], new[2, i, b], new[3, i, b], new[4, i, b], new[5, i, b] = d1, d2, Tn, En, Dn, I
        for i in range(3):
            c = min(max(raw[i], -1.0), 1.0)
            sat[i, b] = c != raw[i]
            out[i, b] = c
        radius = k[13, 0, b]
        norm = math.hypot(out[0, b], out[1, b])
        if norm > radius:  # the swash's cyclic limit
            out[0, b] *= radius / norm
            out[1, b] *= radius / norm
            sat[0, b] = True
            sat[1, b] = True
        for i in range(3):
            new[6, i, b] = 1.0 if sat[i, b] else 0.0
