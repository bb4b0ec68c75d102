"""The native vector environment: ``num_envs`` helicopters stepped as numpy batches."""

from __future__ import annotations

import math

import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from identification.model import N_STATE, quaternion_from_euler

from .env import OBS_DIM, action_space, observation_space
from .errors import ActionError
from .spec import MAX_RATE, build_spec
from .tasks import N_SINES, draw_episode, reward_from_sums, wrap

_RAD2DEG = 180.0 / math.pi


class HeliAttitudeVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`heli_env.env.HeliAttitudeEnv`, batched in numpy.

    Same arguments, spaces, rewards, episode ends and info as the single
    environment (see its docstring), plus ``num_envs``. The state is held as an
    array of shape ``(N_STATE, num_envs)`` and stepped by the same generated
    physics core (:func:`identification.model.discrete_step`) as the single
    environment; every episode is drawn by the same function from a per-copy
    random generator seeded ``seed + i``, so copy ``i`` reproduces a single
    environment reset with ``seed + i`` under the same actions (the dynamics
    bit for bit, observations to float rounding of ``atan2``/``sin``).

    Autoreset is ``NEXT_STEP`` (Gymnasium's default): after a copy's episode
    ends, its next ``step`` resets it and returns the first observation of the
    new episode with reward 0. ``reset(options={"reset_mask": mask})`` resets
    only the copies where ``mask`` is True.

    Infos are dicts of arrays over copies (``time``, ``disturbance`` (n, 3),
    ``attitude_error_deg`` (n, 3), ``rate_error_deg_s`` (n, 3), ``trace``), each
    with its ``_name`` mask as Gymnasium's vector API prescribes.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP, "render_fps": 25}

    def __init__(self, num_envs: int = 1, model=None, task="hold", reference="mixed", dt: float = 0.01,
                 episode_seconds: float = 30.0, collective="trace", gust_scale: float = 1.0, obs_noise=0.0,
                 action_delay: int = 0, init_angle_deg: float = 5.0, init_rate_deg: float = 5.0,
                 library_version=None, render_mode: str | None = None):
        if int(num_envs) != num_envs or num_envs < 1:
            raise ValueError(f"num_envs must be a positive whole number, got {num_envs!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be 'rgb_array' or None for the vector env, got {render_mode!r}")
        self.spec_ = s = build_spec(model, task, reference, dt, episode_seconds, collective, gust_scale, obs_noise,
                                    action_delay, init_angle_deg, init_rate_deg, library_version)
        self.num_envs = n = int(num_envs)
        self.render_mode = render_mode
        self.single_observation_space = observation_space()
        self.single_action_space = action_space()
        self.observation_space = batch_space(self.single_observation_space, n)
        self.action_space = batch_space(self.single_action_space, n)
        # Library columns gathered once per step, one row per sample so that a gather reads
        # contiguous memory: trims (3), collective, gust torque (3), u_d (3).
        self._table = np.ascontiguousarray(np.vstack([s.trim, s.col[None, :], s.torque, s.model.ud]).T)
        self._x = None
        self._rngs = [None] * n
        self._k = np.zeros(n, dtype=np.int64)
        self._base = np.zeros(n, dtype=np.int64)
        self._last = np.zeros(n, dtype=np.int64)
        self._nsteps = np.zeros(n, dtype=np.int64)
        self._gust = np.zeros(n)
        self._trace = np.zeros(n, dtype=np.int64)
        self._prev = np.zeros((3, n))
        self._done = np.zeros(n, dtype=bool)
        self._queue = np.zeros((s.action_delay, 3, n)) if s.action_delay else None
        n_seg = int(s.episode_steps * s.dt // s.task.step_period) + 1
        self._smooth = np.zeros(n, dtype=bool)
        self._steps = np.zeros((3, n_seg, n))
        self._amp = np.zeros((3, N_SINES, n))
        self._freq = np.zeros((3, N_SINES, n))
        self._phase = np.zeros((3, N_SINES, n))
        self._ones = np.ones(n, dtype=bool)
        self._renderer = None
        self._history = []

    @property
    def model(self):
        """The :class:`heli_env.model_dir.EnvModel` driving the environments."""
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
            for i in range(n):
                if mask[i] or self._rngs[i] is None:
                    self._rngs[i] = seeding.np_random(seeds[i])[0]
        for i in range(n):
            if self._rngs[i] is None:
                self._rngs[i] = seeding.np_random(None)[0]
        if self._x is None:
            if not mask.all():
                raise ResetNeeded("the first reset must reset every copy (no reset_mask)")
            self._x = [np.zeros(n) for _ in range(N_STATE)]  # rows of the (N_STATE, n) state
        self._reset_envs(np.flatnonzero(mask), options)
        j = self._base + np.minimum(self._k, self._last) * s.ratio
        self._ud = np.take(self._table, j, axis=0).T[7:10] * self._gust  # the gust about to act
        obs, info = self._observe()
        return obs, info

    def _reset_envs(self, which, options):
        s = self.spec_
        gust_default = s.gust_scale if options.get("gust_scale") is None else float(options["gust_scale"])
        if options.get("gusts") is False:
            gust_default = 0.0
        if not (gust_default >= 0 and math.isfinite(gust_default)):
            raise ValueError(f"options['gust_scale'] must be a non-negative number, got {gust_default!r}")
        for i in which.tolist():
            ep = draw_episode(self._rngs[i], s.task, s.model.n_traces, s.model.lengths, s.needed, s.episode_steps,
                              s.dt, s.init_angle, s.init_rate, options)
            base = int(s.model.starts[ep.trace]) + ep.offset
            end = int(s.model.starts[ep.trace] + s.model.lengths[ep.trace])
            stop = min(end, base + s.needed)
            self._base[i] = base
            self._last[i] = len(range(base, stop, s.ratio)) - 1
            # as the single env: the time limit, or until the replay reaches the trace's last sample
            self._nsteps[i] = min(s.episode_steps, max(int(self._last[i]), 1))
            self._k[i] = 0
            self._trace[i] = ep.trace
            self._gust[i] = gust_default
            trim = s.trim[:, base]
            values = (ep.rates[0], ep.rates[1], ep.rates[2], trim[0], trim[1], trim[2],
                      *quaternion_from_euler(ep.angles[0], ep.angles[1], 0.0))
            for row, v in zip(self._x, values):
                row[i] = v
            self._prev[:, i] = 0.0
            if self._queue is not None:
                self._queue[:, :, i] = 0.0
            self._smooth[i] = ep.smooth
            self._steps[:, :, i] = ep.steps
            self._amp[:, :, i] = ep.amp
            self._freq[:, :, i] = ep.freq
            self._phase[:, :, i] = ep.phase
            self._done[i] = False

    # ------------------------------------------------------------------- step
    def step(self, actions):
        if self._x is None:
            raise ResetNeeded("call reset() before step()")
        s = self.spec_
        n = self.num_envs
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (n, 3):
            raise ActionError(f"actions must have shape ({n}, 3) (lat, lon, ped per copy), got {a.shape}")
        if not np.isfinite(a).all():
            bad = int(np.argmax(~np.isfinite(a).all(axis=1)))
            raise ActionError(f"actions must be finite; copy {bad} got {a[bad].tolist()}")
        a = np.clip(a.T, -1.0, 1.0)  # (3, n)
        restart = self._done.copy()
        if self._queue is not None:
            applied = self._queue[0].copy()
            self._queue[:-1] = self._queue[1:]
            self._queue[-1] = a
        else:
            applied = a
        idx = self._base + np.minimum(self._k, self._last) * s.ratio
        row = np.take(self._table, idx, axis=0).T  # (10, n)
        g = self._gust
        sticks = (np.clip(row[0] + applied[0], -1.0, 1.0), np.clip(row[1] + applied[1], -1.0, 1.0), row[3],
                  np.clip(row[2] + applied[2], -1.0, 1.0))
        self._x = list(s.dstep(self._x, sticks, (g * row[4], g * row[5], g * row[6])))
        self._ud = row[7:10] * g  # the gust of this step, reported in info
        self._k += 1
        self._prev = applied
        if restart.any():
            which = np.flatnonzero(restart)
            self._reset_envs(which, {})
            j = self._base[which]
            self._ud[:, which] = self._table[j, 7:10].T * self._gust[which]
        obs, info = self._observe()
        rew = reward_from_sums(s.task, *self._sums)
        phi, theta = self._att[0], self._att[1]
        lim = s.task.max_angle
        x = self._x
        terminated = ~((np.abs(phi) <= lim) & (np.abs(theta) <= lim)
                       & np.isfinite(x[0]) & np.isfinite(x[1]) & np.isfinite(x[2]))
        truncated = ~terminated & (self._k >= self._nsteps)
        if restart.any():
            rew = np.where(restart, 0.0, rew)
            terminated &= ~restart
            truncated &= ~restart
        self._done = terminated | truncated
        return obs, rew, terminated, truncated, info

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

    def _error_terms(self, ref_att, ref_rate, phi, theta, psi, p, q, r):
        """Attitude error as observed (reference - attitude, wrapped; -attitude for "hold"/"rate"), rate error."""
        if ref_att is None:  # atan2/asin give [-pi, pi]: wrapping would change nothing
            shown = (-phi, -theta, -psi)
        else:
            shown = (wrap(ref_att[0] - phi), wrap(ref_att[1] - theta), wrap(ref_att[2] - psi))
        e_rate = (-p, -q, -r) if ref_rate is None else (ref_rate[0] - p, ref_rate[1] - q, ref_rate[2] - r)
        return shown, e_rate

    def _observe(self):
        s = self.spec_
        x = self._x
        q0, q1, q2, q3 = x[6], x[7], x[8], x[9]
        phi = np.arctan2(2.0 * (q0 * q1 + q2 * q3), 1.0 - 2.0 * (q1 * q1 + q2 * q2))
        theta = np.arcsin(np.clip(2.0 * (q0 * q2 - q3 * q1), -1.0, 1.0))
        psi = np.arctan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))
        self._att = (phi, theta, psi)
        p, q, r = x[0], x[1], x[2]
        t = self._k * s.dt
        ref_att, ref_rate = self._reference(t)
        # Reward, termination and info score the true state; only the observation is measured.
        a = self._prev
        shown, e_rate = self._error_terms(ref_att, ref_rate, phi, theta, psi, p, q, r)
        rows = np.stack([*shown, p, q, r, *e_rate, a[0], a[1], a[2]])
        self._sums = (0.0 if s.task.task == "rate" else np.einsum("ij,ij->j", rows[0:3], rows[0:3]),
                      np.einsum("ij,ij->j", rows[6:9], rows[6:9]), np.einsum("ij,ij->j", rows[9:12], rows[9:12]))
        deg_att = rows[0:3] * _RAD2DEG
        deg_rate = rows[6:9] * _RAD2DEG
        if s.obs_noise[0] or s.obs_noise[1]:
            noise = np.stack([rng.normal(0.0, 1.0, 6) for rng in self._rngs], axis=1)
            na, nr = s.obs_noise
            mp, mq, mr = p + nr * noise[3], q + nr * noise[4], r + nr * noise[5]
            shown, e_rate = self._error_terms(ref_att, ref_rate, phi + na * noise[0], theta + na * noise[1],
                                              psi + na * noise[2], mp, mq, mr)
            rows = np.stack([*shown, mp, mq, mr, *e_rate, a[0], a[1], a[2]])
            rows[0:3] = wrap(rows[0:3])  # noise may cross +-pi
        np.clip(rows[3:9], -MAX_RATE, MAX_RATE, out=rows[3:9])
        obs = rows.T.astype(np.float32)
        ud = self._ud
        m = self._ones
        info = {"time": t, "_time": m, "disturbance": ud.T, "_disturbance": m,
                "attitude_error_deg": deg_att.T, "_attitude_error_deg": m,
                "rate_error_deg_s": deg_rate.T, "_rate_error_deg_s": m, "trace": self._trace.copy(), "_trace": m}
        if self.render_mode is not None:
            ra = (0.0, 0.0, 0.0) if ref_att is None else tuple(float(v[0]) for v in ref_att)
            rr = (0.0, 0.0, 0.0) if ref_rate is None else tuple(float(v[0]) for v in ref_rate)
            self._history.append((float(t[0]), (float(phi[0]), float(theta[0]), float(psi[0])), ra, rr,
                                  (float(p[0]), float(q[0]), float(r[0])), tuple(ud[:, 0].tolist()),
                                  tuple(a[:, 0].tolist())))
            self._history = self._history[-2000:]
        return obs, info

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
