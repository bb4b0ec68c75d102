"""A second, plain implementation of the two firmware loops, used only to cross-check the package's.

Written apart from ``controllers.firmware`` (it imports nothing from it) and in the firmwares' own shape:
one axis, one tick, Python floats, the parameter *names* the firmwares use (``ATC_RAT_RLL_P``,
``roll_p_gain``), the statements in the order of the C sources (ArduPilot AC_AttitudeControl_Heli.cpp
``rate_bf_to_motor_roll_pitch``, AC_PID.cpp ``update_all``/``update_i``, AC_HELI_PID.cpp
``update_leaky_i``, AP_Math control.cpp ``sqrt_controller``, LowPassFilter2p.cpp; Rotorflight pid.c
``pidApplyCyclicMode3``/``pidApplyYawMode3``, leveling.c ``angleModeApply``, filter.c). It reads the
exported parameter files itself (:func:`read_param_file`, :func:`read_cli_file`) and flies a truth aircraft
with its own per-tick loop around the physics core's scalar RK4 (:func:`fly`).

The package's loops are vectorised over axes, sets and gust windows; agreement of the two on the same
inputs (tests/test_firmware_loops.py) and of the errors they fly (scripts/firmware_tune_check.py) is the
cross-check the issue asks for.
"""

from __future__ import annotations

import math

AXIS_AP = ("RLL", "PIT", "YAW")
AXIS_RF = ("roll", "pitch", "yaw")

AP_DEFAULTS = {"ANG_P": 4.5, "RAT_RP_P": 0.024, "RAT_RP_I": 0.15, "RAT_RP_D": 0.001, "RAT_RP_FF": 0.15,
               "RAT_RP_IMAX": 0.4, "RAT_YAW_P": 0.18, "RAT_YAW_I": 0.12, "RAT_YAW_D": 0.003,
               "RAT_YAW_FF": 0.024, "RAT_YAW_IMAX": 0.4, "FLT": 20.0, "ILMI": 0.05,
               "ACCEL_RP": 110000.0, "ACCEL_Y": 27000.0, "SCHED_LOOP_RATE": 400.0, "INS_GYRO_FILTER": 20.0,
               "H_CYC_MAX": 2500.0}


def read_param_file(path) -> dict:
    """``NAME,VALUE`` lines (Mission Planner), ``#`` comments skipped: {name: float}."""
    out = {}
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            line = line.split("#", 1)[0].strip()
            if line:
                name, value = line.split(",")
                out[name.strip()] = float(value)
    return out


def read_cli_file(path) -> dict:
    """Rotorflight CLI ``set name = value`` lines: {name: value as float or list of floats}."""
    out = {}
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            line = line.strip()
            if line.startswith("set "):
                name, value = line[4:].split("=")
                parts = [float(v) for v in value.split(",")]
                out[name.strip()] = parts[0] if len(parts) == 1 else parts
    return out


