"""What a reset writes for each copy of the native vector env, and the next episodes drawn ahead.

A copy's episode is drawn from its own generator (:func:`heli_env.tasks.draw_episodes`, then the gyro lines'
phases and the noise key) and turned into the values its reset writes: a :class:`Starts`, one column per copy.
Drawn for a few copies at a time, as autoresets come in a long run (a copy or two on every step of 4096
copies), its thirty numpy operations cost about 40 us of fixed Python a step, against under 1 us a copy
drawn in a batch (the draws themselves are one compiled call: :mod:`heli_env.generator_draws`).
:class:`EpisodesAhead` therefore draws each copy's *next* episode ahead, for many copies at once, right after
its episode started: the generator gives the same numbers whenever they are drawn, so an
episode drawn ahead is the episode a reset would have drawn, bit for bit. What would have drawn otherwise
puts it back: a reset with options returns the generator to where it was before the draw ahead (the options
change what is drawn; :meth:`heli_env.generator_draws.Streams.put_back`); a new seed replaces the generator,
and the draw is dropped.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from .kernels import BLOCK, N_ROWS, ROW, R

INTS = ("k", "base", "last", "steps", "trace", "key")
"""Rows of :attr:`Starts.ints`: the step (0 at a start), the episode's first library sample, its last step's
index in the replay, its step limit, its trace, its noise key (a uint64's bits)."""
KEY = INTS.index("key")

BATCH = 256
"""Episodes drawn ahead once this many copies (or every copy, in smaller envs) have used theirs: a batch's
fixed cost (about 40 us) spread over its copies."""


class Starts(NamedTuple):
    """What resets write, one column per copy."""

    ints: np.ndarray
    """(len(:data:`INTS`), m) int64."""
    rows: np.ndarray
    """(rows, m) float: block-layout rows ``x0 .. gust`` (the state, the action 0, the gust scale), then the
    gyro lines' phases (:func:`heli_env.tasks.draw_line_phases`, a (cos, sin) pair per line)."""
    references: tuple | None
    """The reference's draws (smooth (m,), steps (3, segments, m), amplitudes, frequencies, phases (3,
    N_SINES, m)), None for the hold task (it has none)."""

    @classmethod
    def zeros(cls, like: "Starts", m: int) -> "Starts":
        """Zeros shaped as ``like`` for ``m`` copies."""
        refs = None if like.references is None else tuple(np.zeros(r.shape[:-1] + (m,), r.dtype)
                                                          for r in like.references)
        return cls(np.zeros((like.ints.shape[0], m), np.int64), np.zeros((like.rows.shape[0], m)), refs)

    def store(self, cols, other: "Starts") -> None:
        """Write ``other``'s columns into columns ``cols`` of this one."""
        self.ints[:, cols] = other.ints
        self.rows[:, cols] = other.rows
        if self.references is not None:
            for mine, theirs in zip(self.references, other.references):
                mine[..., cols] = theirs


START_ROWS = R["gust"] - R["x0"] + 1
"""Rows ``x0 .. gust`` of :data:`heli_env.kernels.R`, consecutive: the state (10), the action (3), the gust
scale; :attr:`Starts.rows` holds them first."""
_X0, _PREV0, _GUST = R["x0"], R["prev0"], R["gust"] - R["x0"]  # (numba reads globals as constants, not dicts)


@numba.njit(cache=True)
def write_starts(S, ints, gust, which, starts_ints, starts_rows, cols):
    """Copies ``which``'s reset: columns ``cols`` of a :class:`Starts` (``starts_ints``, ``starts_rows``)
    into the env's ``ints`` (len(:data:`INTS`), n), ``gust`` (n) and block rows ``S``
    (:class:`heli_env.kernels.BlockLayout`): rows ``x0 .. gust``, the gyro lines' phases after :data:`R`'s
    rows, and rows ``prev`` 0 (an episode starts from rest). One call for what were a dozen numpy
    operations of a few microseconds each, paid on every step of a long run."""
    for q in range(which.size):
        i = which[q]
        c = cols[q]
        block = i // BLOCK
        lane = i % BLOCK
        for r in range(starts_ints.shape[0]):
            ints[r, i] = starts_ints[r, c]
        for r in range(starts_rows.shape[0]):
            row = _X0 + r if r < START_ROWS else N_ROWS + r - START_ROWS
            S[block, row * ROW + lane] = starts_rows[r, c]
        for r in range(3):
            S[block, (_PREV0 + r) * ROW + lane] = 0.0
        gust[i] = starts_rows[_GUST, c]


class EpisodesAhead:
    """Each copy's next episode, drawn ahead in batches (see the module docstring).

    ``draw(which)`` draws the episodes of copies ``which`` (an index array) from their generators with the
    default options, as a :class:`Starts`; ``streams`` (:class:`heli_env.generator_draws.Streams`) are the
    copies' generators, marked before a draw ahead and put back to the mark. A copy whose last reset came with
    options (as an SB3 adapter's pinned gust windows do) is not drawn ahead until a reset without them: its draw
    would be put back unused."""

    def __init__(self, streams, draw):
        self._streams = streams
        self._draw = draw
        self.starts = None  # Starts of every copy, once drawn
        n = streams.states.size
        self.ready = np.zeros(n, dtype=bool)
        self._wanted = np.ones(n, dtype=bool)  # False: the copy's last reset had options
        self._batch = min(n, BATCH)
        self._missing = n  # copies wanted and not ready

    def due(self) -> bool:
        """Whether enough copies have used their episode drawn ahead to draw the next batch."""
        return self._missing >= self._batch

    def fill(self) -> None:
        """Draw the next episode of every copy that has none (and whose resets come without options)."""
        which = np.flatnonzero(self._wanted & ~self.ready)
        self._missing = 0
        if which.size == 0:
            return
        self._streams.mark(which)
        drawn = self._draw(which)
        if self.starts is None:
            self.starts = Starts.zeros(drawn, self.ready.size)
        self.starts.store(which, drawn)
        self.ready[which] = True

    def take(self, which: np.ndarray) -> None:
        """Copies ``which`` (all ready) start their episodes drawn ahead: columns ``which`` of :attr:`starts`,
        read by the caller before the next :meth:`fill`."""
        self.ready[which] = False
        self._missing += which.size

    def drawn_now(self, which: np.ndarray) -> None:
        """Copies ``which`` (none ready) were reset without options and drew their episodes then: draw their
        next ones ahead again."""
        self._wanted[which] = True
        self._missing = int(np.count_nonzero(self._wanted & ~self.ready))

    def forget(self, which: np.ndarray, restore: bool) -> None:
        """Copies ``which`` will not use their episodes drawn ahead. With ``restore`` (a reset with options) their
        generators go back to the state before the draw, as the options draw from there, and they are not
        drawn ahead until a reset without options; without it (new generators) the draws are dropped."""
        drop = which[self.ready[which]]
        if restore:
            self._streams.put_back(drop)
            self._wanted[which] = False
        self.ready[drop] = False
        self._missing = int(np.count_nonzero(self._wanted & ~self.ready))
