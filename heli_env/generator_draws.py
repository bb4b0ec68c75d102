"""Many numpy generators drawn at once: what an episode draws from each copy's ``np_random``, in one numba call.

A native vector env keeps one ``np.random.Generator`` per copy (copy ``i`` is the single env seeded
``seed + i``), so that its episodes are the single env's. Drawn through numpy, an episode's few draws cost
about 10 us a copy of Python calls (two ``integers``, a ``random``, a ``normal``, the noise key's
``integers`` and, for a reset with options to put back, the generator's ``state``): 8-13 us a copy for a
reset of 4096 copies, and in a long run, where a copy or two start an episode on every step, 7 % of the
step. This module draws the same numbers from the same generators in compiled code: each generator's own
64-bit function (its bit generator's ``ctypes.next_uint64``, called on its state's address), turned into
integers, doubles and normals by numpy's own algorithms, transcribed:

* ``integers(n)`` (int64, ``n`` < 2**32): Lemire's bounded 32-bit draw on the bit generator's buffered 32-bit
  output (numpy's ``random_bounded_uint64_fill`` and ``buffered_bounded_lemire_uint32``, and PCG64's
  ``next_uint32``, which keeps the upper half of a 64-bit draw for the next call); ``n == 1`` draws nothing;
* ``integers(0, 2**64, dtype=np.uint64)``: one 64-bit draw;
* ``random()``: the 64-bit draw's upper 53 bits times 2**-53 (PCG64's ``next_double``);
* ``normal(0.0, 1.0)``: ``0.0 + 1.0 * z`` with ``z`` numpy's ziggurat (``random_standard_normal``), whose
  tables numba's own copy of numpy's distributions holds.

The 32-bit half kept between draws is the one part of a generator's state this module holds itself
(:class:`Streams`): it starts as the generator's and only this module draws from the generator after. A
copy's draws can be put back (:meth:`Streams.put_back`): the 64-bit draws by the bit generator's own
``advance`` (modulo 2**128, backwards), the kept half from the values before. ``tests/test_generator_draws.py``
holds every draw against numpy's, the rare branches included (Lemire's rejections, the ziggurat's wedges and
tail). Should numba no longer hold numpy's ziggurat tables where this module reads them (:data:`COMPILED`
False), :class:`Streams` draws through numpy's own calls, copy by copy, and marks a generator by its ``state``:
the same numbers, at the old cost.
"""

from __future__ import annotations

import ctypes

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic
try:  # numba's copy of numpy's ziggurat tables (numba.np.random, since numba 0.56)
    from numba.np.random._constants import fi_double, ki_double, wi_double, ziggurat_nor_inv_r, ziggurat_nor_r
    COMPILED = True
except ImportError:  # a numba that moved them: the copies are drawn through numpy, as before (same numbers)
    COMPILED = False

_TWO_128 = 1 << 128
_LOW32 = np.uint64(0xFFFFFFFF)
_UINT32_MAX = np.uint64(0xFFFFFFFF)
_DOUBLE_UNIT = 1.0 / 9007199254740992.0  # 2**-53


@intrinsic
def _call_next64(typingctx, function, state):
    """``function(state)``: a bit generator's ``uint64_t next_uint64(void *state)`` at address ``function``,
    on the state at address ``state`` (both integers)."""
    sig = types.uint64(types.intp, types.intp)

    def codegen(context, builder, signature, args):
        byte_ptr = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.IntType(64), [byte_ptr])
        fn = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(fn, [builder.inttoptr(args[1], byte_ptr)])

    return sig, codegen


@numba.njit(cache=True)
def _next64(function, state, used, i):
    """Copy ``i``'s next 64-bit draw, counted in ``used[i]``."""
    used[i] += 1
    return _call_next64(function, state)


@numba.njit(cache=True)
def _next32(function, state, kept, used, i):
    """PCG64's ``next_uint32`` for copy ``i``: the half kept from the last 64-bit draw (``kept[0, i]`` its flag,
    ``kept[1, i]`` its value), else the lower half of a new draw, whose upper half is kept."""
    if kept[0, i]:
        kept[0, i] = 0
        return kept[1, i]
    x = _next64(function, state, used, i)
    kept[0, i] = 1
    kept[1, i] = x >> np.uint64(32)
    return x & _LOW32


