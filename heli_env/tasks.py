"""Tasks of the attitude environments: references, observation, reward, termination.

Every draw an episode makes happens in :func:`draw_episodes`, in one fixed order
from the environment's ``np_random``, so the single and the vector environment
draw the same episode from the same seed. The reward and observation are
written once, with arithmetic that serves floats (single env) and arrays
(vector env) alike.

References (``task``):

* ``"hold"`` — level attitude and the initial heading; reference rates zero.
* ``"track"`` — a reference attitude that is either a staircase of random steps
  (a new target every ``step_period`` s, roll/pitch within ±``max_angle_ref``,
  yaw within ±``max_yaw_ref`` of the initial heading) or a smooth random path
  (per axis a sum of two sinusoids of 0.05-0.4 Hz, same bounds), chosen per
  episode by ``reference`` = "steps" | "smooth" | "mixed" (half and half); the
  reference rates are its time derivative (zero between steps).
* ``"rate"`` — reference body rates, steps or smooth as above within
  ±``max_rate_ref``; attitude is not rewarded.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from heli_core.config import is_real

TASKS = ("hold", "track", "rate")
REFERENCES = ("steps", "smooth", "mixed")
N_SINES = 2
TWO_PI = 2.0 * math.pi


def three_weights(value, name: str, labels: str) -> tuple:
    """``value`` as 3 finite floats >= 0, else ValueError naming ``name`` and what each weighs (``labels``)."""
    try:
        weights = tuple(value) if not isinstance(value, (str, bytes)) else ()
    except TypeError:
        weights = ()
    if len(weights) != 3 or not all(is_real(w) and w >= 0 for w in weights):
        raise ValueError(f"{name} must be 3 finite numbers >= 0 ({labels}), got {value!r}")
    return tuple(float(w) for w in weights)


@dataclass(frozen=True)
class TaskConfig:
    """What the agent is asked to do, and how it is scored.

    Attributes
    ----------
    task : {"hold", "track", "rate"}
    reference : {"steps", "smooth", "mixed"}
        Reference shape for "track" and "rate".
    step_period : float
        Time between reference steps [s].
    max_angle_ref : float
        Roll and pitch reference bound [rad] (default 15°).
    max_yaw_ref : float
        Yaw reference bound about the initial heading [rad] (default 30°).
    max_rate_ref : float
        Rate reference bound for "rate" [rad/s] (default 30°/s).
    attitude_scale, rate_scale : float
        Errors that cost 1 per axis and step: 10° and 30°/s by default [rad, rad/s].
    weights : tuple of 3 float
        Weights of the attitude, rate and control-effort terms. Default
        (1, 0.1, 0.01) for "hold"/"track", (0, 1, 0.01) for "rate".
    axis_weights : tuple of 3 float
        Weights of roll, pitch and yaw in the attitude and rate terms (default 1, 1, 1):
        ``(w_roll, w_pitch, w_yaw)`` multiply each axis' squared errors, so an axis
        whose errors are naturally smaller (pitch beside yaw) can count as much.
    stick_step_weight : float
        Weight of the squared change of the applied action from the step before, summed over the axes
        (the first step of an episode from rest): the chatter a servo feels, which the effort term
        (``a²``) charges only by its size. Default 0: the reward without it, bit for bit.
    max_angle : float
        |roll| or |pitch| beyond this terminates the episode [rad] (default 60°).
    """

    task: str = "hold"
    reference: str = "mixed"
    step_period: float = 3.0
    max_angle_ref: float = math.radians(15.0)
    max_yaw_ref: float = math.radians(30.0)
    max_rate_ref: float = math.radians(30.0)
    attitude_scale: float = math.radians(10.0)
    rate_scale: float = math.radians(30.0)
    weights: tuple | None = None
    max_angle: float = math.radians(60.0)
    axis_weights: tuple = (1.0, 1.0, 1.0)
    stick_step_weight: float = 0.0

    def __post_init__(self):
        if self.task not in TASKS:
            raise ValueError(f"task must be one of {TASKS}, got {self.task!r}")
        if self.reference not in REFERENCES:
            raise ValueError(f"reference must be one of {REFERENCES}, got {self.reference!r}")
        for name in ("step_period", "attitude_scale", "rate_scale", "max_angle"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)!r}")
        if self.weights is None:
            object.__setattr__(self, "weights", (0.0, 1.0, 0.01) if self.task == "rate" else (1.0, 0.1, 0.01))
        object.__setattr__(self, "weights", three_weights(self.weights, "weights", "attitude, rate, effort"))
        object.__setattr__(self, "axis_weights", three_weights(self.axis_weights, "axis_weights", "roll, pitch, yaw"))
        w = self.stick_step_weight
        if isinstance(w, bool) or not (is_real(w) and w >= 0):
            raise ValueError(f"stick_step_weight must be a number >= 0, got {w!r}")
        object.__setattr__(self, "stick_step_weight", float(w))

    @property
    def axis_weighted(self) -> bool:
        """The axes weigh differently in the reward (``axis_weights`` is not all ones)."""
        return self.axis_weights != (1.0, 1.0, 1.0)

    @cached_property
    def reward_coefficients(self) -> tuple[float, ...]:
        """:func:`reward_coefficients`, computed once (the single env reads them every step)."""
        wa, wr, wu = self.weights
        return (wa / (self.attitude_scale * self.attitude_scale), wr / (self.rate_scale * self.rate_scale), wu,
                *self.axis_weights, self.stick_step_weight)


@dataclass
class Episode:
    """The draws of one episode (see :func:`draw_episode`)."""

    trace: int
    offset: int
    angles: np.ndarray  # initial roll, pitch [rad]
    rates: np.ndarray  # initial p, q, r [rad/s]
    smooth: bool
    steps: np.ndarray  # (3, n_segments) staircase values
    amp: np.ndarray  # (3, N_SINES)
    freq: np.ndarray  # (3, N_SINES) [rad/s]
    phase: np.ndarray  # (3, N_SINES)


@dataclass
class Episodes:
    """The draws of several episodes, one per generator (see :func:`draw_episodes`): :class:`Episode`'s fields
    with the episodes along the first axis."""

    trace: np.ndarray  # (m,) int64
    offset: np.ndarray  # (m,) int64
    angles: np.ndarray  # (m, 2)
    rates: np.ndarray  # (m, 3)
    smooth: np.ndarray  # (m,) bool
    steps: np.ndarray  # (m, 3, n_segments)
    amp: np.ndarray  # (m, 3, N_SINES)
    freq: np.ndarray  # (m, 3, N_SINES)
    phase: np.ndarray  # (m, 3, N_SINES)

    def __getitem__(self, i: int) -> Episode:
        return Episode(int(self.trace[i]), int(self.offset[i]), self.angles[i], self.rates[i], bool(self.smooth[i]),
                       self.steps[i], self.amp[i], self.freq[i], self.phase[i])


@lru_cache(maxsize=32)
def _uniform_ranges(init_angle: float, init_rate: float, mixed: bool, n_seg: int) -> tuple:
    """The columns of one episode's standard uniforms (:func:`draw_episodes`): their ``low`` and ``high - low``
    (as ``rng.uniform(low, high)`` turns a standard uniform ``u`` into ``low + (high - low) * u``; 0 and 1 leave
    ``u`` as it is, bit for bit), and the slices of the quantities in them."""
    parts = [("angles", 2, -init_angle, init_angle), ("rates", 3, -init_rate, init_rate),
             ("smooth", int(mixed), 0.0, 1.0), ("steps", 3 * n_seg, -1.0, 1.0), ("amp", 3 * N_SINES, 0.2, 1.0),
             ("freq", 3 * N_SINES, 0.05, 0.4), ("phase", 3 * N_SINES, 0.0, TWO_PI)]
    low = np.concatenate([np.full(width, lo) for _, width, lo, _ in parts])
    span = np.concatenate([np.full(width, hi - lo) for _, width, lo, hi in parts])
    edges = [0, *itertools.accumulate(width for _, width, _, _ in parts)]
    return low, span, {name: slice(a, b) for (name, *_), a, b in zip(parts, edges, edges[1:])}


def draw_episodes(rngs, spec, options=None) -> Episodes:
    """Draw everything random about an episode from each generator of ``rngs``, in a fixed order.

    Per generator: the trace and the window's offset (two ``integers``), then one ``random`` call for every
    other draw: the initial roll and pitch (2) and rates (3), whether the reference is smooth (1, with
    ``reference="mixed"``), the staircase (3 per segment) and the sinusoids' amplitudes, frequencies and
    phases (3 x :data:`N_SINES` each), each turned into its range as ``rng.uniform`` does
    (:func:`uniform_ranges`). The generator draws the same numbers as one ``uniform`` call per quantity and
    the episode is the same bit for bit; across generators the arithmetic is one numpy operation
    (:func:`episodes_from`). The native vector env draws the same numbers in compiled code
    (:mod:`heli_env.generator_draws`).

    Parameters
    ----------
    rngs : sequence of numpy Generator
        The environments' ``np_random`` (one per episode).
    spec : heli_env.spec.EnvSpec
        The environment's settings: its task, the library's traces (``spec.model.n_traces``,
        ``spec.model.lengths`` [samples]), the trace samples an episode of full length uses
        (``needed``), its steps and period, and the initial ranges ``init_angle`` [rad] and
        ``init_rate`` [rad/s].
    options : dict, optional
        ``trace`` (index) and ``offset`` (sample) pin the replayed gust.
    """
    trace_pin, offset_pin = window_pins(spec, options)
    lengths = spec.model.lengths
    uniforms = np.empty((len(rngs), uniform_ranges(spec)[0].size))
    traces, offsets = [], []
    for i, rng in enumerate(rngs):
        trace = int(rng.integers(spec.model.n_traces))
        trace = trace if trace_pin < 0 else trace_pin
        offset = draw_offset(rng, max(window_count(lengths[trace], spec.needed), 1))  # a short trace ends early
        traces.append(trace)
        offsets.append(offset if offset_pin is None else offset_pin)
        rng.random(out=uniforms[i])
    traces, offsets = np.array(traces, dtype=np.int64), np.array(offsets, dtype=np.int64)
    check_offset(spec, traces, offset_pin)
    return episodes_from(spec, traces, offsets, uniforms)


def window_pins(spec, options) -> tuple[int, int | None]:
    """The trace (-1 where none) and the window offset (None where none) ``options`` pin, the trace checked
    against the library (ValueError); the offset is checked on the trace drawn (:func:`check_offset`)."""
    options = options or {}
    trace, offset = options.get("trace"), options.get("offset")
    n_traces = spec.model.n_traces
    if trace is not None:
        trace = int(trace)
        if not 0 <= trace < n_traces:
            raise ValueError(f"options['trace'] must be a trace index in [0, {n_traces}), got {trace}")
    return (-1 if trace is None else trace), (None if offset is None else int(offset))


def check_offset(spec, traces: np.ndarray, offset_pin: int | None) -> None:
    """ValueError where a pinned offset (``offset_pin``, None: none) is not a sample of an episode's trace
    (``traces``)."""
    if offset_pin is None:
        return
    lengths = np.asarray(spec.model.lengths)[traces]
    bad = np.flatnonzero((offset_pin < 0) | (offset_pin >= lengths - 1))
    if bad.size:
        trace = int(traces[bad[0]])
        raise ValueError(f"options['offset'] must be a sample in [0, {int(lengths[bad[0]]) - 1}) of trace {trace}, "
                         f"got {offset_pin}")


def window_counts(spec) -> np.ndarray:
    """Per trace, how many windows an episode's offset is drawn over (int64): :func:`window_count`, at least 1
    (a short trace ends the episode early)."""
    return np.array([max(window_count(length, spec.needed), 1) for length in spec.model.lengths], dtype=np.int64)


def uniform_ranges(spec) -> tuple:
    """:func:`_uniform_ranges` of ``spec``: an episode's standard uniforms' ``low``, ``span`` and slices, and its
    reference's segments."""
    cfg = spec.task
    n_seg = int(spec.episode_steps * spec.dt // cfg.step_period) + 1
    return (*_uniform_ranges(float(spec.init_angle), float(spec.init_rate), cfg.reference == "mixed", n_seg),
            n_seg)


def episodes_from(spec, traces: np.ndarray, offsets: np.ndarray, uniforms: np.ndarray) -> Episodes:
    """The episodes drawn as ``traces``, ``offsets`` (m,) and standard ``uniforms`` (m, columns of
    :func:`uniform_ranges`), each uniform turned into its quantity's range."""
    cfg = spec.task
    low, span, at, n_seg = uniform_ranges(spec)
    m = traces.size
    v = low + span * uniforms
    smooth = v[:, at["smooth"].start] < 0.5 if cfg.reference == "mixed" else np.full(m, cfg.reference == "smooth")
    bound = reference_bounds(cfg)[:, None]
    unit_steps = v[:, at["steps"]].reshape(m, 3, n_seg)
    unit_steps[:, :, 0] = 0.0  # start from the current hold point, then step
    unit_amp = v[:, at["amp"]].reshape(m, 3, N_SINES)
    return Episodes(traces, offsets, v[:, at["angles"]],
                    v[:, at["rates"]], smooth, unit_steps * bound, unit_amp / unit_amp.sum(axis=2, keepdims=True) * bound,
                    TWO_PI * v[:, at["freq"]].reshape(m, 3, N_SINES), v[:, at["phase"]].reshape(m, 3, N_SINES))


def draw_episode(rng: np.random.Generator, spec, options=None) -> Episode:
    """Draw everything random about an episode from the environment's ``np_random`` ``rng``: the
    :func:`draw_episodes` of one generator."""
    return draw_episodes([rng], spec, options)[0]


def window_count(length: int, needed: int) -> int:
    """Distinct gust windows of ``needed`` samples in a stretch of ``length`` samples: ``length - needed + 1``.

    Less than 1 when no window fits. Window ``o`` replays samples ``o .. o + needed - 1``.
    """
    return int(length) - int(needed) + 1


def draw_offset(rng: np.random.Generator, count: int) -> int:
    """One window start, uniform over ``count`` distinct windows (one ``rng.integers`` draw)."""
    return int(rng.integers(count))


def draw_offsets(rng: np.random.Generator, count: int, m: int) -> list:
    """``m`` window starts uniform over ``count`` windows, sorted; distinct when ``m <= count``.

    One ``rng.choice`` draw, without replacement where the stretch has room for ``m`` windows.
    """
    return [int(o) for o in np.sort(rng.choice(count, size=m, replace=m > count))]


def reference_bounds(cfg: TaskConfig) -> np.ndarray:
    """Bounds of the reference per axis [rad or rad/s]."""
    if cfg.task == "rate":
        return np.full(3, cfg.max_rate_ref)
    return np.array([cfg.max_angle_ref, cfg.max_angle_ref, cfg.max_yaw_ref])


def wrap(angle):
    """Wrap an angle (float or array) to [-pi, pi] (ties to even at the boundary).

    ``round`` on a float and ``numpy.round`` on an array both round half to even,
    so the single and the vector environment wrap identically.
    """
    if isinstance(angle, float):
        return angle - TWO_PI * round(angle / TWO_PI)
    return angle - TWO_PI * np.round(angle / TWO_PI)


def reward_coefficients(cfg: TaskConfig) -> tuple[float, ...]:
    """Weights of the squared attitude error [1/rad^2], rate error [s^2/rad^2] and action in the reward,
    then the three axis weights (roll, pitch, yaw) and the stick step's weight."""
    return cfg.reward_coefficients


def reward_of(cfg: TaskConfig, e_att, e_rate, action, previous=(0.0, 0.0, 0.0)):
    """Reward of one step from the attitude errors [rad], rate errors [rad/s] and action [stick], 3 each, and
    the action applied the step before (``previous``; read only with a ``stick_step_weight``).

    ``-(w_att * att2/attitude_scale^2 + w_rate * rate2/rate_scale^2 + w_u * effort2 [+ w_s * step2])``
    with ``att2 = sum(w_axis * e_att^2)``, ``rate2 = sum(w_axis * e_rate^2)``,
    ``effort2 = sum(a^2)`` and, when ``w_s = stick_step_weight > 0``, ``step2 = sum((a - previous)^2)``;
    floats or arrays over copies. Without axis weights the sums are unweighted (``e0*e0 + e1*e1 + e2*e2``).
    The vector environment's loop (:func:`heli_env.kernels.env_kernels`) evaluates the same expression
    with :func:`reward_coefficients`.
    """
    ca, cr, cu, w0, w1, w2, cs = cfg.reward_coefficients
    e, r, a = e_att, e_rate, action
    if cfg.axis_weighted:
        att2 = w0 * e[0] * e[0] + w1 * e[1] * e[1] + w2 * e[2] * e[2]
        rate2 = w0 * r[0] * r[0] + w1 * r[1] * r[1] + w2 * r[2] * r[2]
    else:
        att2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2]
        rate2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    cost = ca * att2 + cr * rate2 + cu * (a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if cs > 0.0:  # added last, as the vector env's loop adds it: the same rounding
        d0, d1, d2 = a[0] - previous[0], a[1] - previous[1], a[2] - previous[2]
        cost = cost + cs * (d0 * d0 + d1 * d1 + d2 * d2)
    return -cost


def draw_line_phases(rngs, n_lines: int) -> np.ndarray:
    """A uniform random phase per gyro vibration line from each generator of ``rngs``, as its (cos, sin) pair:
    (len(rngs), n_lines, 2).

    Drawn as a normalised Gaussian pair, so that a line reads ``sin(w t) cos + cos(w t) sin`` with only
    products and sums: the single and the vector environment compute it bit for bit alike.
    """
    return phases_from(np.array([rng.normal(0.0, 1.0, (n_lines, 2)) for rng in rngs]).reshape(len(rngs), n_lines, 2))


def phases_from(g: np.ndarray) -> np.ndarray:
    """The (cos, sin) pairs of normal pairs ``g`` (..., 2): each pair divided by its length."""
    norm = np.sqrt(g[..., 0] * g[..., 0] + g[..., 1] * g[..., 1])
    return g / norm[..., None]


def line_phases(rng: np.random.Generator, n_lines: int) -> list:
    """:func:`draw_line_phases` of the one generator ``rng``, as a list of (cos, sin) pairs."""
    return draw_line_phases([rng], n_lines)[0].tolist()

