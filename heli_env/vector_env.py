"""The native vector environment: ``num_envs`` helicopters stepped as numpy batches."""

from __future__ import annotations

import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from heli_core.physics import N_STATE
from heli_core.quaternion import quaternion_from_euler

from .env_model import as_env_model
from .errors import ActionError
from .kernels import N_ROWS, OUT, R, BlockLayout, env_kernels, first_non_finite
from .observation import MAX_RATE, OBS_DIM, action_space, observation_space
from .generator_draws import Streams
from .spec import build_spec, real_actions, reset_options
from .restarts import INTS, KEY, START_ROWS, EpisodesAhead, Starts, write_starts
from .tasks import (N_SINES, check_offset, episodes_from, phases_from, reward_coefficients, uniform_ranges,
                    window_counts, window_pins)
from .threads import ThreadChoice


class HeliAttitudeVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`heli_env.env.HeliAttitudeEnv`, batched in numpy.

    Same arguments, spaces, rewards, episode ends and info as the single
    environment (see its docstring), plus ``num_envs`` and ``threads``. The
    state is held as an array of shape ``(N_STATE, num_envs)`` and stepped by
    a fused numba loop compiled from the same statements as the single
    environment's physics core (:func:`heli_core.discrete.discrete_step_statements`,
    :mod:`heli_env.kernels`). ``threads`` is how many threads share the copies
    (default None: one, or numba's pool while it measures faster on a large
    batch; ``$HELI_NUM_THREADS`` fixes it too: :mod:`heli_env.threads`);
    results do not depend on it. Every episode
    is drawn by the same function from a per-copy random generator seeded
    ``seed + i``, so copy ``i`` reproduces a single
    environment reset with ``seed + i`` under the same actions (the dynamics
    bit for bit, observations to float rounding of ``atan2``/``sin``).

    Autoreset is ``NEXT_STEP`` (Gymnasium's default): after a copy's episode
    ends, its next ``step`` resets it and returns the first observation of the
    new episode with reward 0. ``reset(options={"reset_mask": mask})`` resets
    only the copies where ``mask`` is True. Each copy's next episode is drawn
    ahead, many copies at once (:mod:`heli_env.restarts`): the same draws from
    the same generator, so nothing a user sees changes, and a long run's
    autoresets cost little.

    Infos are dicts of arrays over copies (``time``, ``disturbance`` (n, 3),
    ``attitude_error_deg`` (n, 3), ``rate_error_deg_s`` (n, 3), ``trace``), each
    with its ``_name`` mask as Gymnasium's vector API prescribes.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP, "render_fps": 25}

    def __init__(self, num_envs: int = 1, model=None, task="hold", reference="mixed", dt: float | None = None,
                 episode_seconds: float = 30.0, collective="trace", gust_scale: float = 1.0, obs_noise="model",
                 action_delay: int = 0, init_angle_deg: float = 5.0, init_rate_deg: float = 5.0,
                 library_version=None, render_mode: str | None = None, threads: int | None = None):
        if int(num_envs) != num_envs or num_envs < 1:
            raise ValueError(f"num_envs must be a positive whole number, got {num_envs!r}")
        self._thread_choice = ThreadChoice(int(num_envs), threads)
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be 'rgb_array' or None for the vector env, got {render_mode!r}")
        self.spec_ = s = build_spec(as_env_model(model, library_version), task, reference, dt, episode_seconds,
                                    collective, gust_scale, obs_noise, action_delay, init_angle_deg, init_rate_deg)
        self.num_envs = n = int(num_envs)
        self.render_mode = render_mode
        self.single_observation_space = observation_space()
        self.single_action_space = action_space()
        self.observation_space = batch_space(self.single_observation_space, n)
        self.action_space = batch_space(self.single_action_space, n)
        # Library columns gathered once per step, one row per sample so that a gather reads
        # contiguous memory: trims (3), collective, gust torque (3), u_d (3).
        self._table = np.ascontiguousarray(np.vstack([s.trim, s.col[None, :], s.torque, s.model.ud]).T)
        self._rows = None  # BlockLayout: the state and every per-copy row the step loops share, once reset
        variant = (s.task.task, s.measured, s.task.axis_weighted, s.line_axis, s.task.stick_step_weight > 0.0)
        kernels = env_kernels(s.model.params, s.dt, *variant)
        self._step_loop = kernels.step
        self._step_pool = kernels.step_pool if self._thread_choice.compiled_parallel else None
        self._constants = kernels.constants  # the model's values, read by the loops
        self._coef = np.array(reward_coefficients(s.task))
        self._rngs = [None] * n  # each copy's np_random, drawn through self._streams (heli_env.generator_draws)
        self._streams = Streams(n)
        self._counts = window_counts(s)  # per trace, the windows an episode's offset is drawn over
        self._n_uniforms = uniform_ranges(s)[0].size
        self._ahead = EpisodesAhead(self._streams, self._draw)  # each copy's next episode, drawn ahead
        self._ints = np.zeros((len(INTS), n), dtype=np.int64)  # restarts.INTS: rows written by a reset at once
        self._gust = np.zeros(n)
        self._restart = None  # the copies whose episode ended in the last step (indices), None if none did
        self._restarting = np.zeros(n, dtype=np.uint8)  # 1: the copy starts its next episode in this step
        self._queue = np.zeros((s.action_delay, n, 3)) if s.action_delay else None  # actions not yet applied
        n_seg = int(s.episode_steps * s.dt // s.task.step_period) + 1
        self._references = (np.zeros(n, dtype=bool), np.zeros((3, n_seg, n)), *np.zeros((3, 3, N_SINES, n)))
        self._smooth, self._steps, self._amp, self._freq, self._phase = self._references
        n_lines = len(s.line_axis)  # the gyro lines: sin, cos of each at every step; each copy's phases
        self._line_amp = np.array(s.line_amp, dtype=float)
        self._line_table = np.ascontiguousarray(np.stack([s.line_sin, s.line_cos], axis=-1).transpose(1, 0, 2)
                                                .reshape(s.line_sin.shape[1], 2 * n_lines))
        self._noise_std = np.array([*s.obs_noise[0], *s.obs_noise[1]], dtype=float)
        self._ones = np.ones(n, dtype=bool)
        self._no_actions = np.zeros((n, 3))  # what the loop is given when it only observes
        self._actions = np.empty((n, 3))  # float32 actions as the loop reads them
        self._bind()
        self._out = None  # the last step's output rows (u_d, errors, reward, end): a fresh array each step
        self._renderer = None
        self._history = []

    _VIEWS = ("_k", "_base", "_last", "_nsteps", "_trace", "_key", "_observe_arguments")

    def _bind(self) -> None:
        """The views of ``_ints`` the loops and resets share (its rows: :data:`heli_env.restarts.INTS`)."""
        self._k, self._base, self._last, self._nsteps, self._trace = self._ints[:KEY]
        self._key = self._ints[KEY].view(np.uint64)  # each copy's episode noise key (heli_env.sensor_noise)
        self._observe_arguments = (self._k, self._nsteps, self._key, self._noise_std, self._line_amp,
                                   self._line_table, MAX_RATE, self.spec_.task.max_angle, self._coef)  # in place

    def __getstate__(self) -> dict:
        return {name: value for name, value in self.__dict__.items() if name not in self._VIEWS}

    def __setstate__(self, state: dict) -> None:
        """A copy (``copy.deepcopy``) views its own arrays: a copied view would be an array apart."""
        self.__dict__.update(state)
        self._bind()

    @property
    def _x(self) -> np.ndarray:
        """The state of every copy, (N_STATE, num_envs): a copy."""
        return self._rows.get(R["x0"], R["x0"] + N_STATE)

    @property
    def _prev(self) -> np.ndarray:
        """The action applied in the last step, (3, num_envs): a copy."""
        return self._rows.get(R["act0"], R["act0"] + 3)

    @property
    def model(self):
        """The :class:`heli_env.env_model.EnvModel` driving the environments."""
        return self.spec_.model

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed=None, options=None):
        s = self.spec_
        n = self.num_envs
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        mask = self._ones.copy() if mask is None else np.asarray(mask, dtype=bool)
        if mask.shape != (n,):
            raise ValueError(f"reset_mask must have shape ({n},), got {mask.shape}")
        if seed is not None:
            seeds = [seed + i for i in range(n)] if isinstance(seed, int) else list(seed)
            if len(seeds) != n:
                raise ValueError(f"seed must be an int or {n} seeds, got {len(seeds)}")
            renewed = [i for i in range(n) if mask[i] or self._rngs[i] is None]
            self._ahead.forget(np.array(renewed, dtype=np.int64), restore=False)
            for i in renewed:
                self._adopt(i, seeding.np_random(seeds[i])[0])
        for i in range(n):
            if self._rngs[i] is None:
                self._adopt(i, seeding.np_random(None)[0])
        if self._rows is None:
            if not mask.all():
                raise ResetNeeded("the first reset must reset every copy (no reset_mask)")
            self._rows = BlockLayout(n, extra_rows=2 * len(s.line_axis))  # the lines' phases after R's rows
        which = np.flatnonzero(mask)
        self._reset_envs(which, options)
        obs, out, ends = self._fresh_outputs()
        j = self._base + np.minimum(self._k, self._last) * s.ratio
        self._rows.put(R["ud0"], self._table[j, 7:10].T * self._gust)  # the gust about to act
        # a copy not reset is observed again as it was last: its observation is a function of its state, step
        # and noise key, all unchanged
        self._put_references()
        self._observe(obs, out, ends, 0, self._rows.blocks)
        return obs, self._info(out)

    def _reset_envs(self, which, options):
        """Start the next episodes of copies ``which``: each drawn ahead where it has one and the options are
        the defaults (:mod:`heli_env.restarts`), drawn now otherwise, all from the copy's own generator (as
        a single env seeded ``seed + i`` would draw them)."""
        options, gust = reset_options(options, self.spec_.gust_scale)
        if which.size == 0:
            return
        if options:  # what is drawn depends on them: from the generator's state before any draw ahead
            self._ahead.forget(which, restore=True)
            self._start(which, self._draw(which, options, gust))
        else:
            ready = self._ahead.ready[which]
            ahead, now = which[ready], which[~ready]
            if ahead.size:
                self._start(ahead, self._ahead.starts, ahead)
                self._ahead.take(ahead)
            if now.size:
                self._start(now, self._draw(now))
                self._ahead.drawn_now(now)
        if self._restart is not None:  # reset now (a masked reset): they do not restart at the next step
            left = self._restart[~np.isin(self._restart, which, assume_unique=True)]
            self._restart = left if left.size else None

    def _adopt(self, i: int, rng) -> None:
        self._rngs[i] = rng
        self._streams.adopt(i, rng)

    def _draw(self, which, options=None, gust=None) -> Starts:
        """The episodes of copies ``which`` from their generators: the episode, then the gyro lines' phases, then
        the noise key (the single env's order: :func:`heli_env.tasks.draw_episodes`, ``line_phases``,
        ``draw_noise_key``, the same numbers drawn in one compiled call), as what their resets write."""
        s = self.spec_
        n_lines = len(s.line_axis)
        trace_pin, offset_pin = window_pins(s, options)
        traces, offsets, uniforms, normals, keys = self._streams.draw(
            which, s.model.n_traces, self._counts, self._n_uniforms, 2 * n_lines, s.measured, trace_pin,
            -1 if offset_pin is None else offset_pin)
        check_offset(s, traces, offset_pin)
        eps = episodes_from(s, traces, offsets, uniforms)
        m = which.size
        rows = np.zeros((START_ROWS + 2 * n_lines, m))  # the action rows stay 0
        if n_lines:  # (cos, sin) of each line
            rows[START_ROWS:] = phases_from(normals.reshape(m, n_lines, 2)).reshape(m, -1).T
        ints = np.zeros((len(INTS), m), dtype=np.int64)
        if s.measured:
            ints[KEY] = keys.view(np.int64)
        base = s.model.starts[traces] + eps.offset
        stop = np.minimum(s.model.starts[traces] + s.model.lengths[traces], base + s.needed)
        last = (stop - base + s.ratio - 1) // s.ratio - 1  # len(range(base, stop, ratio)) - 1
        # as the single env: the time limit, or until the replay reaches the trace's last sample
        ints[1:KEY] = base, last, np.minimum(s.episode_steps, np.maximum(last, 1)), traces
        angles = eps.angles.T
        rows[0:3] = eps.rates.T
        rows[3:6] = s.trim[:, base]
        rows[6:10] = quaternion_from_euler(angles[0], angles[1], 0.0)  # elementwise as on one copy
        rows[R["gust"] - R["x0"]] = s.gust_scale if gust is None else gust
        refs = None if s.task.task == "hold" else (
            eps.smooth, *(v.transpose(1, 2, 0) for v in (eps.steps, eps.amp, eps.freq, eps.phase)))
        return Starts(ints, rows, refs)

    def _start(self, which, starts: Starts, cols=None):
        """Write columns ``cols`` (all by default) of ``starts`` as copies ``which``'s state, step, replay and
        reference."""
        cols = np.arange(which.size) if cols is None else cols
        write_starts(self._rows.S, self._ints, self._gust, which, starts.ints, starts.rows, cols)
        if self._queue is not None:
            self._queue[:, which] = 0.0
        if starts.references is not None:
            for mine, drawn in zip(self._references, starts.references):
                mine[..., which] = drawn[..., cols]

    # ------------------------------------------------------------------- step
    def step(self, actions):
        if self._rows is None:
            raise ResetNeeded("call reset() before step()")
        s = self.spec_
        n = self.num_envs
        native = isinstance(actions, np.ndarray) and actions.dtype in (np.float32, np.float64)
        a = actions if native else real_actions(actions, "actions")
        if a.shape != (n, 3):
            raise ActionError(f"actions must have shape ({n}, 3) (lat, lon, ped per copy), got {a.shape}")
        bad = first_non_finite(a)
        if bad >= 0:  # nothing has changed yet
            raise ActionError(f"actions must be finite; copy {bad} got {a[bad].tolist()}")
        if a.dtype != np.float64 or not a.flags.c_contiguous:  # the loop is compiled for this layout only
            np.copyto(self._actions, a)
            a = self._actions
        if self._queue is not None:  # the action that acts in this step, observed after it
            incoming = a
            a = self._queue[0].copy()
            self._queue[:-1] = self._queue[1:]
            self._queue[-1] = incoming
        which, self._restart = self._restart, None
        if which is not None:  # these copies start their next episode instead: observed as reset, reward 0
            self._reset_envs(which, {})  # (their queued actions too: the one given now is dropped)
            self._restarting[which] = 1  # the loop keeps their reset state and step (heli_env.kernels)
        self._put_references(1)
        obs, out, ends = self._fresh_outputs()
        rows = self._rows
        ended = self._thread_choice.run(self._step_loop, self._step_pool, rows.S, a, self._table, self._base,
                                        self._last, s.ratio, self._constants, self._restarting,
                                        *self._observe_arguments, obs.reshape(-1), out, ends, 0, rows.blocks, True)
        if which is not None:
            self._restarting[which] = 0
        self._restart = np.flatnonzero(ends[0] | ends[1]) if ended else None
        if self._ahead.due():
            self._ahead.fill()
        return obs, out[OUT["reward"]], ends[0], ends[1], self._info(out)

    # -------------------------------------------------------------- internals
    def _reference(self, t):
        cfg = self.spec_.task
        n = self.num_envs
        if cfg.task == "hold":
            return None, None
        arg = self._freq * t + self._phase  # (3, S, n)
        val_s = (self._amp * np.sin(arg)).sum(axis=1)
        der_s = (self._amp * self._freq * np.cos(arg)).sum(axis=1)
        seg = np.minimum((t // cfg.step_period).astype(np.int64), self._steps.shape[1] - 1)
        val_st = self._steps[:, seg, np.arange(n)]
        val = np.where(self._smooth, val_s, val_st)
        der = np.where(self._smooth, der_s, 0.0)
        if cfg.task == "rate":
            return None, val
        return val, der

    def _put_references(self, ahead: int = 0):
        """Rows ``refatt``/``refrate`` at each copy's step ``k + ahead`` (the step loop observes at ``k + 1``),
        at ``k`` for a copy starting its next episode in the step."""
        if self.spec_.task.task == "hold":
            return
        ref_att, ref_rate = self._reference((self._k + ahead - self._restarting) * self.spec_.dt)
        if ref_att is not None:
            self._rows.put(R["refatt0"], ref_att)
        if ref_rate is not None:
            self._rows.put(R["refrate0"], ref_rate)

    def _observe(self, obs, out, ends, first, stop):
        """Observe the copies of blocks ``first .. stop - 1`` as they are, into ``obs``, ``out`` and ``ends``."""
        self._step_loop(self._rows.S, self._no_actions, self._table, self._base, self._last, self.spec_.ratio,
                        self._constants, self._restarting, *self._observe_arguments, obs.reshape(-1), out, ends,
                        first, stop, False)

    def _fresh_outputs(self):
        """Arrays the loops write a step's observations (n, 12), outputs (:data:`heli_env.kernels.OUT`, n) and
        episode ends (2, n: terminated, truncated) into: fresh each step, since what is returned may be kept."""
        n = self.num_envs
        return np.empty((n, OBS_DIM), dtype=np.float32), np.empty((len(OUT), n)), np.empty((2, n), dtype=bool)

    def _info(self, out):
        """The info dict of the outputs ``out`` just written: views of it (it is fresh each step)."""
        self._out = out
        t = out[OUT["time"]]
        ud = out[OUT["ud0"]:OUT["ud0"] + 3]
        m = self._ones
        info = {"time": t, "_time": m, "disturbance": ud.T, "_disturbance": m,
                "attitude_error_deg": out[OUT["degatt0"]:OUT["degatt0"] + 3].T, "_attitude_error_deg": m,
                "rate_error_deg_s": out[OUT["degrate0"]:OUT["degrate0"] + 3].T, "_rate_error_deg_s": m,
                "trace": self._trace.copy(), "_trace": m}
        if self.render_mode is not None:
            self._remember_frame(t, ud)
        return info

    def _remember_frame(self, t, ud):
        """Copy 0's state, references, gust and action for :meth:`render`."""
        view = self._rows.view
        x = self._x
        a = self._prev
        ref_att, ref_rate = self._reference(t)
        ra = (0.0, 0.0, 0.0) if ref_att is None else tuple(float(v[0]) for v in ref_att)
        rr = (0.0, 0.0, 0.0) if ref_rate is None else tuple(float(v[0]) for v in ref_rate)
        self._history.append((float(t[0]), tuple(float(view(R[f"att{c}"])[0, 0]) for c in range(3)), ra, rr,
                              tuple(x[0:3, 0].tolist()), tuple(ud[:, 0].tolist()), tuple(a[:, 0].tolist())))
        self._history = self._history[-2000:]

    def render(self):
        """An RGB frame of copy 0 (``render_mode="rgb_array"``)."""
        if self.render_mode is None:
            return None
        from .render import Renderer

        if self._renderer is None:
            self._renderer = Renderer("rgb_array", self.spec_.task.task)
        return self._renderer.draw(self._history)

    def close_extras(self, **kwargs):
        self._renderer = None