@numba.njit(cache=True)
def _bounded(function, state, kept, used, i, n):
    """numpy's ``integers(n)`` (int64, 1 <= n <= 2**32): Lemire's rejection on 32-bit draws; nothing drawn for
    ``n == 1``."""
    rng = np.uint64(n - 1)
    if rng == 0:
        return 0
    if rng == _UINT32_MAX:
        return np.int64(_next32(function, state, kept, used, i))
    excl = rng + np.uint64(1)
    m = _next32(function, state, kept, used, i) * excl
    leftover = m & _LOW32
    if leftover < excl:
        threshold = (_UINT32_MAX - rng) % excl
        while leftover < threshold:
            m = _next32(function, state, kept, used, i) * excl
            leftover = m & _LOW32
    return np.int64(m >> np.uint64(32))


@numba.njit(cache=True)
def _double(function, state, used, i):
    """PCG64's ``next_double``: a 64-bit draw's upper 53 bits times 2**-53."""
    return np.float64(_next64(function, state, used, i) >> np.uint64(11)) * _DOUBLE_UNIT


@numba.njit(cache=True)
def _standard_normal(function, state, used, i):
    """numpy's ``random_standard_normal``: the ziggurat (256 rectangles, a wedge test, the tail beyond ``r``)."""
    while True:
        r = _next64(function, state, used, i)
        idx = np.int64(r & np.uint64(0xFF))
        r >>= np.uint64(8)
        sign = r & np.uint64(1)
        rabs = (r >> np.uint64(1)) & np.uint64(0x000FFFFFFFFFFFFF)
        x = np.float64(rabs) * wi_double[idx]
        if sign & np.uint64(1):
            x = -x
        if rabs < ki_double[idx]:
            return x
        if idx == 0:
            while True:
                xx = -ziggurat_nor_inv_r * np.log1p(-_double(function, state, used, i))
                yy = -np.log1p(-_double(function, state, used, i))
                if yy + yy > xx * xx:
                    if (rabs >> np.uint64(8)) & np.uint64(1):
                        return -(ziggurat_nor_r + xx)
                    return ziggurat_nor_r + xx
        else:
            wedge = (fi_double[idx - 1] - fi_double[idx]) * _double(function, state, used, i) + fi_double[idx]
            if wedge < np.exp(-0.5 * x * x):
                return x


@numba.njit(cache=True)
def draw_copies(function, states, kept, used, which, n_traces, counts, trace_pin, offset_pin, uniforms, normals, keys,
                traces, offsets):
    """Copy ``which[q]``'s episode draws, in the single env's order: the trace (``integers(n_traces)``), the
    window's offset (``integers(counts[trace])``, ``trace`` the pinned one where ``trace_pin >= 0``), the
    standard uniforms (a row of ``uniforms``), the normals (a row of ``normals``, ``normal(0.0, 1.0)`` each)
    and, where ``keys`` has a row per copy, the noise key (``integers(0, 2**64, dtype=np.uint64)``).

    ``function`` is the bit generators' ``next_uint64`` (one address: every copy's generator is a PCG64),
    ``states`` (n,) their states' addresses, ``kept`` (2, n) uint64 the 32-bit halves kept, ``used`` (n,) int64
    counts each copy's 64-bit draws; results go to row
    ``q`` of ``traces``, ``offsets`` (the pins replace what was drawn, as the single env does), ``uniforms``,
    ``normals`` and ``keys``.
    """
    for q in range(which.size):
        i = which[q]
        state = states[i]
        trace = _bounded(function, state, kept, used, i, n_traces)
        if trace_pin >= 0:
            trace = trace_pin
        offset = _bounded(function, state, kept, used, i, counts[trace])
        traces[q] = trace
        offsets[q] = offset if offset_pin < 0 else offset_pin
        for c in range(uniforms.shape[1]):
            uniforms[q, c] = _double(function, state, used, i)
        for c in range(normals.shape[1]):
            normals[q, c] = 0.0 + 1.0 * _standard_normal(function, state, used, i)
        if keys.size:
            keys[q] = _next64(function, state, used, i)


def _next64_address(rng: np.random.Generator) -> int:
    bits = rng.bit_generator
    if not isinstance(bits, np.random.PCG64):
        raise TypeError(f"the vector env's generators are PCG64 (their 32-bit draws are PCG64's); got "
                        f"{type(bits).__name__}")
    return ctypes.cast(bits.ctypes.next_uint64, ctypes.c_void_p).value


def _numpy_draws(rng, n_traces, counts, trace_pin, offset_pin, uniforms, normals, keys, q):
    """:func:`draw_copies` of one generator through numpy's calls (the single env's), into row ``q``."""
    trace = int(rng.integers(n_traces))
    trace = trace if trace_pin < 0 else trace_pin
    offset = int(rng.integers(counts[trace]))
    rng.random(out=uniforms[q])
    normals[q] = rng.normal(0.0, 1.0, normals.shape[1])
    if keys.size:
        keys[q] = rng.integers(0, 2**64, dtype=np.uint64)
    return trace, (offset if offset_pin < 0 else offset_pin)