# ------------------------------------------------------------------------------------------ ArduPilot
class PlainArduPilotAxis:
    """One axis of ArduPilot's heli attitude and rate loops, one tick per :meth:`update`."""

    def __init__(self, params: dict, axis: int):
        a = AXIS_AP[axis]
        rp = "RP" if axis < 2 else "YAW"

        def get(name, default):
            return float(params.get(name, default))

        self.axis = axis
        self.rate_hz = get("SCHED_LOOP_RATE", AP_DEFAULTS["SCHED_LOOP_RATE"])
        self.dt = 1.0 / self.rate_hz
        self.ang_p = get(f"ATC_ANG_{a}_P", AP_DEFAULTS["ANG_P"])
        self.kp = get(f"ATC_RAT_{a}_P", AP_DEFAULTS[f"RAT_{rp}_P"])
        self.ki = get(f"ATC_RAT_{a}_I", AP_DEFAULTS[f"RAT_{rp}_I"])
        self.kd = get(f"ATC_RAT_{a}_D", AP_DEFAULTS[f"RAT_{rp}_D"])
        self.kff = get(f"ATC_RAT_{a}_FF", AP_DEFAULTS[f"RAT_{rp}_FF"])
        self.kdff = get(f"ATC_RAT_{a}_D_FF", 0.0)
        self.imax = get(f"ATC_RAT_{a}_IMAX", AP_DEFAULTS[f"RAT_{rp}_IMAX"])
        self.ilmi = get(f"ATC_RAT_{a}_ILMI", AP_DEFAULTS["ILMI"] if axis < 2 else 0.0)
        self.flt_t = get(f"ATC_RAT_{a}_FLTT", AP_DEFAULTS["FLT"])
        self.flt_e = get(f"ATC_RAT_{a}_FLTE", AP_DEFAULTS["FLT"])
        self.flt_d = get(f"ATC_RAT_{a}_FLTD", 0.0)
        accel_name = ("ATC_ACCEL_R_MAX", "ATC_ACCEL_P_MAX", "ATC_ACCEL_Y_MAX")[axis]
        accel = get(accel_name, AP_DEFAULTS["ACCEL_RP" if axis < 2 else "ACCEL_Y"])  # cdeg/s/s
        lo, hi = ((40.0, 720.0) if axis < 2 else (10.0, 120.0))
        self.accel = 0.0 if accel <= 0 else min(max(math.radians(accel / 100.0) / 2.0, math.radians(lo)),
                                                math.radians(hi))
        f = get("INS_GYRO_FILTER", AP_DEFAULTS["INS_GYRO_FILTER"])
        self.biquad = None
        if f > 0:
            fr = self.rate_hz / f
            ohm = math.tan(math.pi / fr)
            c = 1.0 + 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm
            b0 = ohm * ohm / c
            self.biquad = (b0, 2.0 * b0, b0, 2.0 * (ohm * ohm - 1.0) / c,
                           (1.0 - 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm) / c)
        self.d1 = self.d2 = 0.0
        self.target = self.error = self.derivative = self.integrator = 0.0
        self.limit = False

    @staticmethod
    def alpha(dt, cutoff):
        if cutoff <= 0:
            return 1.0
        rc = 1.0 / (2.0 * math.pi * cutoff)
        return dt / (dt + rc)

    def gyro(self, sample):
        """LowPassFilter2p::apply."""
        if self.biquad is None:
            return sample
        b0, b1, b2, a1, a2 = self.biquad
        d0 = sample - self.d1 * a1 - self.d2 * a2
        out = d0 * b0 + self.d1 * b1 + self.d2 * b2
        self.d2, self.d1 = self.d1, d0
        return out

    def sqrt_controller(self, error):
        p, lim, dt = self.ang_p, self.accel, self.dt
        if lim <= 0:
            rate = error * p
        elif p == 0:
            rate = math.copysign(math.sqrt(2.0 * lim * abs(error)), error) if error else 0.0
        else:
            linear_dist = lim / (p * p)
            if error > linear_dist:
                rate = math.sqrt(2.0 * lim * (error - linear_dist / 2.0))
            elif error < -linear_dist:
                rate = -math.sqrt(2.0 * lim * (-error - linear_dist / 2.0))
            else:
                rate = error * p
        return max(-abs(error) / dt, min(abs(error) / dt, rate))

    def update(self, att_error, gyro_rate, leaky=True):
        """One tick: the rate PID output before the motors' clamps (AC_PID::update_all + get_ff)."""
        dt = self.dt
        measured = self.gyro(gyro_rate)
        rate_target = self.sqrt_controller(att_error)
        if leaky and self.axis < 2 and self.ki != 0.0:  # AC_HELI_PID::update_leaky_i
            if self.integrator > self.ilmi:
                self.integrator -= (self.integrator - self.ilmi) * 0.02
            elif self.integrator < -self.ilmi:
                self.integrator -= (self.integrator + self.ilmi) * 0.02
        previous_target = self.target
        self.target += self.alpha(dt, self.flt_t) * (rate_target - self.target)
        error_last = self.error
        self.error += self.alpha(dt, self.flt_e) * ((self.target - measured) - self.error)
        derivative = (self.error - error_last) / dt
        self.derivative += self.alpha(dt, self.flt_d) * (derivative - self.derivative)
        if self.ki != 0.0:  # AC_PID::update_i
            if (not self.limit or (self.integrator > 0 and self.error < 0)
                    or (self.integrator < 0 and self.error > 0)):
                self.integrator += self.error * self.ki * dt
                self.integrator = max(-self.imax, min(self.imax, self.integrator))
        else:
            self.integrator = 0.0
        return (self.error * self.kp + self.integrator + self.derivative * self.kd + self.target * self.kff
                + self.kdff * (self.target - previous_target) / dt)


class PlainArduPilot:
    """The three axes, the output clamps and the swash's cyclic limit (AP_MotorsHeli_Single)."""

    def __init__(self, params: dict):
        self.axes = [PlainArduPilotAxis(params, i) for i in range(3)]
        self.rate_hz = self.axes[0].rate_hz
        self.cyc = float(params.get("H_CYC_MAX", AP_DEFAULTS["H_CYC_MAX"])) / 4500.0

    def update(self, att_error, gyro):
        out = [ax.update(e, g) for ax, e, g in zip(self.axes, att_error, gyro)]
        clamped = [max(-1.0, min(1.0, v)) for v in out]
        limits = [c != v for c, v in zip(clamped, out)]
        total = math.hypot(clamped[0], clamped[1])
        if total > self.cyc:
            ratio = self.cyc / total
            clamped[0] *= ratio
            clamped[1] *= ratio
            limits[0] = limits[1] = True
        for ax, lim in zip(self.axes, limits):
            ax.limit = lim
        return clamped


