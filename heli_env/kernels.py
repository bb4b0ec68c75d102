"""Fused numba loops of the native vector environment's step.

A numpy batch pays one pass over memory and one interpreter round trip per
arithmetic operation: stepping the model (eqs. 18, 21, 25-26, 31) and building
the observation takes about 150 of them per step. The loops here do the same
arithmetic in one pass per copy:

* :func:`clip_actions` checks and clips the actions.
* :func:`advance_kernel` compiles the physics core's own statements
  (:func:`identification.model.discrete_step_statements`, the text the single
  environment's step is compiled from) into a loop that also adds the trim
  sticks of each copy's library row, scales its gust and prepares the Euler
  angles (eqs. 27-29). numba compiles IEEE arithmetic in the order written
  and does not contract multiply-adds (``fastmath`` is off), so every copy's
  state equals the single environment's bit for bit.
* The three inverse trigonometric functions stay with numpy, whose SIMD
  ``arctan2`` / ``arcsin`` cost a few microseconds for thousands of copies,
  where a scalar libm call in the loop would cost tens of nanoseconds per copy.
* :func:`observe_kernel` turns the angles into the observation, the reward,
  the info arrays in degrees and the episode ends.

The two long loops run over the copies with ``numba.prange`` on numba's thread
pool (all cores by default; ``HeliAttitudeVectorEnv(threads=...)`` or
``NUMBA_NUM_THREADS`` limit it). Copies are independent, so the results are the
same for any number of threads.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numba
import numpy as np

from identification.model import DISCRETE_OUTPUTS, ModelParams, discrete_step_statements

ROW_PAD = 8
"""Extra columns per row of the batched arrays. Rows of exactly 4096 float64 lie 32 KiB
apart and fall into the same cache sets; a loop that reads and writes a dozen such rows
per copy evicts its own lines (measured: the step loop took 225 us instead of 61 us)."""


def batch_rows(rows: int, n: int, fill: float | None = 0.0) -> np.ndarray:
    """A float64 ``(rows, n)`` array whose rows are :data:`ROW_PAD` columns apart in memory.

    Filled with ``fill``, or left uninitialised with ``fill=None`` (for outputs a loop writes whole).
    """
    buf = np.empty((rows, n + ROW_PAD)) if fill is None else np.full((rows, n + ROW_PAD), fill)
    return buf[:, :n]


def _clip_line(name: str) -> str:
    """``np.clip(v, -1, 1)`` and the single env's ``min(1.0, max(-1.0, v))`` for finite ``v``."""
    return f"{name} = -1.0 if {name} < -1.0 else (1.0 if {name} > 1.0 else {name})"


_EULER_ARGUMENTS = (
    "trig[0, i] = 2.0 * (b0 * b1 + b2 * b3)",
    "trig[1, i] = 1.0 - 2.0 * (b1 * b1 + b2 * b2)",
    "v = 2.0 * (b0 * b2 - b3 * b1)",
    "trig[2, i] = -1.0 if v < -1.0 else (1.0 if v > 1.0 else v)",
    "trig[3, i] = 2.0 * (b0 * b3 + b1 * b2)",
    "trig[4, i] = 1.0 - 2.0 * (b2 * b2 + b3 * b3)",
)
"""Arguments of roll = atan2(trig0, trig1), pitch = asin(trig2), yaw = atan2(trig3, trig4) of the
quaternion ``b0..b3``: the expressions of :func:`identification.model.euler_from_quaternion`."""


def _compile(lines: list[str], name: str, tag: str):
    """numba-compile generated source; a loop written ``prange`` runs over copies on numba's threads."""
    source = "\n".join(lines) + "\n"
    namespace = {"abs": abs, "np": np, "isfinite": math.isfinite, "prange": numba.prange}
    exec(compile(source, f"<heli-env {tag} {hash(source) & 0xFFFFFFFF:08x}>", "exec"), namespace)  # noqa: S102
    return numba.njit(error_model="numpy", parallel="prange(" in source)(namespace[name])


