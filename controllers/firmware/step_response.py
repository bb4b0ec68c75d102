"""A firmware loop's response to a commanded attitude step, for the flight-test card (no gusts).

The pilot's first check of a new tune is a stick rap: command a few degrees, let go, watch the aircraft
follow and stop. :func:`step_response` flies that on the identified model: the loop at its own rate, the
physics core's exact discrete step at the tick, the trim for the library's mean collective, a step of the
attitude reference on one axis at t = 0. ArduPilot shapes the reference first (``ATC_INPUT_TC`` and the
axis' ``ATC_ACCEL_*_MAX``: :func:`~controllers.firmware.ardupilot.input_shaping_angle`, whose rate is the
loop's feed-forward); Rotorflight's angle mode takes the step as it comes. Rotorflight's tail holds a rate,
not a heading, so it has no yaw step.
"""

from __future__ import annotations

import math

import numpy as np

from heli_core.physics import trim_sticks
from heli_core.quaternion import euler_from_quaternion_scalar

from ..replay import zoh_step
from .ardupilot import input_shaping_angle


def step_response(spec, params, model_params, scale, signs, axis: int, step_deg: float = 10.0,
                  seconds: float = 3.0, collective: float = 0.0) -> dict | None:
    """Overshoot [%], 90 % rise time [s] and the time it stays within ±10 % of the step [s] after a step of
    ``step_deg`` on ``axis``; None where the firmware has no such command (Rotorflight's yaw).

    Returns
    -------
    dict or None
        ``{"step_deg", "overshoot_pct", "rise_90_s", "settle_10pct_s", "time_s" (list), "angle_deg" (list)}``;
        ``rise_90_s``/``settle_10pct_s`` None where the response never gets there within ``seconds``.
    """
    if spec.name == "rotorflight" and axis == 2:
        return None
    loop = spec.loop_class(params, scale, signs)
    h = loop.dt
    n = int(round(seconds / h))
    step = zoh_step(model_params, h)
    trim = [float(v) for v in trim_sticks(model_params, float(collective))]
    x = (0.0, 0.0, 0.0, trim[0], trim[1], trim[2], 1.0, 0.0, 0.0, 0.0)
    mem = loop.initial_memory()
    ref = math.radians(step_deg)
    shaped, shaped_rate = 0.0, 0.0
    accel = params.accel_max[axis] * 0.01 * math.pi / 180.0 if spec.name == "ardupilot" else 0.0
    angles = np.empty(n)
    for k in range(n):
        ang = euler_from_quaternion_scalar(*x[6:10])
        angles[k] = ang[axis]
        target = np.zeros(3)
        ff = np.zeros(3)
        if spec.name == "ardupilot":
            shaped_rate = float(input_shaping_angle(ref - shaped, params.input_tc, accel, shaped_rate, h))
            shaped += shaped_rate * h
            target[axis], ff[axis] = shaped, shaped_rate
        else:
            target[axis] = ref
        out, mem, _ = loop.tick(mem, target - np.array(ang), np.array(x[0:3]), ff)
        s = np.clip(np.array(trim) + np.clip(loop.sticks(out), -1.0, 1.0), -1.0, 1.0)
        x = step(x, (s[0], s[1], 0.0 + collective, s[2]), (0.0, 0.0, 0.0))
        if not all(map(math.isfinite, x)):
            return {"step_deg": step_deg, "overshoot_pct": None, "rise_90_s": None, "settle_10pct_s": None,
                    "diverged": True}
    t = np.arange(n) * h
    frac = angles / ref
    rise = np.flatnonzero(frac >= 0.9)
    outside = np.flatnonzero(np.abs(frac - 1.0) > 0.1)
    settle = None if outside.size and outside[-1] == n - 1 else float(t[outside[-1] + 1]) if outside.size else 0.0
    every = max(1, n // 300)
    return {"step_deg": step_deg, "overshoot_pct": float(max(0.0, frac.max() - 1.0) * 100.0),
            "rise_90_s": float(t[rise[0]]) if rise.size else None, "settle_10pct_s": settle, "diverged": False,
            "time_s": t[::every].tolist(), "angle_deg": np.degrees(angles[::every]).tolist()}