# ----------------------------------------------------------------------------------------- Rotorflight
RF_SCALES = {"p": (0.00000666666, 0.00000666666, 0.00006666666), "i": (0.0002, 0.0002, 0.0005),
             "d": (0.1e-6, 1.0e-6, 1.0e-6), "f": (0.000025, 0.000025, 0.000025), "b": (0.1e-6, 0.1e-6, 1.0e-6)}
RF_DEFAULTS = {"p": (50, 50, 80), "i": (100, 100, 120), "d": (10, 40, 40), "f": (100, 100, 0), "b": (0, 0, 0),
               "error_limit": (30, 30, 45), "d_cutoff": (15, 15, 20), "b_cutoff": (15, 15, 20),
               "gyro_cutoff": (50, 50, 100)}


class PlainRotorflightAxis:
    """One axis of Rotorflight's pid_mode 3 (angle mode on roll and pitch)."""

    def __init__(self, params: dict, axis: int, rate_hz: float):
        name = AXIS_RF[axis]

        def get(key, default):
            return float(params.get(key, default))

        def arr(key, default):
            v = params.get(key)
            return float(default[axis] if v is None else v[axis])

        self.axis, self.fs, self.dt = axis, rate_hz, 1.0 / rate_hz
        self.k = {t: RF_SCALES[t][axis] * get(f"{name}_{t}_gain", RF_DEFAULTS[t][axis]) for t in "pidfb"}
        self.error_limit = arr("error_limit", RF_DEFAULTS["error_limit"])
        self.level = get("angle_level_strength", 40) / 10.0 if axis < 2 else 0.0
        self.dif_d = self.difference_filter(get(f"{name}_d_cutoff", RF_DEFAULTS["d_cutoff"][axis]))
        self.dif_b = self.difference_filter(get(f"{name}_b_cutoff", RF_DEFAULTS["b_cutoff"][axis]))
        gyro_cut = min(get(f"{name}_gyro_cutoff", RF_DEFAULTS["gyro_cutoff"][axis]), 0.475 * rate_hz)
        self.gyro_on = gyro_cut > 0
        w = math.tan(math.pi * gyro_cut / rate_hz)
        self.g_b, self.g_a1 = w / (w + 1.0), (w - 1.0) / (w + 1.0)
        lpf1 = min(get("gyro_lpf1_static_hz", 100), 0.475 * rate_hz)
        self.lpf1 = 1.0 if lpf1 <= 0 else min(lpf1 / (lpf1 + rate_hz / (2 * math.pi)), 1.0)
        relax_cut = min(max(arr("iterm_relax_cutoff", (10, 10, 10)), 1.0), 100.0)
        self.relax_gain = relax_cut / (relax_cut + rate_hz / (2 * math.pi))
        self.relax_level = min(max(arr("iterm_relax_level", (40, 40, 40)), 10.0), 250.0)
        self.relax_on = str(params.get("iterm_relax_type", "RPY")).upper() != "OFF"
        if axis < 2:
            t, lim = get("error_decay_time_cyclic", 250), get("error_decay_limit_cyclic", 12)
            self.decay_rate = (10.0 / t) * 12 * 0.08 if t else 0.0
            self.decay_limit = lim * 12 * 0.08 if lim else 3600.0
        else:
            t, lim = get("error_decay_time_yaw", 0), get("error_decay_limit_yaw", 0)
            self.decay_rate = 10.0 / t if t else 0.0
            self.decay_limit = lim if lim else 3600.0
        self.cw, self.ccw = get("yaw_cw_stop_gain", 120) / 100.0, get("yaw_ccw_stop_gain", 80) / 100.0
        self.lp = self.gx = self.gy = 0.0
        self.d_x = self.d_y = self.b_x = self.b_y = 0.0
        self.axis_error = self.relax = 0.0
        self.saturated = False

    def difference_filter(self, cutoff):
        cutoff = min(cutoff, 0.475 * self.fs)
        k = math.tan(math.pi * cutoff / self.fs)
        return (k - 1.0) / (k + 1.0), 2.0 * math.pi * cutoff / (k + 1.0)

    def update(self, att_error, gyro_rate):
        """One tick: the PID sum (mixer units)."""
        dt = self.dt
        self.lp += (math.degrees(gyro_rate) - self.lp) * self.lpf1
        if self.gyro_on:
            g = self.g_b * self.lp + self.g_b * self.gx - self.g_a1 * self.gy
        else:
            g = self.lp
        self.gx, self.gy = self.lp, g
        setpoint = self.level * math.degrees(att_error)
        error = setpoint - g
        if self.axis == 2:
            x = min(max((error + 10.0) / 20.0, 0.0), 1.0)
            p_term = self.k["p"] * error * (self.ccw + (self.cw - self.ccw) * x)
        else:
            p_term = self.k["p"] * error
        a, b = self.dif_d
        dterm = b * (-g) - b * self.d_x - a * self.d_y
        self.d_x, self.d_y = -g, dterm
        self.relax += (setpoint - self.relax) * self.relax_gain
        iterm_error = error
        if self.relax_on:
            iterm_error *= max(0.0, 1.0 - abs(setpoint - self.relax) / self.relax_level)
        if not (self.saturated and self.axis_error * iterm_error > 0):
            self.axis_error += iterm_error * dt
        self.axis_error = max(-self.error_limit, min(self.error_limit, self.axis_error))
        i_term = self.k["i"] * self.axis_error
        decay = max(-self.decay_limit, min(self.decay_limit, self.axis_error * self.decay_rate))
        self.axis_error -= decay * dt
        a, b = self.dif_b
        bterm = b * setpoint - b * self.b_x - a * self.b_y
        self.b_x, self.b_y = setpoint, bterm
        return p_term + i_term + self.k["d"] * dterm + self.k["f"] * setpoint + self.k["b"] * bterm


