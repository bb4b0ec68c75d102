"""A firmware loop in the environment and the evaluator at its own rate: the library held at the loop's tick.

The environments step at a whole number of the disturbance library's sample periods (0.01 s), longer than a
firmware loop's tick (2.5 ms at ``SCHED_LOOP_RATE`` 400 Hz, 1 ms at Rotorflight's 1 kHz). Held at the
environment's period, a loop would read one gyro and attitude sample per 0.01 s and its output would be held
for as long: a 100 Hz loop, not the firmware's. Instead, :func:`held_library` gives the same model with every
library sample held over ``substeps = loop_rate·dt`` ticks (the gust torque, its ``u_d``, the collective and so
the trim: exactly what :func:`controllers.replay.fly` holds over a period while the physics is sub-stepped to
the tick), so :class:`heli_env.env.HeliAttitudeEnv` and :class:`heli_env.vector_env.HeliAttitudeVectorEnv` run
at ``dt = 1/loop_rate`` on it with their own physics core, unchanged, and the loop acts every tick through the
one policy interface (:class:`TickAgent`). :func:`evaluate_firmware` flies it through
:func:`controllers.evaluate.evaluate_agent` that way.

The environments' sensor noise is white per step. Drawn per tick with the identified standard deviation it
would carry ``substeps`` times less power below the library's Nyquist frequency than the identified noise
(which the replay holds over each period), so the held model's white noise is scaled by ``√substeps``: the
same density where the loop's filters pass it. The gyro's vibration lines are sinusoids and keep their
amplitude.

Windows and episodes count samples of the held library (``substeps`` per original sample); trace indices are
unchanged.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from heli_core.sensors import SensorModel

from .errors import FirmwareMappingError


def held_library(env_model, substeps: int):
    """``env_model`` with every library sample held over ``substeps`` samples (module docstring).

    Parameters
    ----------
    env_model : heli_env.env_model.EnvModel
    substeps : int
        Ticks per library sample period, >= 1 (:meth:`controllers.firmware.loop.FirmwareLoop.substeps`).

    Returns
    -------
    EnvModel
        Sample rate ``substeps`` times the library's; traces, gains and parameters as they were; the sensors'
        white noise scaled by ``√substeps``. ``substeps == 1`` returns ``env_model`` itself.
    """
    m = int(substeps)
    if m != substeps or m < 1:
        raise FirmwareMappingError(f"substeps must be a whole number >= 1, got {substeps!r}")
    if m == 1:
        return env_model
    sensors = env_model.sensors
    held = SensorModel(gyro_noise=tuple(v * math.sqrt(m) for v in sensors.gyro_noise),
                       attitude_noise=tuple(v * math.sqrt(m) for v in sensors.attitude_noise),
                       gyro_lines=sensors.gyro_lines)
    ud = np.repeat(env_model.ud, m, axis=1)
    collective = np.repeat(env_model.collective, m)
    for a in (ud, collective):
        a.setflags(write=False)
    return replace(env_model, document=env_model.document.with_sensors(held), ud=ud,
                   collective=collective, starts=np.asarray(env_model.starts) * m,
                   lengths=np.asarray(env_model.lengths) * m, sample_rate=float(env_model.sample_rate) * m)


class TickAgent:
    """A firmware loop as an agent whose control period is its tick: one tick per ``predict`` call.

    ``predict(observation, state=None, episode_start=None, deterministic=False)`` is the loop's own
    (:meth:`controllers.firmware.loop.FirmwareLoop.predict`) with ``control_dt`` its tick, for an environment
    running at ``dt = 1/loop_rate_hz`` (on :func:`held_library`'s model).

    Parameters
    ----------
    loop : FirmwareLoop
        One parameter set (:class:`~controllers.firmware.ardupilot.ArduPilotHeli` or
        :class:`~controllers.firmware.rotorflight.Rotorflight`).
    """

    def __init__(self, loop):
        self.loop = loop
        self.dt = loop.dt

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = False):
        return self.loop.predict(observation, state, episode_start, deterministic, control_dt=self.dt)

    def describe(self) -> tuple[str, str]:
        """(kind, description) for reports (:func:`controllers.evaluate.describe_agent`): the firmware and its
        loop rate."""
        return self.loop.firmware, f"{self.loop.firmware} attitude loop at {self.loop.loop_rate_hz:g} Hz"


def evaluate_firmware(loop, model=None, config=None, *, name: str | None = None, **settings):
    """Fly a firmware loop through the one evaluator at its own rate (module docstring).

    Parameters
    ----------
    loop : FirmwareLoop
        One parameter set; its ``loop_rate_hz`` must be a whole multiple of the library's sample rate.
    model : str, Path, EnvModel or None
        As :func:`controllers.evaluate.evaluate_agent` (None: the shipped model).
    config : EvaluationConfig, optional
    name : str, optional
        Label in reports (default: the firmware and its rate).
    **settings
        :class:`~controllers.evaluate.EvaluationConfig` fields (``episode_seconds``, ``traces`` ...); ``dt`` is
        the loop's tick and cannot be given.

    Returns
    -------
    EvaluationResult
        Sampled every tick (``settings["dt"]`` is the tick, ``settings["sample_rate"]`` the held library's).
    """
    from heli_env.env_model import as_env_model

    from ..evaluate import evaluate_agent

    if "dt" in settings or (config is not None and config.dt is not None):
        raise FirmwareMappingError(f"a firmware loop is evaluated at its own tick ({loop.dt:g} s); dt cannot be given")
    env_model = as_env_model(model)
    m = loop.substeps(1.0 / env_model.sample_rate)
    held = held_library(env_model, m)
    label = name or f"{loop.firmware} loop at {loop.loop_rate_hz:g} Hz"
    return evaluate_agent(TickAgent(loop), held, config, name=label, dt=loop.dt, **settings)