@lru_cache(maxsize=16)
def advance_kernel(params: ModelParams, dt: float):
    """The compiled loop ``advance(table, base, k, last, ratio, act, gust, x, ud, trig)`` of one control period.

    For each copy ``i``: reads library row ``j = base[i] + min(k[i], last[i]) * ratio``
    of ``table`` (trim lat/lon/ped, collective, gust torque roll/pitch/yaw, u_d
    roll/pitch/yaw) and increments ``k[i]``. Steps the state ``x[:, i]`` in
    place with the sticks ``clip(trim + act[:, i])`` and the torque
    ``gust[i] * torque``, writes the reported gust ``gust[i] * u_d`` to
    ``ud[:, i]`` and the Euler-angle arguments of the new attitude to
    ``trig[:, i]`` (see :data:`_EULER_ARGUMENTS`).

    The rows are first touched in a short loop: its loads are independent, so
    the processor keeps many cache misses in flight; the long loop body that
    follows finds the rows in cache instead of waiting on them one by one.
    """
    lines = [
        "def advance(table, base, k, last, ratio, act, gust, x, ud, trig):",
        "    touched = 0.0",
        "    for i in prange(base.shape[0]):",
        "        j = base[i] + min(k[i], last[i]) * ratio",
        "        touched += table[j, 0] + table[j, 9]",
        "    for i in prange(base.shape[0]):",
        "        j = base[i] + min(k[i], last[i]) * ratio",
        "        k[i] += 1",
        "        g = gust[i]",
        "        lat = table[j, 0] + act[0, i]",
        "        " + _clip_line("lat"),
        "        lon = table[j, 1] + act[1, i]",
        "        " + _clip_line("lon"),
        "        ped = table[j, 2] + act[2, i]",
        "        " + _clip_line("ped"),
        "        col = table[j, 3]",
        "        d0 = g * table[j, 4]",
        "        d1 = g * table[j, 5]",
        "        d2 = g * table[j, 6]",
        "        p = x[0, i]; q = x[1, i]; r = x[2, i]; z0 = x[3, i]; z1 = x[4, i]; z2 = x[5, i]",
        "        q0 = x[6, i]; q1 = x[7, i]; q2 = x[8, i]; q3 = x[9, i]",
        *("        " + line for line in discrete_step_statements(params, float(dt))),
        *(f"        x[{row}, i] = {name}" for row, name in enumerate(DISCRETE_OUTPUTS)),
        "        ud[0, i] = g * table[j, 7]; ud[1, i] = g * table[j, 8]; ud[2, i] = g * table[j, 9]",
        *("        " + line for line in _EULER_ARGUMENTS),
        "    return touched",
    ]
    return _compile(lines, "advance", "fused step")


@lru_cache(maxsize=1)
def euler_arguments_kernel():
    """The compiled loop ``euler_arguments(x, trig, which)``: :data:`_EULER_ARGUMENTS` of copies ``which``."""
    lines = [
        "def euler_arguments(x, trig, which):",
        "    for i in which:",
        "        b0 = x[6, i]; b1 = x[7, i]; b2 = x[8, i]; b3 = x[9, i]",
        *("        " + line for line in _EULER_ARGUMENTS),
    ]
    return _compile(lines, "euler_arguments", "euler arguments")


@numba.njit(error_model="numpy", cache=True)
def clip_actions(actions, out):
    """Clip ``actions`` (n, 3) to [-1, 1] into ``out`` (3, n); return the first copy with a non-finite action, or -1."""
    for i in range(actions.shape[0]):
        for c in range(3):
            v = float(actions[i, c])
            if not math.isfinite(v):
                return i
            out[c, i] = -1.0 if v < -1.0 else (1.0 if v > 1.0 else v)
    return -1


