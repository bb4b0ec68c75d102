"""Fused numba loops of the native vector environment's step.

A numpy batch pays one pass over memory and one interpreter round trip per
arithmetic operation: stepping the model (eqs. 18, 21, 25-26, 31) and building
the observation takes about 150 of them per step. The loops here do the same
arithmetic over the copies' rows of one :class:`BlockLayout`, a block of
:data:`BLOCK` copies at a time, and a step is one call (:func:`env_kernels`),
that finishes each block before it takes the next, while the block's rows are
in the core's cache:

* :func:`_advance_lines`: the action (checked before by :func:`first_non_finite`),
  the library row, the physics core's own statements
  (:func:`heli_core.discrete.discrete_step_statements`, the text the single
  environment's step is compiled from) and the Euler angles (eqs. 27-29). numba
  compiles IEEE arithmetic in the order written and does not contract
  multiply-adds (``fastmath`` is off), so every copy's state equals the single
  environment's bit for bit. The angles use the branch-free ``atan2``/``asin`` of
  :mod:`heli_env.vector_math` (within 1-2 ulp of the C library's, as numpy's are).
* :func:`_observe_lines`: the sensor noise, the observation, the reward, the info
  values in degrees and the episode ends, also run for chosen copies after a reset.

Every row of a block lies a compile-time constant (:data:`ROW`) from the next, so
the compiler can prove that a loop's rows do not overlap and runs the arithmetic
several copies an instruction (8 where LLVM uses 512-bit vectors, as on Zen 4; 4 with
AVX2 and on the AVX-512 Xeons it tunes for 256 bits); the same values come out as one
copy at a time, since vector lanes round as scalars do. The blocks of the step
loop are a ``numba.prange`` when numba's pool is used (:mod:`heli_env.threads`).
Copies are independent, so the results are the same for any number of threads.
"""

from __future__ import annotations

import math
import re
from functools import lru_cache
from typing import NamedTuple

import numba
import numpy as np

from heli_core.discrete import DISCRETE_INPUTS, DISCRETE_OUTPUTS, discrete_step_statements
from heli_core.params import ModelParams
from heli_core.physics import N_STATE
from heli_core.quaternion import EULER_ARGUMENTS

from .kernel_modules import compile_module as _compile_module
from .sensor_noise import LOW32, fast_normal, standard_normal, stream_bits
from .vector_math import asinv, atan2v
from .observation import OBS_DIM
from .tasks import TWO_PI


def _clip_line(name: str) -> str:
    """``np.clip(v, -1, 1)`` and the single env's ``min(1.0, max(-1.0, v))`` for finite ``v``."""
    return f"{name} = -1.0 if {name} < -1.0 else (1.0 if {name} > 1.0 else {name})"


def _on_new_quaternion(expression: str) -> str:
    """An expression of :data:`heli_core.quaternion.EULER_ARGUMENTS` over ``q0..q3`` read on ``b0..b3``."""
    return re.sub(r"\bq([0-3])\b", r"b\1", expression)


_ON_B = [_on_new_quaternion(e) for e in EULER_ARGUMENTS]
_EULER_ARGUMENTS = (
    f"_e0 = {_ON_B[0]}",
    f"_e1 = {_ON_B[1]}",
    f"_e2 = {_ON_B[2]}",
    "_e2 = -1.0 if _e2 < -1.0 else (1.0 if _e2 > 1.0 else _e2)",
    f"_e3 = {_ON_B[3]}",
    f"_e4 = {_ON_B[4]}",
)
"""Arguments of roll = atan2(_e0, _e1), pitch = asin(_e2), yaw = atan2(_e3, _e4) of the quaternion ``b0..b3``:
the one text of the conversion, :data:`heli_core.quaternion.EULER_ARGUMENTS`, with the pitch argument clipped
to [-1, 1]."""


def _angle_lines() -> list[str]:
    """The Euler angles (eqs. 27-29) of the quaternion ``b0..b3`` into rows ``att`` [rad], by the branch-free
    :func:`heli_env.vector_math.atan2v` / :func:`~heli_env.vector_math.asinv`, so that the loop stays 8 copies
    an instruction."""
    return [*_EULER_ARGUMENTS, f"{_at('att0')} = atan2v(_e0, _e1)", f"{_at('att1')} = asinv(_e2)",
            f"{_at('att2')} = atan2v(_e3, _e4)"]


