"""A firmware loop as the autopilot of the project's batched closed loop, the physics sub-stepped to its rate.

:func:`controllers.replay.fly` flies a :class:`FirmwareAutopilot` through
:func:`controllers.replay._fly_substeps`: every control period of the replayed gusts (the library's sample
period, 0.01 s) holds ``substeps = loop_rate_hz·dt`` ticks; at each tick the loop reads the attitude and the
gyro of that instant (plus the period's sensor errors) and the physics core's exact discrete step advances
one tick (:func:`fly_firmware` builds it: :func:`controllers.replay.zoh_step` at ``dt/substeps``).

Each of the autopilot's ``G`` parameter sets flies all three axes (one set is one tune of the aircraft);
the records keep every axis' attitude error (``LoopRecord.axes``) and, for the statistics a sweep reads, the
``axis`` one's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..replay import LoopInputs, fly, zoh_step
from .errors import FirmwareMappingError


@dataclass(frozen=True, eq=False)
class FirmwareAutopilot:
    """``G`` parameter sets of one firmware, each flying the three axes, at the loop's own rate.

    Attributes
    ----------
    loop_class : type
        :class:`~controllers.firmware.ardupilot.ArduPilotHeli` or
        :class:`~controllers.firmware.rotorflight.Rotorflight`.
    sets : tuple
        The parameter sets (one per flown tune).
    scale : 3 floats
        Command scale [model stick per firmware unit].
    signs : 3 floats
        Signs of the model's control gains.
    control_dt : float
        The period the gusts are held over [s].
    axis : int
        The axis whose records :class:`controllers.replay.LoopRecord` keeps as the swept one.
    """

    loop_class: type
    sets: tuple
    scale: tuple
    signs: tuple
    control_dt: float
    axis: int = 0
    _loops: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "sets", tuple(self.sets))
        if not self.sets:
            raise FirmwareMappingError("the autopilot needs at least one parameter set, got none")
        loop = self.loop(slice(0, len(self.sets)))
        object.__setattr__(self, "substeps", loop.substeps(self.control_dt))

    @property
    def pairs(self) -> int:
        """Number of parameter sets flown (the name :func:`controllers.replay.fly` reads)."""
        return len(self.sets)

    def loop(self, sl: slice):
        """The loop of the sets in ``sl`` (built once per slice)."""
        key = (sl.start, sl.stop)
        if key not in self._loops:
            self._loops[key] = self.loop_class(list(self.sets[sl]), self.scale, self.signs)
        return self._loops[key]

    def start(self, sl: slice, windows: int) -> np.ndarray:
        """Memory of the sets in ``sl`` at rest, for ``windows`` gust windows: (rows, 3, g, W)."""
        return self.loop(sl).initial_memory((sl.stop - sl.start, windows))

    def command(self, memory, att_error, rates, sl: slice):
        """One tick: stick offsets (3, g, W) before the clip, the new memory, where the loop clamped."""
        loop = self.loop(sl)
        out, memory, sat = loop.tick(memory, att_error, rates)
        return loop.sticks(out), memory, sat


def fly_firmware(params, inputs: LoopInputs, autopilot: FirmwareAutopilot, max_batch: int = 4096,
                 progress=True, desc: str | None = None):
    """Fly ``autopilot`` against ``inputs`` in :func:`controllers.replay.fly`, the physics at the loop's tick.

    Parameters
    ----------
    params : ModelParams
        The aircraft flown.
    inputs : LoopInputs
        Trim, collective, gust torque (and sensor errors) per control period.
    autopilot : FirmwareAutopilot
    max_batch, progress, desc
        As :func:`controllers.replay.fly`.

    Yields
    ------
    slice, LoopRecord
        As :func:`controllers.replay.fly`, with ``LoopRecord.axes`` filled.
    """
    step = zoh_step(params, autopilot.control_dt / autopilot.substeps)
    yield from fly(step, inputs, autopilot, max_batch, progress, desc or f"{autopilot.loop_class.firmware} loop")