class Streams:
    """The generators of ``n`` copies, drawn in compiled code (:func:`draw_copies`).

    :meth:`adopt` takes a copy's new generator (its 32-bit half kept as the generator holds it); the env
    keeps the generator objects alive (their states are read at their addresses). :meth:`draw` returns what
    the copies' episodes draw; :meth:`mark` and :meth:`put_back` return copies' generators to a mark.
    """

    def __init__(self, n: int):
        self.compiled = COMPILED
        self._saved: list = [None] * n  # without COMPILED: each generator's state at its mark
        self.states = np.zeros(n, dtype=np.intp)
        self.kept = np.zeros((2, n), dtype=np.uint64)
        self._rngs: list = [None] * n
        self._function = 0
        self._mark_kept = np.zeros((2, n), dtype=np.uint64)
        self._mark_count = np.zeros(n, dtype=np.int64)  # 64-bit draws since the mark

    def __setstate__(self, state: dict) -> None:
        """A copy (``copy.deepcopy``, pickle) reads its own generators, wherever their states now are."""
        self.__dict__.update(state)
        for i, rng in enumerate(self._rngs):
            if rng is not None:
                self._function = _next64_address(rng)
                self.states[i] = rng.bit_generator.ctypes.state_address

    def adopt(self, i: int, rng: np.random.Generator) -> None:
        """Copy ``i`` draws from ``rng`` from now on."""
        function = _next64_address(rng)
        if self._function and function != self._function:  # one PCG64 code in a process
            raise TypeError("the copies' generators must share one bit generator type")
        self._function = function
        state = rng.bit_generator.state
        self.states[i] = rng.bit_generator.ctypes.state_address
        self.kept[0, i] = int(state["has_uint32"])
        self.kept[1, i] = int(state["uinteger"])
        self._rngs[i] = rng
        self._saved[i] = None
        self._mark_count[i] = 0
        self._mark_kept[:, i] = self.kept[:, i]

    def draw(self, which: np.ndarray, n_traces: int, counts: np.ndarray, n_uniform: int, n_normal: int,
             key: bool, trace_pin: int = -1, offset_pin: int = -1):
        """Copies ``which``'s draws (:func:`draw_copies`): traces, offsets (m,) int64, uniforms (m,
        n_uniform), normals (m, n_normal), keys (m,) uint64 (empty without ``key``)."""
        if not 1 <= n_traces <= 2**32 or counts.size == 0 or counts.min() < 1 or counts.max() > 2**32:
            raise ValueError(f"draws are bounded by 1 to 2**32 traces and windows a trace, got {n_traces} traces "
                             f"and {counts.min() if counts.size else 'no'}-{counts.max() if counts.size else ''} "
                             "windows")
        m = which.size
        uniforms, normals = np.empty((m, n_uniform)), np.empty((m, n_normal))
        keys = np.empty(m if key else 0, dtype=np.uint64)
        traces, offsets = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
        if m and not self.compiled:
            for q, i in enumerate(which.tolist()):
                traces[q], offsets[q] = _numpy_draws(self._rngs[i], n_traces, counts, trace_pin, offset_pin, uniforms,
                                                     normals, keys, q)
        elif m:
            draw_copies(self._function, self.states, self.kept, self._mark_count, which, int(n_traces), counts,
                        int(trace_pin), int(offset_pin), uniforms, normals, keys, traces, offsets)
        return traces, offsets, uniforms, normals, keys

    def mark(self, which: np.ndarray) -> None:
        """Remember where copies ``which``'s generators are (cheap: a copy's count and kept half)."""
        if not self.compiled:
            for i in which.tolist():
                self._saved[i] = self._rngs[i].bit_generator.state
            return
        self._mark_count[which] = 0
        self._mark_kept[:, which] = self.kept[:, which]

    def put_back(self, which: np.ndarray) -> None:
        """Return copies ``which``'s generators to their marks: as if nothing had been drawn since."""
        if not self.compiled:
            for i in which.tolist():
                if self._saved[i] is not None:
                    self._rngs[i].bit_generator.state = self._saved[i]
            return
        for i in which.tolist():
            count = int(self._mark_count[i])
            if count:
                self._rngs[i].bit_generator.advance(_TWO_128 - count)
        self._mark_count[which] = 0
        self.kept[:, which] = self._mark_kept[:, which]
