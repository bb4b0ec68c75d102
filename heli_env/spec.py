"""Settings and precomputed arrays shared by the single and the vector environment.

:func:`build_spec` checks the constructor arguments once and precomputes what
every step needs: the model's discrete-time step (:func:`heli_core.discrete.discrete_step`
generated for the control period), the gust torque ``k*u_d`` of every library
sample (:attr:`heli_env.env_model.EnvModel.torque`), and the trim sticks for
every recorded collective.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from heli_core.config import is_real
from heli_core.control_period import default_dt
from heli_core.deprecation import module_getattr
from heli_core.discrete import discrete_kernel
from heli_core.physics import trim_sticks
from heli_core.sensors import SensorModel

from .errors import ActionError, OptionError
from .tasks import TaskConfig


@dataclass(frozen=True, eq=False)
class EnvSpec:
    """Everything an environment instance needs, validated and precomputed."""

    model: EnvModel
    task: TaskConfig
    dt: float
    ratio: int  # trace samples per control period
    episode_steps: int
    needed: int  # trace samples a full episode uses
    collective: object  # "trace" or a float
    gust_scale: float
    sensors: SensorModel  # what the observation measures through (noise and gyro lines)
    line_sin: np.ndarray  # (n_lines, episode_steps + 1) sin(w t) of each gyro line at every step
    line_cos: np.ndarray  # (n_lines, episode_steps + 1) cos(w t)
    action_delay: int
    init_angle: float
    init_rate: float
    dstep: object
    torque: np.ndarray  # (3, total) k * u_d, each trace with the gains it was identified with
    trim: np.ndarray  # (3, total) trim lat, lon, ped at each recorded collective
    col: np.ndarray  # (total,) collective applied at each library sample


    @cached_property
    def measured(self) -> bool:
        """The observation carries sensor noise or lines (the reward and the info never do)."""
        return not self.sensors.silent

    @property
    def obs_noise(self) -> tuple:
        """(attitude [rad], rate [rad/s]) white-noise standard deviations, each per axis."""
        return self.sensors.attitude_noise, self.sensors.gyro_noise

    @cached_property
    def line_axis(self) -> tuple:
        """Axis index of each gyro line (computed once: the vector env reads it every step)."""
        return tuple(int(a) for a in self.sensors.line_arrays()[0])

    @cached_property
    def line_amp(self) -> tuple:
        """Amplitude of each gyro line [rad/s]."""
        return tuple(float(a) for a in self.sensors.line_arrays()[2])


MAX_GUST_SCALE = 100.0
"""Largest gust multiplier accepted: beyond it the replayed gust is no longer the aircraft's weather
(and at 1e300 the reward overflows)."""

MAX_INIT_ANGLE_DEG = 90.0
"""Largest initial roll/pitch magnitude drawn at reset [deg]."""

MAX_INIT_RATE_DEG = 1000.0
"""Largest initial body-rate magnitude drawn at reset [deg/s]."""


def _index(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def checked_gust_scale(value, name: str) -> float:
    """``value`` as a gust multiplier in [0, :data:`MAX_GUST_SCALE`], else :class:`OptionError`."""
    if not (is_real(value) and 0 <= value <= MAX_GUST_SCALE):
        raise OptionError(f"{name} must be a number in [0, {MAX_GUST_SCALE:g}], got {value!r}")
    return float(value)


def real_actions(actions, name: str) -> np.ndarray:
    """``actions`` as a float64 array, or :class:`~heli_env.errors.ActionError` when they are not real
    numbers (strings, None, complex values: the imaginary part is never dropped silently)."""
    a = np.asarray(actions) if not isinstance(actions, np.ndarray) else actions
    if a.dtype.kind not in "iuf":
        if a.dtype.kind == "O":
            try:
                a = a.astype(np.float64)
            except (TypeError, ValueError) as e:
                raise ActionError(f"{name} must be real numbers, got {actions!r}") from e
        else:
            raise ActionError(f"{name} must be real numbers, got dtype {a.dtype} ({actions!r})")
    return np.asarray(a, dtype=np.float64)


RESET_OPTIONS = ("trace", "offset", "gust_scale", "gusts")
"""Options ``reset`` reads (the vector env adds ``reset_mask``)."""


def reset_options(options, default_gust: float, extra=()) -> tuple[dict, float]:
    """Check ``reset``'s options once for both environments: ``(options, gust multiplier)``.

    ``trace`` and ``offset`` must be whole numbers (an index, not 0.9), ``gusts`` a bool, ``gust_scale`` a
    number in [0, :data:`MAX_GUST_SCALE`]; an unknown key is refused. Raises :class:`OptionError`.
    """
    if options is None:
        options = {}
    if not isinstance(options, dict):
        raise OptionError(f"options must be a dict, got {type(options).__name__}")
    unknown = [k for k in options if k not in RESET_OPTIONS + tuple(extra)]
    if unknown:
        raise OptionError(f"unknown reset option(s) {unknown}; known: {', '.join(RESET_OPTIONS + tuple(extra))}")
    for key in ("trace", "offset"):
        if options.get(key) is not None and not _index(options[key]):
            raise OptionError(f"options[{key!r}] must be a whole number (an index), got {options[key]!r}")
    gusts = options.get("gusts", True)
    if not isinstance(gusts, (bool, np.bool_)):
        raise OptionError(f"options['gusts'] must be True or False, got {gusts!r}")
    gust = default_gust if options.get("gust_scale") is None else checked_gust_scale(options["gust_scale"],
                                                                                     "options['gust_scale']")
    return dict(options), (gust if gusts else 0.0)


def measurement_model(obs_noise, model: EnvModel) -> SensorModel:
    """The sensors an environment measures through: ``"model"`` the model's identified ones
    (``model.json["sensors"]``, silent when it has none), a :class:`~heli_core.sensors.SensorModel`, a
    standard deviation for attitude [rad] and rates [rad/s] alike, or a pair (attitude, rate), white only."""
    if isinstance(obs_noise, str):
        if obs_noise != "model":
            raise ValueError(f"obs_noise must be 'model', a std, (attitude rad, rate rad/s) stds or a SensorModel, "
                             f"got {obs_noise!r}")
        return model.sensors
    if isinstance(obs_noise, SensorModel):
        return obs_noise
    noise = (obs_noise, obs_noise) if np.ndim(obs_noise) == 0 else tuple(obs_noise)
    try:
        noise = tuple(float(v) for v in noise)
    except (TypeError, ValueError):
        noise = ()
    if len(noise) != 2 or any(not (v >= 0 and math.isfinite(v)) for v in noise):
        raise ValueError(f"obs_noise must be 'model', a std or (attitude rad, rate rad/s) stds >= 0, got {obs_noise!r}")
    return SensorModel(gyro_noise=(noise[1],) * 3, attitude_noise=(noise[0],) * 3)


def build_spec(env_model: EnvModel, task="hold", reference="mixed", dt: float | None = None,
               episode_seconds: float = 30.0, collective="trace", gust_scale: float = 1.0, obs_noise="model",
               action_delay: int = 0, init_angle_deg: float = 5.0, init_rate_deg: float = 5.0) -> EnvSpec:
    """Validate the environment arguments (see :class:`heli_env.env.HeliAttitudeEnv`) and precompute.

    ``env_model`` is the loaded model (:class:`heli_env.env_model.EnvModel`): the environments load it
    (:func:`heli_env.env_model.as_env_model`), so that the spec is a function of a model, not of a folder.
    """
    cfg = task if isinstance(task, TaskConfig) else TaskConfig(task=task, reference=reference)
    if dt is None:
        dt = default_dt(env_model.sample_rate)
    if not (isinstance(dt, (int, float)) and dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a positive control period in seconds, got {dt!r}")
    ratio_f = dt * env_model.sample_rate
    ratio = int(round(ratio_f))
    if ratio < 1 or abs(ratio_f - ratio) > 1e-6:
        raise ValueError(
            f"dt={dt} s must be a whole number of the disturbance traces' sample periods "
            f"({1.0 / env_model.sample_rate:g} s); got {ratio_f:g} periods (left unset, dt is "
            f"{default_dt(env_model.sample_rate):g} s)"
        )
    if not (episode_seconds > 0 and math.isfinite(episode_seconds)):
        raise ValueError(f"episode_seconds must be positive, got {episode_seconds!r}")
    episode_steps = int(round(episode_seconds / dt))
    gust_scale = checked_gust_scale(gust_scale, "gust_scale")
    for name, value, high in (("init_angle_deg", init_angle_deg, MAX_INIT_ANGLE_DEG),
                              ("init_rate_deg", init_rate_deg, MAX_INIT_RATE_DEG)):
        if not (is_real(value) and 0 <= value <= high):
            raise OptionError(f"{name} must be a number in [0, {high:g}], got {value!r}")
    sensors = measurement_model(obs_noise, env_model)
    omega = sensors.line_arrays()[1]
    phase = omega[:, None] * (np.arange(episode_steps + 1) * float(dt))[None, :]
    line_sin, line_cos = np.sin(phase), np.cos(phase)  # one table both environments read: identical values
    if int(action_delay) != action_delay or action_delay < 0:
        raise ValueError(f"action_delay must be a whole number of steps >= 0, got {action_delay!r}")
    params = env_model.params
    if collective == "trace":
        col = np.asarray(env_model.collective, dtype=float)
    else:
        c = float(collective)
        if not -1.0 <= c <= 1.0:
            raise ValueError(f"collective must be 'trace' or a stick value in [-1, 1], got {collective!r}")
        col = np.full(env_model.collective.shape, c)
    trim = np.array(trim_sticks(params, col))
    if not np.all(np.isfinite(trim)):
        raise ValueError("the model has a zero control gain on some axis; it cannot be trimmed")
    torque = env_model.torque  # read-only already (EnvModel caches it)
    for a in (trim, col, line_sin, line_cos):
        a.setflags(write=False)
    return EnvSpec(
        model=env_model, task=cfg, dt=float(dt), ratio=ratio, episode_steps=episode_steps,
        needed=episode_steps * ratio + 1, collective=collective if collective == "trace" else float(collective),
        gust_scale=float(gust_scale), sensors=sensors, line_sin=line_sin, line_cos=line_cos,
        action_delay=int(action_delay),
        init_angle=math.radians(init_angle_deg), init_rate=math.radians(init_rate_deg),
        dstep=discrete_kernel(params, float(dt))[0], torque=torque, trim=trim, col=col,
    )


__getattr__ = module_getattr(__name__)