BLOCK = 256
"""Copies per block of the batch state (:class:`BlockLayout`): the loops take a block at a time, numba's
threads whole blocks."""

ROW = BLOCK + 8
"""Distance in float64 between two rows of a block. A compile-time constant, so that the compiler sees that
the rows a loop reads and writes never overlap and steps 8 copies per AVX-512 instruction (with rows of a
runtime length it must assume they might, and steps one copy at a time: 38 ns per copy instead of 5). Eight
more than :data:`BLOCK`: rows 2 KiB apart would fall into the same cache sets."""

CHUNK = BLOCK
"""Copies one task of the step loop handles (the threads take whole blocks)."""

_ROWS = ("x0 x1 x2 x3 x4 x5 x6 x7 x8 x9 act0 act1 act2 gust att0 att1 att2 "
         "refatt0 refatt1 refatt2 refrate0 refrate1 refrate2 prev0 prev1 prev2").split()
_OUTPUTS = "ud0 ud1 ud2 degatt0 degatt1 degatt2 degrate0 degrate1 degrate2 reward end".split()
R = {name: i for i, name in enumerate(_ROWS + _OUTPUTS)}
"""Row of each per-copy quantity in a block: the state (10), the action applied (3), the gust scale, the
Euler angles (3), the references (3 + 3), the action applied the step before (3: kept only with a
stick-step weight in the reward), and the step's outputs, together last (:data:`OUT`)."""
OUT = {name: i for i, name in enumerate(_OUTPUTS + ["time"])}
"""Row of each output in the step's fresh ``out`` array (len(OUT), n), copied there from the block's rows at the
end of each block: u_d scaled, attitude and rate errors in degrees, reward, episode end (0 running,
1 terminated, 2 truncated); and each copy's time ``k dt`` [s]. Written straight into ``out``, the loops ran at half speed: numba cannot tell that
``out`` and ``S`` do not overlap."""
_SCRATCH_ROWS = ("lib0 lib1 lib2 lib3 lib4 lib5 lib6 lib7 lib8 lib9 noise0 noise1 noise2 noise3 noise4 noise5 slow "
                 "line0 line1 line2").split()
W = {name: i for i, name in enumerate(_SCRATCH_ROWS)}
"""Rows of a block's scratch ``Wb`` (:data:`ROW` apart, as the block's), allocated in the loop (so that the
compiler knows it overlaps nothing): what one step computes and uses within the block, kept out of ``S``: the
library row of the step (10: trims, collective, gust torque, u_d), the step's sensor normals (6) and which of
them need the ziggurat's slow path, the gyro lines (3)."""
N_ROWS = len(R)


