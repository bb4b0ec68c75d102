"""The single attitude-control environment, ``HeliAttitude-v0``."""

from __future__ import annotations

import math
from collections import deque

import gymnasium as gym
import numpy as np
from gymnasium.error import ResetNeeded

from heli_core.deprecation import module_getattr
from heli_core.quaternion import euler_from_quaternion_scalar, quaternion_from_euler

from .env_model import as_env_model
from .errors import ActionError
from .observation import MAX_RATE, action_space, observation_space
from .spec import build_spec, real_actions, reset_options
from .sensor_noise import draw_noise_key, noise_block
from .tasks import TWO_PI, draw_episode, line_phases, reward_of, wrap

_DEGREES = 180.0 / math.pi

NOISE_STEPS = 256
"""Steps of sensor noise the single env computes at once (:func:`heli_env.sensor_noise.noise_block`): one
compiled call per 256 steps instead of one per step. The values depend only on the episode's key and the step."""


class HeliAttitudeEnv(gym.Env):
    """Attitude control of an identified RC helicopter in replayed gusts.

    ## Description

    The dynamics are an attitude model identified from flight logs by
    ``heli identify`` (paper eqs. 18 and 21, decoupled or coupled, with the
    servo delay of eq. 31 when identified), stepped by the package's one
    physics core. The wind is *replayed*: on every reset a disturbance trace
    of the model's library (the equivalent cyclic inputs u_d that the real
    aircraft met, eqs. 41-47; from a maximum-likelihood model, as the shipped
    one, a draw from the wind smoother's posterior, which has the identified
    wind's full power) and a start offset are drawn, and its torque
    ``k*u_d`` is applied sample by sample. With no ``model`` argument the
    environment uses the model shipped with the package, which heli-env
    identified itself from synthetic flights of its truth model
    (``scripts/build_default_model.py``; its report is ``heli_env/data/default/report.md``).

    The control period is ``dt``: by default 0.01 s, or where that is not a whole number of the model's
    gust-trace sample periods, the shortest whole number of them above it (0.02 s for a 50 Hz log's model,
    0.012 s for a 250 Hz one; :func:`heli_core.control_period.default_dt`); ``env.unwrapped.spec_.dt`` says which. Each period is integrated
    exactly for the model's linear part under a zero-order hold of the action
    (:func:`heli_core.discrete.discrete_step`); products of rates are held
    over the period and the attitude turns by the mean rate. Largest error
    against RK4 with 20 sub-steps (:func:`heli_core.physics.step`) over 30 s
    of random sticks (σ 0.4) in replayed gusts, worst of four episodes
    (``tests/test_env.py`` checks the first three rows):

    | model | rate error | attitude error |
    |---|---|---|
    | decoupled (eqs. 18, 21; the shipped model) | < 1e-13 rad/s (rounding) | < 0.002° |
    | with the coupling terms k1, k4, k5, k8, k9 | < 5e-4 rad/s | < 0.005° |
    | with servo delay (eq. 31) | < 1e-9 rad/s | < 0.015° |
    | with nonlinear damping (p·abs(p) terms) | < 2e-3 rad/s | < 0.05° |
    | every catalogue term and the servo delay at once | < 0.05 rad/s | < 0.2° |

    Held products are first order in ``dt`` (the last row is dominated by the
    collective-scheduled gain acting on the delayed servo state), and ``dt`` is a
    whole number of the traces' sample periods.

    ## Action Space

    ``Box(-1, 1, (3,), float32)``: offsets from trim of the sticks, in stick units.

    | index | stick | drives | unit |
    |---|---|---|---|
    | 0 | lat (lateral cyclic) | roll | stick, [-1, 1] |
    | 1 | lon (longitudinal cyclic) | pitch | stick, [-1, 1] |
    | 2 | ped (pedal) | yaw | stick, [-1, 1] |

    The applied stick is ``clip(trim + action, -1, 1)``, where the trim holds
    the aircraft at rest for the current collective (it cancels the offsets
    kd and the collective torque). Actions outside [-1, 1] are clipped; NaN or
    inf raise :class:`heli_env.errors.ActionError`.

    ## Observation Space

    ``Box(float32, (12,))``:

    | index | observation | unit | bound |
    |---|---|---|---|
    | 0-2 | attitude error: reference − (roll, pitch, yaw), wrapped | rad | ±π |
    | 3-5 | body rates p, q, r | rad/s | ±35 (clipped) |
    | 6-8 | rate error: reference rate − (p, q, r) | rad/s | ±35 (clipped) |
    | 9-11 | previous action (lat, lon, ped) | stick | ±1 |

    The attitude and rates are measured through the model's identified sensors
    (``model.json["sensors"]``: white noise on the attitude estimate and the gyros, the gyros'
    vibration lines at a random phase per episode), or through ``obs_noise``; the reward, termination
    and ``info`` use the true state. The phases and a 64-bit noise key are drawn from ``np_random`` at
    reset; the white noise of each step is a function of the key and the step
    (:mod:`heli_env.sensor_noise`), so the vector env computes the same noise in its compiled loop.

    ## Rewards

    Per step ``-(w_a·Σ(e_att/10°)² + w_r·Σ(e_rate/30°/s)² + w_u·Σ a²)``, weights
    (1, 0.1, 0.01) for "hold" and "track", (0, 1, 0.01) for "rate"
    (:class:`heli_env.tasks.TaskConfig`). Holding 10° off on one axis costs 1 per step. With a
    ``TaskConfig(stick_step_weight=w_s)`` the reward also charges ``w_s·Σ(a − a_prev)²``, the change of the
    applied action from the step before (from rest at an episode's start): the chatter a servo feels.

    ## Starting State

    Roll and pitch uniform in ±``init_angle_deg`` (5°), heading 0, body rates
    uniform in ±``init_rate_deg`` (5°/s), servos settled on the trim sticks.

    ## Episode End

    * Termination: |roll| or |pitch| beyond 60° (``TaskConfig.max_angle``), or a non-finite state.
    * Truncation: ``episode_seconds`` elapsed (default 30 s), or the replay reached the
      last sample of its disturbance trace. Stepping on after that raises
      :class:`gymnasium.error.ResetNeeded` (there is no gust left to replay).

    ## Arguments

    ```python
    gymnasium.make("HeliAttitude-v0", model=None, task="hold", reference="mixed", dt=None,
                   episode_seconds=30.0, collective="trace", gust_scale=1.0, obs_noise="model",
                   action_delay=0, init_angle_deg=5.0, init_rate_deg=5.0, library_version=None,
                   render_mode=None)
    ```

    * ``model``: a model directory written by ``heli identify`` (``model.json`` +
      ``disturbances/``), or None for the shipped model.
    * ``task``: "hold" (level, initial heading), "track" (reference attitude), "rate"
      (reference body rates), or a :class:`heli_env.tasks.TaskConfig`.
    * ``reference``: "steps", "smooth" or "mixed" references for "track"/"rate".
    * ``collective``: "trace" follows the collective recorded with the gust (the yaw
      model needs it, eq. 21); a number holds it constant.
    * ``gust_scale``: multiplies the replayed gust; 0 switches gusts off.
    * ``obs_noise``: "model" (the model's identified sensors; none for a model without them), a
      standard deviation, (attitude rad, rate rad/s) white-noise stds, or a
      :class:`heli_core.sensors.SensorModel`.
    * ``action_delay``: whole control periods between an action and its effect.

    ``reset(options=...)`` accepts ``trace`` (library index) and ``offset``
    (sample) to pin the gust, ``gust_scale`` to scale it, ``gusts=False`` to switch
    it off, for that episode.

    ## Info

    ``time`` [s], ``disturbance`` (the replayed u_d, scaled, stick units),
    ``attitude_error_deg``, ``rate_error_deg_s``, ``trace`` (library index) and
    ``trace_id``.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 25}

    def __init__(self, model=None, task="hold", reference="mixed", dt: float | None = None, episode_seconds: float = 30.0,
                 collective="trace", gust_scale: float = 1.0, obs_noise="model", action_delay: int = 0,
                 init_angle_deg: float = 5.0, init_rate_deg: float = 5.0, library_version=None,
                 render_mode: str | None = None):
        self.spec_ = build_spec(as_env_model(model, library_version), task, reference, dt, episode_seconds,
                                collective, gust_scale, obs_noise, action_delay, init_angle_deg, init_rate_deg)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.observation_space = observation_space()
        self.action_space = action_space()
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.spec_.dt)) if self.spec_.dt >= 0.04 else 25}
        self._x = None
        self._lines = None
        self._renderer = None

    # ----------------------------------------------------------------- API
    @property
    def model(self):
        """The :class:`heli_env.env_model.EnvModel` driving the environment."""
        return self.spec_.model

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        s = self.spec_
        options, gust = reset_options(options, s.gust_scale)
        ep = draw_episode(self.np_random, s, options)
        self._episode = ep
        self._lines = None
        if s.line_axis:  # the gyros' vibration lines over the whole episode, each at its episode's phase
            phase = line_phases(self.np_random, len(s.line_axis))
            table = np.zeros((3, s.line_sin.shape[1]))
            for i, (axis, amp) in enumerate(zip(s.line_axis, s.line_amp)):  # the vector env's order and operations
                table[axis] += amp * (s.line_sin[i] * phase[i][0] + s.line_cos[i] * phase[i][1])
            self._lines = table.T.tolist()
        if s.measured:  # the episode's sensor noise: a pure function of this key and the step (drawn last)
            self._noise_key = draw_noise_key(self.np_random)
            self._noise_first = None
        self._gust = gust
        self._base = int(s.model.starts[ep.trace]) + ep.offset
        self._end = int(s.model.starts[ep.trace] + s.model.lengths[ep.trace])  # exclusive
        self._k = 0
        # The episode's window of the library as Python floats: per-step arithmetic on
        # numpy scalars costs several times more than on floats.
        stop = min(self._end, self._base + s.needed)
        window = slice(self._base, stop, s.ratio)
        g = self._gust
        self._seq = (s.trim[0, window].tolist(), s.trim[1, window].tolist(), s.trim[2, window].tolist(),
                     s.col[window].tolist(), (g * s.torque[0, window]).tolist(), (g * s.torque[1, window]).tolist(),
                     (g * s.torque[2, window]).tolist(), (g * s.model.ud[0, window]).tolist(),
                     (g * s.model.ud[1, window]).tolist(), (g * s.model.ud[2, window]).tolist())
        # Steps the episode can take: the time limit, or until the replay reaches the trace's last sample
        # (a trace of n samples spans n - 1 periods; at least one step).
        self._steps = min(s.episode_steps, max(len(self._seq[0]) - 1, 1))
        trim = s.trim[:, self._base]
        quat = quaternion_from_euler(ep.angles[0], ep.angles[1], 0.0)
        self._x = (float(ep.rates[0]), float(ep.rates[1]), float(ep.rates[2]),
                   float(trim[0]), float(trim[1]), float(trim[2]), *(float(v) for v in quat))
        self._prev = (0.0, 0.0, 0.0)
        self._queue = deque([(0.0, 0.0, 0.0)] * s.action_delay) if s.action_delay else None
        self._history = [] if self.render_mode else None
        obs, info = self._observe()
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action):
        if self._x is None:
            raise ResetNeeded("call reset() before step()")
        if self._k >= self._steps:
            raise ResetNeeded(f"the episode is over: t = {self._k * self.spec_.dt:g} s reached the time limit or the "
                              "end of the disturbance trace; call reset() before step()")
        s = self.spec_
        if isinstance(action, np.ndarray) and action.shape == (3,) and action.dtype.kind == "f":
            a0, a1, a2 = action.tolist()
        else:
            a = real_actions(action, "action")
            if a.shape != (3,):
                raise ActionError(f"action must have shape (3,) (lat, lon, ped), got {a.shape}")
            a0, a1, a2 = a.tolist()
        if not (math.isfinite(a0) and math.isfinite(a1) and math.isfinite(a2)):
            raise ActionError(f"action must be finite, got {[a0, a1, a2]}")
        # min(1.0, max(-1.0, v)) written out (the builtins cost a call each, a third of a step's Python)
        a0 = (a0 if a0 < 1.0 else 1.0) if a0 > -1.0 else -1.0
        a1 = (a1 if a1 < 1.0 else 1.0) if a1 > -1.0 else -1.0
        a2 = (a2 if a2 < 1.0 else 1.0) if a2 > -1.0 else -1.0
        if self._queue is not None:
            self._queue.append((a0, a1, a2))
            a0, a1, a2 = self._queue.popleft()
        k = self._k
        seq = self._seq
        lat, lon, ped = seq[0][k] + a0, seq[1][k] + a1, seq[2][k] + a2
        sticks = ((lat if lat < 1.0 else 1.0) if lat > -1.0 else -1.0,
                  (lon if lon < 1.0 else 1.0) if lon > -1.0 else -1.0, seq[3][k],
                  (ped if ped < 1.0 else 1.0) if ped > -1.0 else -1.0)
        self._x = s.dstep(self._x, sticks, (seq[4][k], seq[5][k], seq[6][k]))
        self._k = k + 1
        before = self._prev
        self._prev = (a0, a1, a2)
        obs, info = self._observe()
        e_att, e_rate = self._errors
        a = self._prev
        r = reward_of(s.task, e_att, e_rate, a, before)
        x = self._x
        terminated = not (abs(self._att[0]) <= s.task.max_angle and abs(self._att[1]) <= s.task.max_angle
                          and math.isfinite(x[0]) and math.isfinite(x[1]) and math.isfinite(x[2]))
        truncated = (not terminated) and self._k >= self._steps
        if self.render_mode == "human":
            self.render()
        return obs, r, terminated, truncated, info

    # ------------------------------------------------------------ internals
    def _reference(self, t):
        ep, cfg = self._episode, self.spec_.task
        if cfg.task == "hold":
            return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        if ep.smooth:
            arg = ep.freq * t + ep.phase
            val = (ep.amp * np.sin(arg)).sum(axis=1)
            der = (ep.amp * ep.freq * np.cos(arg)).sum(axis=1)
        else:
            seg = min(int(t // cfg.step_period), ep.steps.shape[1] - 1)
            val, der = ep.steps[:, seg], np.zeros(3)
        if cfg.task == "rate":
            return (0.0, 0.0, 0.0), tuple(val.tolist())
        return tuple(val.tolist()), tuple(der.tolist())

    def _observe(self):
        s = self.spec_
        x = self._x
        self._att = phi, theta, psi = euler_from_quaternion_scalar(x[6], x[7], x[8], x[9])
        p, q, r = x[0], x[1], x[2]
        t = self._k * s.dt
        ref_att, ref_rate = self._reference(t)
        # Reward, termination and info score the true state; only the observation is measured.
        shown, e_rate = self._error_terms(ref_att, ref_rate, phi, theta, psi, p, q, r)
        self._errors = ((0.0, 0.0, 0.0) if s.task.task == "rate" else shown, e_rate)
        m_shown, m_rate, mp, mq, mr = shown, e_rate, p, q, r
        if s.measured:
            k = self._k
            if self._noise_first is None or not 0 <= k - self._noise_first < NOISE_STEPS:
                self._noise = noise_block(self._noise_key, k, NOISE_STEPS).tolist()
                self._noise_first = k
            n = self._noise[k - self._noise_first]
            na, nr = s.obs_noise
            mp, mq, mr = p + nr[0] * n[3], q + nr[1] * n[4], r + nr[2] * n[5]
            if self._lines is not None:
                lines = self._lines[self._k]
                mp, mq, mr = mp + lines[0], mq + lines[1], mr + lines[2]
            m_shown, m_rate = self._error_terms(ref_att, ref_rate, phi + na[0] * n[0], theta + na[1] * n[1],
                                                psi + na[2] * n[2], mp, mq, mr)
            m0, m1, m2 = m_shown  # noise may cross +-pi: wrapped (tasks.wrap on floats, written out)
            m_shown = (m0 - TWO_PI * round(m0 / TWO_PI), m1 - TWO_PI * round(m1 / TWO_PI),
                       m2 - TWO_PI * round(m2 / TWO_PI))
        a = self._prev
        lim, low = MAX_RATE, -MAX_RATE  # min(lim, max(-lim, v)) written out
        r0, r1, r2 = m_rate
        obs = np.array([m_shown[0], m_shown[1], m_shown[2], (mp if mp < lim else lim) if mp > low else low,
                        (mq if mq < lim else lim) if mq > low else low, (mr if mr < lim else lim) if mr > low else low,
                        (r0 if r0 < lim else lim) if r0 > low else low, (r1 if r1 < lim else lim) if r1 > low else low,
                        (r2 if r2 < lim else lim) if r2 > low else low, a[0], a[1], a[2]], dtype=np.float32)
        j = self._k - 1 if self._k else 0  # the gust of the step just taken (at reset: the one about to act)
        seq = self._seq
        deg = _DEGREES  # math.degrees(v) is v * (180 / pi), one multiplication
        buf = np.array([seq[7][j], seq[8][j], seq[9][j], shown[0] * deg, shown[1] * deg, shown[2] * deg,
                        e_rate[0] * deg, e_rate[1] * deg, e_rate[2] * deg])
        info = {"time": t, "disturbance": buf[0:3], "attitude_error_deg": buf[3:6], "rate_error_deg_s": buf[6:9],
                "trace": self._episode.trace, "trace_id": s.model.trace_ids[self._episode.trace]}
        if self._history is not None:
            self._history.append((t, self._att, ref_att, ref_rate, (p, q, r), tuple(buf[0:3].tolist()), self._prev))
        return obs, info

    def _error_terms(self, ref_att, ref_rate, phi, theta, psi, p, q, r):
        """Attitude error as observed (reference - attitude, wrapped; -attitude for "hold"/"rate") and rate error."""
        if self.spec_.task.task == "track":
            shown = (wrap(ref_att[0] - phi), wrap(ref_att[1] - theta), wrap(ref_att[2] - psi))
        else:  # atan2/asin give [-pi, pi]: wrapping would change nothing
            shown = (-phi, -theta, -psi)
        return shown, (ref_rate[0] - p, ref_rate[1] - q, ref_rate[2] - r)

    # ---------------------------------------------------------------- render
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        if self._x is None:
            raise ResetNeeded("call reset() before render()")
        from .render import Renderer

        if self._renderer is None:
            self._renderer = Renderer(self.render_mode, self.spec_.task.task)
        return self._renderer.draw(self._history)

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


__getattr__ = module_getattr(__name__)
"""OBS_DIM (:mod:`heli_env.observation`), once importable from here (deprecated: :mod:`heli_env._deprecated`)."""
