"""Training and held-out splits of a disturbance library, and gust windows drawn from them.

RL agents train on some of the library's gust traces and are compared with PD
controllers on the others (:func:`split_traces`). A split is a list of
:class:`TraceSegment` per side: a whole trace, or — for a library of one trace,
which cannot be split by trace — a stretch of it in time. An episode replays
one *window* of a segment, given as ``(trace, offset)`` and pinned through the
environments' ``reset(options={"trace": ..., "offset": ...})``
(:func:`draw_windows`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from heli_core.config import is_real, whole_number
from heli_env.tasks import draw_offset, draw_offsets, window_count


@dataclass(frozen=True)
class TraceSegment:
    """A stretch of one library trace.

    Attributes
    ----------
    trace : int
        Library index of the trace.
    start, stop : float
        The stretch as fractions of the trace's samples, ``0 <= start < stop <= 1``
        (sample ``floor(start * n)`` up to, not including, ``floor(stop * n)``).
    """

    trace: int
    start: float = 0.0
    stop: float = 1.0

    def __post_init__(self):
        if int(self.trace) != self.trace or self.trace < 0:
            raise ValueError(f"trace must be a library index >= 0, got {self.trace!r}")
        if not (0.0 <= self.start < self.stop <= 1.0):
            raise ValueError(f"a segment needs 0 <= start < stop <= 1 (fractions of the trace), got "
                             f"{self.start!r}, {self.stop!r}")
        object.__setattr__(self, "trace", int(self.trace))

    def samples(self, length: int) -> tuple[int, int]:
        """``(first, end)`` sample of the stretch in a trace of ``length`` samples (end exclusive)."""
        return int(math.floor(self.start * length)), int(math.floor(self.stop * length))

    def to_dict(self) -> dict:
        return {"trace": self.trace, "start": self.start, "stop": self.stop}


@dataclass(frozen=True)
class TraceSplit:
    """Training and held-out segments of a library (see :func:`split_traces`).

    Attributes
    ----------
    train, held_out : tuple of TraceSegment
    n_traces : int
        Traces in the library that was split.
    held_out_fraction : float
    seed : int
    in_time : bool
        True when a single trace was split in time.
    """

    train: tuple
    held_out: tuple
    n_traces: int
    held_out_fraction: float
    seed: int
    in_time: bool = False

    def side(self, name: str) -> tuple:
        """The segments of ``"train"``, ``"held-out"`` or ``"all"`` (every trace whole)."""
        if name == "train":
            return self.train
        if name in ("held-out", "held_out"):
            return self.held_out
        if name == "all":
            return tuple(TraceSegment(i) for i in range(self.n_traces))
        raise ValueError(f"split side must be 'train', 'held-out' or 'all', got {name!r}")

    def to_dict(self) -> dict:
        return {"n_traces": self.n_traces, "held_out_fraction": self.held_out_fraction, "seed": self.seed,
                "in_time": self.in_time, "train": [s.to_dict() for s in self.train],
                "held_out": [s.to_dict() for s in self.held_out]}

    @classmethod
    def from_dict(cls, doc: dict) -> "TraceSplit":
        try:
            return cls(tuple(TraceSegment(**s) for s in doc["train"]),
                       tuple(TraceSegment(**s) for s in doc["held_out"]), int(doc["n_traces"]),
                       float(doc["held_out_fraction"]), int(doc["seed"]), bool(doc.get("in_time", False)))
        except (KeyError, TypeError, OverflowError) as e:
            raise ValueError(f"not a trace split: {e!r}") from e


def split_traces(n_traces: int, held_out_fraction: float = 0.25, seed: int = 0) -> TraceSplit:
    """Split a library's traces into training and held-out traces.

    With two or more traces, ``max(1, round(fraction * n))`` traces (at most
    ``n - 1``) drawn by ``numpy.random.default_rng(seed)`` are held out, whole;
    each side keeps at least one trace. A library of **one** trace is split in
    time instead: training gets its first ``1 - held_out_fraction`` of samples,
    the held-out side the rest (``in_time=True``). Held-out gusts then come from
    the same flight as the training gusts, only later, so they test less of a
    controller's generality than another flight would.

    Parameters
    ----------
    n_traces : int
        Traces in the library (``EnvModel.n_traces``), >= 1.
    held_out_fraction : float
        Fraction of traces (or of the single trace's time) held out, in (0, 1).
    seed : int
        Seeds the choice of held-out traces.

    Returns
    -------
    TraceSplit
    """
    if int(n_traces) != n_traces or n_traces < 1:
        raise ValueError(f"n_traces must be a whole number >= 1, got {n_traces!r}")
    if not (isinstance(held_out_fraction, (int, float)) and 0.0 < held_out_fraction < 1.0):
        raise ValueError(f"held_out_fraction must be in (0, 1), got {held_out_fraction!r}")
    n = int(n_traces)
    f = float(held_out_fraction)
    if n == 1:
        return TraceSplit((TraceSegment(0, 0.0, 1.0 - f),), (TraceSegment(0, 1.0 - f, 1.0),), 1, f, int(seed), True)
    k = min(max(1, int(round(f * n))), n - 1)
    order = np.random.default_rng(seed).permutation(n)
    held = sorted(int(i) for i in order[:k])
    train = sorted(int(i) for i in order[k:])
    return TraceSplit(tuple(TraceSegment(i) for i in train), tuple(TraceSegment(i) for i in held), n, f, int(seed))


def segment_rooms(env_model, segments, needed: int) -> np.ndarray:
    """Number of distinct windows of ``needed`` samples in each segment (offsets ``first .. end - needed``).

    Raises
    ------
    ValueError
        A segment names a trace the library lacks, or is shorter than one window.
    """
    rooms = []
    for seg in segments:
        if seg.trace >= env_model.n_traces:
            raise ValueError(f"segment of trace {seg.trace}: the library holds {env_model.n_traces} traces")
        length = int(env_model.lengths[seg.trace])
        first, end = seg.samples(length)
        room = window_count(end - first, needed)
        if room < 1:
            raise ValueError(
                f"trace {seg.trace} ({env_model.trace_ids[seg.trace]}) from {first / env_model.sample_rate:g} s to "
                f"{end / env_model.sample_rate:g} s is shorter than one episode of "
                f"{(needed - 1) / env_model.sample_rate:g} s; the longest episode that fits every trace is "
                f"{longest_episode_s(env_model, segments):g} s: pass episode_seconds="
                f"{longest_episode_s(env_model, segments):g} or less")
        rooms.append(room)
    return np.array(rooms, dtype=np.int64)


def longest_episode_s(env_model, segments) -> float:
    """The longest episode [s, floored to 10 ms] whose window fits in every segment (``heli evaluate`` flies
    it when its default of 30 s does not fit a short flight's traces)."""
    spans = [(lambda fe: fe[1] - fe[0] - 1)(seg.samples(int(env_model.lengths[seg.trace]))) for seg in segments
             if seg.trace < env_model.n_traces]
    return math.floor(100.0 * max(min(spans), 0) / env_model.sample_rate) / 100.0


def draw_windows(env_model, segments, needed: int, rng: np.random.Generator, count: int | None = None,
                 per_segment: int | None = None) -> list:
    """Gust windows ``(trace, offset)`` of ``needed`` samples inside ``segments``.

    Either ``count`` windows drawn uniformly over all windows the segments hold
    (a segment is chosen with probability proportional to its room), or
    ``per_segment`` windows from each segment in turn (distinct offsets where the
    segment has room). Every draw comes from ``rng``.

    Parameters
    ----------
    env_model : heli_env.env_model.EnvModel
    segments : sequence of TraceSegment
    needed : int
        Library samples one episode replays (``EnvSpec.needed``).
    rng : numpy Generator
    count, per_segment : int
        Exactly one of them.

    Returns
    -------
    list of (int, int)
        Library trace index and start sample (the environments' ``offset``).
    """
    segments = tuple(segments)
    if not segments:
        raise ValueError("segments must name at least one trace")
    if (count is None) == (per_segment is None):
        raise ValueError("give exactly one of count and per_segment")
    rooms = segment_rooms(env_model, segments, needed)
    out = []
    if count is not None:
        p = rooms / rooms.sum()
        for _ in range(int(count)):
            j = int(rng.choice(len(segments), p=p))
            seg = segments[j]
            first = seg.samples(int(env_model.lengths[seg.trace]))[0]
            out.append((seg.trace, first + draw_offset(rng, rooms[j])))
        return out
    for seg, room in zip(segments, rooms):
        first = seg.samples(int(env_model.lengths[seg.trace]))[0]
        out.extend((seg.trace, first + o) for o in draw_offsets(rng, room, int(per_segment)))
    return out


class WindowSampler:
    """Reset options pinning a random gust window of ``segments``: ``sampler(i, rng) -> {"trace", "offset"}``.

    Windows are uniform over every window the segments hold (as :func:`draw_windows`
    with ``count=1``), drawn from the caller's ``rng``; ``i`` (the copy) is unused.
    This is the ``episode_options`` hook of :class:`controllers.rl.vec_env.GymnasiumVecEnv`.
    """

    def __init__(self, env_model, segments, needed: int):
        self.segments = tuple(segments)
        if not self.segments:
            raise ValueError("segments must name at least one trace")
        self.rooms = segment_rooms(env_model, self.segments, needed)
        self.firsts = [s.samples(int(env_model.lengths[s.trace]))[0] for s in self.segments]
        self._p = self.rooms / self.rooms.sum()

    def __call__(self, i: int, rng: np.random.Generator) -> dict:
        j = int(rng.choice(len(self.segments), p=self._p)) if len(self.segments) > 1 else 0
        return {"trace": self.segments[j].trace, "offset": self.firsts[j] + draw_offset(rng, self.rooms[j])}


class GustCurriculum:
    """Episode options of ``sampler`` with the gusts scaled by how far training has come (a curriculum).

    ``gust_scale`` rises linearly from ``start`` at timestep 0 to 1 at ``steps`` and stays 1 after;
    the trainer sets :attr:`timesteps` as it goes (:class:`controllers.sb3_training.CurriculumProgress`).
    The scale depends on timesteps only, so the same seed gives the same episodes.

    Parameters
    ----------
    sampler : callable
        ``sampler(i, rng) -> dict`` of reset options (a :class:`WindowSampler`).
    start : float
        Gust multiplier of the first episodes, in [0, 1).
    steps : int
        Timesteps over which the gusts reach their recorded level, >= 1.
    """

    def __init__(self, sampler, start: float, steps: int):
        if not (is_real(start) and 0.0 <= start < 1.0):
            raise ValueError(f"the curriculum's starting gust scale must be a number in [0, 1), got {start!r}")
        steps = whole_number(steps, "the curriculum's steps", 1)
        self.sampler, self.start, self.steps = sampler, float(start), steps
        self.timesteps = 0

    @property
    def gust_scale(self) -> float:
        """The gust multiplier of episodes starting now."""
        return self.start + (1.0 - self.start) * min(self.timesteps / self.steps, 1.0)

    def __call__(self, i: int, rng: np.random.Generator) -> dict:
        return {**self.sampler(i, rng), "gust_scale": self.gust_scale}


def as_segments(traces, split: TraceSplit | None = None, default: str = "held-out") -> tuple:
    """Segments from trace indices, :class:`TraceSegment` objects, or a split side name.

    Parameters
    ----------
    traces : None, str, or sequence of int / TraceSegment
        None takes ``split.side(default)``; a string ``"train"``, ``"held-out"`` or
        ``"all"`` names a side of ``split``; ints are whole traces.
    split : TraceSplit, optional
        Needed when ``traces`` is None or a string.
    """
    if traces is None or isinstance(traces, str):
        if split is None:
            raise ValueError("a split is needed to take the segments of a side")
        return split.side(default if traces is None else traces)
    out = []
    for t in traces:
        out.append(t if isinstance(t, TraceSegment) else TraceSegment(int(t)))
    if not out:
        raise ValueError("traces must name at least one trace")
    return tuple(out)