class BlockLayout:
    """The batch state of ``n`` copies: ``S`` (blocks, (:data:`N_ROWS` + ``extra_rows``) x :data:`ROW`) float64,
    copy ``i`` in lane ``i % BLOCK`` of block ``i // BLOCK``; lanes past ``n`` stay zero. The extra rows
    follow :data:`R`'s: the phases of the gyro lines (:func:`_observe_lines`)."""

    def __init__(self, n: int, extra_rows: int = 0):
        self.n = n
        self.blocks = -(-n // BLOCK)
        self.S = np.zeros((self.blocks, (N_ROWS + extra_rows) * ROW))
        self._bind()
        self._lane = np.arange(n) % BLOCK
        self._block = np.arange(n) // BLOCK

    def _bind(self) -> None:
        self._cube = self.S.reshape(self.blocks, -1, ROW)  # views of S
        self._views = {}

    def __getstate__(self) -> dict:
        return {name: value for name, value in self.__dict__.items() if name not in ("_cube", "_views")}

    def __setstate__(self, state: dict) -> None:
        """A copy (``copy.deepcopy``) views its own ``S``: a copied view would be an array apart."""
        self.__dict__.update(state)
        self._bind()

    def view(self, row: int) -> np.ndarray:
        """Row ``row`` of every block, (blocks, BLOCK) (one block: its first ``n`` lanes): a view, for numpy's
        elementwise functions."""
        view = self._views.get(row)
        if view is None:
            view = self._views[row] = self._cube[:, row, :BLOCK if self.blocks > 1 else self.n]
        return view

    def get(self, first: int, stop: int, which=None) -> np.ndarray:
        """Rows ``first .. stop - 1`` of copies ``which`` (all by default), a fresh (rows, copies) array."""
        if which is None:
            if self.blocks == 1:
                return self._cube[0, first:stop, :self.n].copy()
            out = np.empty((stop - first, self.blocks, BLOCK))
            np.copyto(out, self._cube[:, first:stop, :BLOCK].transpose(1, 0, 2))
            return out.reshape(stop - first, -1)[:, :self.n]
        return self._cube[self._block[which], first:stop, self._lane[which]].T

    def put(self, first: int, values, which=None) -> None:
        """Write ``values`` (rows, copies) or a scalar into rows ``first ..`` of copies ``which`` (all by default)."""
        values = np.asarray(values, dtype=float)
        rows = values.shape[0] if values.ndim == 2 else 1
        which = np.arange(self.n) if which is None else np.asarray(which)
        if values.ndim < 2:
            values = np.broadcast_to(values, (rows, which.size))
        self._cube[self._block[which][None, :], np.arange(first, first + rows)[:, None],
                   self._lane[which][None, :]] = values


def _at(name: str) -> str:
    """Row ``name`` of the block's copy ``l``, in generated source over ``Sb`` (one block's row of ``S``) or, for
    the rows of :data:`W`, the block's scratch ``Wb``."""
    if name in W:
        return f"Wb[{W[name] * ROW} + l]"
    return f"Sb[{R[name] * ROW} + l]"


_SCRATCH = f"Wb = np.empty({len(_SCRATCH_ROWS) * ROW})"
"""A block's scratch (the rows of :data:`W`), in generated source."""


def _output_lines() -> list[str]:
    """Copy the block's output rows into ``out`` (:data:`OUT`), a loop per row on rows still in cache; then each
    copy's time ``k dt`` (as numpy's ``k * dt``) and ``ends`` (2, n: terminated, truncated), counting in
    ``_ended`` the copies whose episode ended."""
    return [f"        for _r in range({len(_OUTPUTS)}):",
            f"            _src = ({R['ud0']} + _r) * {ROW}",
            "            for l in range(_m):",
            "                out[_r, _i0 + l] = Sb[_src + l]",
            "        for l in range(_m):",
            f"            out[{OUT['time']}, _i0 + l] = float(k[_i0 + l]) * _dt",
            f"            _end = {_at('end')}",
            "            ends[0, _i0 + l] = _end == 1.0",
            "            ends[1, _i0 + l] = _end == 2.0",
            "            _ended += 0 if _end == 0.0 else 1"]


_LITERAL = re.compile(r"(?<![\w.])(?<!\*\*)(?:\d+\.\d*(?:e[-+]?\d+)?|\d+e[-+]?\d+)(?![\w.])")
"""A float literal of :func:`heli_core.physics._fmt` (unsigned: a sign stays an exact unary minus), not an
exponent (``**0.5`` is a square root to the compiler, a ``pow`` call as a variable)."""


def model_constants(params: ModelParams, dt: float) -> tuple[tuple[str, ...], np.ndarray]:
    """The physics core's statements (:func:`heli_core.discrete.discrete_step_statements`) with each distinct
    float literal read from a local ``_mc<i>`` instead, and the values, in order, of ``_mc0, _mc1, ...``.

    The statements' shape depends on the model's structure only (which terms are zero, which axes have a
    servo delay); the values are the model's. The generated step reads the values from an argument, so that
    models of one structure (a sweep's gains scaled by 0.8 and 1.2, a refreshed fit) share one compiled
    loop: each took 6-11 s to compile. The arithmetic is the same IEEE arithmetic on the same values: a
    literal and a variable holding it give the same bits."""
    values: dict[str, int] = {}

    def local(match: re.Match) -> str:
        return f"_mc{values.setdefault(match.group(0), len(values))}"

    statements = tuple(_LITERAL.sub(local, line) for line in discrete_step_statements(params, float(dt)))
    return statements, np.array([float(text) for text in values], dtype=float)


def _advance_lines(statements: tuple[str, ...], stick_step: bool) -> list[str]:
    """One control period of a block's copies (eqs. 18, 21, 25-26, 31), in :func:`env_kernels`' step.

    For each copy ``i``: reads library row ``j = base[i] + min(k[i], last[i]) * ratio`` of ``table`` (trim
    lat/lon/ped, collective, gust torque roll/pitch/yaw, u_d roll/pitch/yaw), increments ``k[i]`` and takes
    its action ``clip(actions[i], -1, 1)`` into rows ``act`` (with ``stick_step``, the action before into rows
    ``prev``). Steps the state rows in place with the sticks ``clip(trim + act)`` and the torque
    ``gust * torque`` and writes the reported gust ``gust * u_d``.

    The library rows and actions are gathered first in a short loop, which also prefetches each copy's row of
    the next step (:func:`heli_env.prefetch.prefetch_row`): copies start at random places in a library of
    megabytes, so a row's cache line was last read by another copy many steps ago and comes from main
    memory; asked for a step ahead, it arrives while the step computes (measured: 19 ns of a 69 ns
    copy-step without it). Then the physics runs over the block's rows, 4 or 8 copies an instruction (as the
    compiler tunes for the CPU: 4 on an AVX-512 Xeon, 8 on Zen 4): the physics
    core's ``statements`` (:func:`model_constants`: the text the single environment's step is compiled from,
    its constants read from locals). numba compiles IEEE arithmetic in the order written and does not
    contract multiply-adds (``fastmath`` is off), so every copy's state equals the single environment's bit
    for bit.

    A copy whose ``restart`` is set (its next episode starts in this step, its reset rows just written) keeps
    its step and action rows; its state rows are saved in ``_kept`` and written back after the physics, so
    what is observed is its reset state, and its library row is its episode's first, so the gust it reports
    (``gust * u_d``) is the one a reset reports.
    """
    return [
        "        for l in range(_m):",
        "            i = _i0 + l",
        "            j = np.uint64(base[i] + min(k[i], last[i]) * ratio)",  # unsigned: no negative-index branch
        *(f"            {_at(f'lib{c}')} = table[j, {c}]" for c in range(10)),
        "            if restart[i]:",  # its next episode's first observation: kept as reset (docstring)
        "                _lanes[_nr] = l",
        *(f"                _kept[_nr * {N_STATE} + {row}] = {_at(f'x{row}')}" for row in range(N_STATE)),
        "                _nr += 1",
        "                continue",
        "            k[i] += 1",
        "            prefetch_row(table, base[i] + min(k[i], last[i]) * ratio)",  # the next step's row (docstring)
        *(f"            {_at(f'prev{c}')} = {_at(f'act{c}')}" for c in range(3) if stick_step),
        *(line for c in range(3) for line in (f"            _u = float(actions[i, {c}])",
                                              "            " + _clip_line("_u"),
                                              f"            {_at(f'act{c}')} = _u")),
        "        for l in range(_m):",
        f"            g = {_at('gust')}",
        f"            lat = {_at('lib0')} + {_at('act0')}",
        "            " + _clip_line("lat"),
        f"            lon = {_at('lib1')} + {_at('act1')}",
        "            " + _clip_line("lon"),
        f"            ped = {_at('lib2')} + {_at('act2')}",
        "            " + _clip_line("ped"),
        f"            col = {_at('lib3')}",
        f"            d0 = g * {_at('lib4')}",
        f"            d1 = g * {_at('lib5')}",
        f"            d2 = g * {_at('lib6')}",
        *(f"            {name} = {_at(f'x{row}')}" for row, name in enumerate(DISCRETE_INPUTS[:10])),
        *("            " + line for line in statements),
        *(f"            {_at(f'x{row}')} = {name}" for row, name in enumerate(DISCRETE_OUTPUTS)),
        *(f"            {_at(f'ud{c}')} = g * {_at(f'lib{7 + c}')}" for c in range(3)),
        "        for _q in range(_nr):",
        "            l = _lanes[_q]",
        *(f"            {_at(f'x{row}')} = _kept[_q * {N_STATE} + {row}]" for row in range(N_STATE)),
    ]


def _state_angle_lines() -> list[str]:
    """The Euler angles of each copy's attitude, from its state rows (a loop of its own: in the physics loop
    the inverse functions cost twice as much)."""
    return ["        for l in range(_m):",
            *(f"            b{c} = {_at(f'x{6 + c}')}" for c in range(4)),
            *("            " + line for line in _angle_lines())]


@numba.njit(error_model="numpy", cache=True)
def first_non_finite(actions) -> int:
    """The first row of ``actions`` (n, 3) holding a value that is not finite, or -1."""
    for i in range(actions.shape[0]):
        for c in range(3):
            if not math.isfinite(float(actions[i, c])):
                return i
    return -1


def _line_loops(line_axes: tuple) -> list[str]:
    """The gyro lines of a block's copies as the single env tabulates them: each axis' lines summed in order
    from 0.0, line ``m`` reading sin and cos of its frequency at step ``k`` (``line_table[k, 2 m : 2 m + 2]``)
    and the copy's phase (rows ``N_ROWS + 2 m``, ``+ 1``). Where every copy of the block is at the same step
    (copies reset together) the table's values are read once and the loop runs 4 or 8 copies an instruction;
    otherwise (a long run, its copies' episodes ending on different steps) the same arithmetic one copy at a
    time, each reading its own step's row: 7-10 ns a copy-step more, measured on an AVX-512 Xeon; copying the
    rows into scratch rows first (then the arithmetic 4 copies an instruction, the copy by vector gathers or
    one copy at a time) and prefetching them measured the same."""

    def sums(table):
        out = ["l0 = 0.0", "l1 = 0.0", "l2 = 0.0"]
        out += [f"l{axis} += _amp{m} * ({table(2 * m)} * Sb[{(N_ROWS + 2 * m) * ROW} + l] + {table(2 * m + 1)}"
                f" * Sb[{(N_ROWS + 2 * m + 1) * ROW} + l])" for m, axis in enumerate(line_axes)]
        return out + [f"{_at(f'line{c}')} = l{c}" for c in range(3)]

    width = 2 * len(line_axes)
    return [*(f"        _amp{m} = line_amp[{m}]" for m in range(len(line_axes))),
            "        _last_row = line_table.shape[0] - 1",
            "        _k0 = kb[0]",
            "        _same = True",
            "        for l in range(_m):",
            "            _same = _same and kb[l] == _k0",
            "        if _same:",
            "            _kl = min(_k0, _last_row)",
            *(f"            _t{c} = line_table[_kl, {c}]" for c in range(width)),
            "            for l in range(_m):",
            *("                " + line for line in sums(lambda c: f"_t{c}")),
            "        else:",
            "            for l in range(_m):",
            "                kl = min(kb[l], _last_row)",
            *("                " + line for line in sums(lambda c: f"line_table[kl, {c}]"))]


def _noise_lines(line_axes: tuple) -> list:
    """The sensors' part of :func:`_observe_lines`: the step's six normals of each copy by the ziggurat's
    rectangles (rows ``noise``, and ``slow`` marking the samples that need its slow path), that slow path, and
    the gyro lines on ``line_axes`` (rows ``line``)."""
    lines = [*(f"        na{c} = noise_std[{c}]" for c in range(3)),
             *(f"        nr{c} = noise_std[{3 + c}]" for c in range(3)),
             "        keyb = key[_i0:_i0 + _m]",
             "        for l in range(_m):",  # the step's 6 normals: 3 words of the key's stream
             "            _pair = np.uint64(kb[l]) * np.uint64(3)",
             "            _key = keyb[l]",
             "            _slow = 0.0"]
    for word in range(3):
        lines.append(f"            _b = stream_bits(_key, _pair + np.uint64({word}))")
        for half in range(2):
            c = 2 * word + half
            lines += [f"            _z, _again = fast_normal({'_b & LOW32' if half == 0 else '_b >> np.uint64(32)'})",
                      f"            {_at(f'noise{c}')} = _z",
                      f"            _slow += {float(1 << c)!r} if _again else 0.0"]
    lines += [f"            {_at('slow')} = _slow"]
    lines += ["        for l in range(_m):",  # the slow path where the rectangles rejected
              f"            _slow = {_at('slow')}",
              "            if _slow != 0.0:",
              "                _flags = int(_slow)",
              "                for _c in range(6):",
              "                    if _flags & (1 << _c):",
              f"                        Wb[({W['noise0']} + _c) * {ROW} + l] = standard_normal(keyb[l], kb[l] * 6 + _c)"]
    if line_axes:
        lines += _line_loops(line_axes)
    return lines


def _reward_lines(task: str, axis_weighted: bool, stick_step: bool) -> list:
    """The reward of one copy in :func:`_observe_lines`' loop: :func:`heli_env.tasks.reward_of` written out per
    axis from the errors ``e``/``r`` and the action ``u`` (and, with ``stick_step``, the step from rows ``prev``,
    the action before, which the step's advance set)."""
    def squares(v):
        if axis_weighted:
            return f"(w0 * {v}0 * {v}0 + w1 * {v}1 * {v}1 + w2 * {v}2 * {v}2)"
        return f"({v}0 * {v}0 + {v}1 * {v}1 + {v}2 * {v}2)"

    att2 = "0.0" if task == "rate" else squares("e")
    effort = "cu * (u0 * u0 + u1 * u1 + u2 * u2)"
    lines = []
    if stick_step:
        lines += [f"            d{c} = u{c} - {_at(f'prev{c}')}" for c in range(3)]
        effort += " + cs * (d0 * d0 + d1 * d1 + d2 * d2)"
    return lines + [f"            {_at('reward')} = -(ca * {att2} + cr * {squares('r')} + {effort})"]


def _observe_lines(task: str, noisy: bool, axis_weighted: bool = False, line_axes: tuple = (),
                   stick_step: bool = False) -> list[str]:
    """The observation of a block's copies (``_m`` copies from ``_i0`` in ``Sb``), in the loops of
    :func:`env_kernels`, specialised on the task, the noise and the axes of the gyro lines.

    Reads the angles (rows ``att``, [rad]), the rates (``x0..x2``), the action applied (``act``), the
    references where the task has them (``refatt`` for ``"track"``, ``refrate`` for ``"track"`` and
    ``"rate"``); ``k``/``steps`` (n): steps taken and allowed; ``coef``:
    :func:`heli_env.tasks.reward_coefficients`. When ``noisy``: ``key`` (n, uint64) each copy's noise key,
    ``noise_std`` (6,) the attitude [rad] and gyro [rad/s] white-noise standard deviations, and the gyro lines
    (on axes ``line_axes``): ``line_amp`` (L,), ``line_table`` (steps + 1, 2 L) holding sin(w t), cos(w t)
    of each line at each step, and each copy's phases in the rows after :data:`R`'s (2 L: the (cos, sin)
    pair of each line). The
    measured attitude adds ``std * z_c`` and the measured rate ``std * z_(c+3)`` plus its lines, as the
    single env does, where ``z`` are the step's normals ``6 k .. 6 k + 5`` of the copy's key
    (:mod:`heli_env.sensor_noise`). Writes ``obs`` (n * 12, float32: the (n, 12) observations) and the
    output rows: ``degatt``/``degrate``, ``reward`` and ``end`` (1: attitude beyond ``max_angle`` or a rate
    not finite; 2: otherwise, at the step limit; 0: running). The same expressions as the single
    environment's ``_observe`` and :func:`heli_env.tasks.reward_of`, written out per axis
    (``axis_weighted``: with ``coef[3:6]`` weighing each axis' errors; ``stick_step``: the squared change of
    the action from rows ``prev`` at weight ``coef[6]``). Observing a copy twice gives the same: what it
    writes is computed from rows it does not write.

    Per block, three loops: the normals by the ziggurat's rectangles, 8 copies an instruction, marking the
    about 1 % of samples that need its slow path; those samples and the gyro lines (table reads), one copy
    at a time; then the observation, reward and episode end, 8 copies an instruction.
    """
    two_pi = repr(TWO_PI)

    def wrap(v):  # heli_env.tasks.wrap
        return f"({v}) - {two_pi} * np.round(({v}) / {two_pi})"

    def bound(v):
        return f"-max_rate if {v} < -max_rate else (max_rate if {v} > max_rate else {v})"

    lines = [
        "        ca = coef[0]",
        "        cr = coef[1]",
        "        cu = coef[2]",
        *(["        w0 = coef[3]", "        w1 = coef[4]", "        w2 = coef[5]"] if axis_weighted else []),
        *(["        cs = coef[6]"] if stick_step else []),
        "        kb = k[_i0:_i0 + _m]",
        "        sb = steps[_i0:_i0 + _m]",
        f"        ob = obs[_i0 * {OBS_DIM}:(_i0 + _m) * {OBS_DIM}]",
    ]
    if noisy:
        lines += _noise_lines(line_axes)
    lines.append("        for l in range(_m):")
    for c, w in enumerate(("p", "q", "r")):
        att = _at(f"att{c}")
        err = wrap(f"{_at(f'refatt{c}')} - {att}") if task == "track" else f"-{att}"
        ref = _at(f"refrate{c}") if task in ("track", "rate") else "0.0"
        lines += [f"            a{c} = {att}",
                  f"            e{c} = {err}", f"            {w} = {_at(f'x{c}')}", f"            r{c} = {ref} - {w}",
                  f"            u{c} = {_at(f'act{c}')}",
                  f"            {_at(f'degatt{c}')} = e{c} * {repr(180.0 / math.pi)}",
                  f"            {_at(f'degrate{c}')} = r{c} * {repr(180.0 / math.pi)}"]
        if noisy:  # heli_env.env.HeliAttitudeEnv._observe: attitude + noise, (rate + noise) + lines
            line = _at(f"line{c}") if c in line_axes else "0.0"
            lines += [f"            ma{c} = a{c} + na{c} * {_at(f'noise{c}')}",
                      f"            m{c} = ({w} + nr{c} * {_at(f'noise{3 + c}')}) + {line}"]
            shown = wrap(f"{_at(f'refatt{c}')} - ma{c}") if task == "track" else wrap(f"-ma{c}")
            lines += [f"            mr{c} = {ref} - m{c}", f"            ob[l * {OBS_DIM} + {c}] = {shown}"]
            rate, rate_err = f"m{c}", f"mr{c}"
        else:
            lines.append(f"            ob[l * {OBS_DIM} + {c}] = e{c}")
            rate, rate_err = w, f"r{c}"
        lines += [f"            ob[l * {OBS_DIM} + {3 + c}] = {bound(rate)}",
                  f"            ob[l * {OBS_DIM} + {6 + c}] = {bound(rate_err)}",
                  f"            ob[l * {OBS_DIM} + {9 + c}] = u{c}"]

    lines += _reward_lines(task, axis_weighted, stick_step)
    lines += [
        "            ok = abs(a0) <= max_angle and abs(a1) <= max_angle and isfinite(p) and isfinite(q) and isfinite(r)",
        f"            {_at('end')} = (2.0 if kb[l] >= sb[l] else 0.0) if ok else 1.0",
    ]
    return lines


_OBSERVE_ARGUMENTS = "k, steps, key, noise_std, line_amp, line_table, max_rate, max_angle, coef, obs, out, ends"


def _tag(task: str, noisy: bool, axis_weighted: bool, stick_step: bool) -> str:
    return (f"{task}{' noisy' if noisy else ''}{' axis-weighted' if axis_weighted else ''}"
            f"{' stick-step' if stick_step else ''}")


class Kernels(NamedTuple):
    """The compiled loops of one env configuration (:func:`env_kernels`)."""

    constants: np.ndarray
    """What the loops read as their argument ``P``: the model's values (:func:`model_constants`), then the
    control period ``dt``."""
    step: object
    """``step(S, actions, table, base, last, ratio, P, restart, k, steps, key, noise_std, line_amp, line_table,
    max_rate, max_angle, coef, obs, out, ends, first, stop, advance)``: blocks ``first .. stop - 1`` on the
    calling thread; returns how many copies' episodes ended."""
    step_pool: object
    """The same, the blocks on numba's pool (a ``prange``: the step's only parallel region)."""


@lru_cache(maxsize=16)
def env_kernels(params: ModelParams, dt: float, task: str, noisy: bool, axis_weighted: bool = False,
                line_axes: tuple = (), stick_step: bool = False) -> Kernels:
    """The compiled loops of an env, one module.

    ``step`` runs, block by block, one control period (:func:`_advance_lines`; ``actions`` (n, 3) finite, see
    :func:`first_non_finite`) and then the observation of the new state (:func:`_observe_lines`) and the copy
    of the block's outputs into ``out`` (:func:`_output_lines`), while the block's rows are in the core's
    cache: one function, whose compiler sees the block's scratch allocated and overlapping nothing (split
    into functions per part, the step took 5-10 % longer). With ``advance`` False it only observes: the
    Euler angles of the state's quaternion, then the observation (after a reset; ``actions`` unread). An
    observation is a pure function of the state rows, the step and the noise key, so observing a copy again
    gives what it gave. A copy whose ``restart`` (n, uint8) is set starts its next episode in the step (the
    env has just written its reset state): it is not advanced (its state rows are kept through the physics,
    its step and action rows not touched) but observed as a reset observes it, with reward 0 and no end:
    Gymnasium's next-step autoreset without a second pass over its block. ``step_pool`` calls ``step`` on one
    block per task of a ``prange``: a thin parallel loop that compiles in two seconds, where the whole step
    compiled as one parallel function took fifteen.
    The model's values and ``dt`` are an argument (:attr:`Kernels.constants`), the model's structure the
    source: envs of models of one structure share the module. ``actions`` are float64 (a C array): one
    compiled signature (each took 5 s to compile).
    """
    statements, constants = model_constants(params, dt)
    arguments = f"S, actions, table, base, last, ratio, P, restart, {_OBSERVE_ARGUMENTS}, first, stop, advance"
    step = [f"def step({arguments}):",
            *(f"    _mc{i} = P[{i}]" for i in range(constants.size)),
            f"    _dt = P[{constants.size}]",
            "    _copies = k.shape[0]",
            "    _ended = 0",
            f"    _lanes = np.empty({BLOCK}, dtype=np.int64)",  # a block's copies starting their next episode
            f"    _kept = np.empty({N_STATE * BLOCK})",  # and their reset states, kept through the physics
            "    for _block in range(stop):",  # from 0: the compiler then knows every index below is not negative
            "        if _block < first:",  # (with range(first, stop) the step took 10 % longer)
            "            continue",
            "        Sb = S[_block]",
            "        " + _SCRATCH,
            f"        _i0 = _block * {BLOCK}",
            f"        _m = min({BLOCK}, _copies - _i0)",
            "        _nr = 0",
            "        if advance:",
            *("    " + line for line in _advance_lines(statements, stick_step)),
            *_state_angle_lines(),
            *_observe_lines(task, noisy, axis_weighted, line_axes, stick_step),
            "        for _q in range(_nr):",  # a first observation: reward 0, not ended (as after reset())
            "            l = _lanes[_q]",
            f"            {_at('reward')} = 0.0",
            f"            {_at('end')} = 0.0",
            *_output_lines(),
            "    return _ended"]
    step_pool = [f"def step_pool({arguments}):",
                 "    _ended = 0",
                 "    for _block in prange(first, stop):",
                 f"        _ended += step({arguments.replace('first, stop', '_block, _block + 1')})",
                 "    return _ended"]
    module = _compile_module({"step": (step, False), "step_pool": (step_pool, True)},
                             "env " + _tag(task, noisy, axis_weighted, stick_step))
    return Kernels(np.append(constants, float(dt)), module.step, module.step_pool)