class PlainRotorflight:
    """The three axes and the mixer's input limit."""

    def __init__(self, params: dict, rate_hz: float = 1000.0, output_limit: float = 1.25):
        self.rate_hz = rate_hz
        self.limit = output_limit
        self.axes = [PlainRotorflightAxis(params, i, rate_hz) for i in range(3)]

    def update(self, att_error, gyro):
        out = []
        for ax, e, g in zip(self.axes, att_error, gyro):
            v = ax.update(e, g)
            c = max(-self.limit, min(self.limit, v))
            ax.saturated = c != v
            out.append(c)
        return out


# ------------------------------------------------------------------------------------- the closed loop
def fly(params, controller, scale, signs, torque, collective, trim, dt=0.01, att_noise=None, gyro_noise=None):
    """Fly ``controller`` on the aircraft ``params`` (per-tick scalar loop); attitude errors at each period's start.

    The physics core's scalar RK4 (``heli_core.physics.kernel``) advances one tick per controller update; the
    gust torque (3, n), the collective (n,), the trim (3, n) and the sensor errors (3, n) are held over each
    period ``dt``.

    Returns
    -------
    list of 3 lists of float
        Attitude error (−angle) [rad] of roll, pitch, yaw at the start of each period; a flight that leaves
        ±60° in roll or pitch stops there.
    """
    from heli_core.physics import kernel
    from heli_core.quaternion import euler_from_quaternion_scalar

    rk4 = kernel(params)[0]["rk4"]
    m = int(round(dt * controller.rate_hz))
    h = dt / m
    n = len(collective)
    x = (0.0, 0.0, 0.0, float(trim[0][0]), float(trim[1][0]), float(trim[2][0]), 1.0, 0.0, 0.0, 0.0)
    errors = [[], [], []]
    for k in range(n):
        an = [0.0, 0.0, 0.0] if att_noise is None else [float(att_noise[i][k]) for i in range(3)]
        gn = [0.0, 0.0, 0.0] if gyro_noise is None else [float(gyro_noise[i][k]) for i in range(3)]
        d = (float(torque[0][k]), float(torque[1][k]), float(torque[2][k]))
        for j in range(m):
            ang = list(euler_from_quaternion_scalar(*x[6:10]))
            if j == 0:
                for i in range(3):
                    errors[i].append(-ang[i])
                if abs(ang[0]) > math.radians(60) or abs(ang[1]) > math.radians(60) or not all(map(math.isfinite, x)):
                    return errors
            out = controller.update([-(a + e) for a, e in zip(ang, an)], [x[i] + gn[i] for i in range(3)])
            sticks = [max(-1.0, min(1.0, float(trim[i][k]) + max(-1.0, min(1.0, signs[i] * scale[i] * out[i]))))
                      for i in range(3)]
            x = rk4(x, (sticks[0], sticks[1], float(collective[k]), sticks[2]), d, h)
    return errors