@lru_cache(maxsize=8)
def observe_kernel(task: str, noisy: bool):
    """The compiled loop ``observe(att, x, ref_att, ref_rate, meas_att, meas_rate, prev, max_rate, max_angle,
    coef, k, steps, obs, deg_att, deg_rate, reward, terminated, truncated)``, specialised on the task.

    ``att`` (3, n): roll, pitch, yaw [rad]; ``ref_att``/``ref_rate`` (3, n): the
    references (read only where the task has them: attitude for ``"track"``,
    rate for ``"track"`` and ``"rate"``); ``meas_att``/``meas_rate`` (3, n): the
    measured angles and rates (read only when ``noisy``); ``prev`` (3, n): the
    action applied; ``coef``: :func:`heli_env.tasks.reward_coefficients`;
    ``k``/``steps`` (n): steps taken and allowed. Writes ``obs`` (n, 12)
    float32, ``deg_att``/``deg_rate`` (3, n), ``reward`` (n), ``terminated``
    (attitude beyond ``max_angle`` or a rate not finite) and ``truncated``
    (otherwise, at the step limit). The same expressions as the single
    environment's ``_observe`` and :func:`heli_env.tasks.reward_from_sums`,
    written out per axis.
    """
    two_pi = repr(2.0 * math.pi)

    def wrap(v):
        return f"({v}) - {two_pi} * np.round(({v}) / {two_pi})"

    def bound(v):
        return f"-max_rate if {v} < -max_rate else (max_rate if {v} > max_rate else {v})"

    lines = [
        "def observe(att, x, ref_att, ref_rate, meas_att, meas_rate, prev, max_rate, max_angle, coef, k, steps,",
        "            obs, deg_att, deg_rate, reward, terminated, truncated):",
        "    ca = coef[0]",
        "    cr = coef[1]",
        "    cu = coef[2]",
        "    for i in prange(att.shape[1]):",
    ]
    for c, w in enumerate(("p", "q", "r")):
        err = wrap(f"ref_att[{c}, i] - att[{c}, i]") if task == "track" else f"-att[{c}, i]"
        ref = f"ref_rate[{c}, i]" if task in ("track", "rate") else "0.0"
        lines += [f"        e{c} = {err}", f"        {w} = x[{c}, i]", f"        r{c} = {ref} - {w}",
                  f"        u{c} = prev[{c}, i]",
                  f"        deg_att[{c}, i] = e{c} * {repr(180.0 / math.pi)}",
                  f"        deg_rate[{c}, i] = r{c} * {repr(180.0 / math.pi)}"]
        if noisy:
            shown = (wrap(f"ref_att[{c}, i] - meas_att[{c}, i]") if task == "track"
                     else wrap(f"-meas_att[{c}, i]"))
            lines += [f"        m{c} = meas_rate[{c}, i]", f"        mr{c} = {ref} - m{c}",
                      f"        obs[i, {c}] = {shown}"]
            rate, rate_err = f"m{c}", f"mr{c}"
        else:
            lines.append(f"        obs[i, {c}] = e{c}")
            rate, rate_err = w, f"r{c}"
        lines += [f"        obs[i, {3 + c}] = {bound(rate)}", f"        obs[i, {6 + c}] = {bound(rate_err)}",
                  f"        obs[i, {9 + c}] = u{c}"]
    att2 = "0.0" if task == "rate" else "(e0 * e0 + e1 * e1 + e2 * e2)"
    lines += [
        f"        reward[i] = -(ca * {att2} + cr * (r0 * r0 + r1 * r1 + r2 * r2) + cu * (u0 * u0 + u1 * u1 + u2 * u2))",
        "        ok = (abs(att[0, i]) <= max_angle and abs(att[1, i]) <= max_angle and isfinite(p) and isfinite(q)",
        "              and isfinite(r))",
        "        terminated[i] = not ok",
        "        truncated[i] = ok and k[i] >= steps[i]",
    ]
    return _compile(lines, "observe", f"observe {task}{' noisy' if noisy else ''}")
