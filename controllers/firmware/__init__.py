"""The attitude loops of the firmwares helicopter pilots fly, as controllers of this project.

* :mod:`.ardupilot` — ArduPilot's traditional-helicopter loop (angle P through the square-root controller,
  the rate PID with feed-forward, its filters, the leaky integrator, the output and cyclic limits) at
  ``SCHED_LOOP_RATE``;
* :mod:`.rotorflight` — Rotorflight's pid_mode 3 loop in angle mode (P, I with its error limit and decay,
  D on the gyro, F, B, the gyro filters) at its PID loop rate;
* :mod:`.loop` — what they share: gains over a batch of parameter sets, the command scale between the
  firmware's output and the model's sticks, SB3's ``predict``.

Both fly in the project's one batched closed loop (:func:`controllers.replay.fly`) with the physics
sub-stepped to their own rate (:class:`controllers.firmware.autopilot.FirmwareAutopilot`), and in the
environments and the evaluator at their own tick on the library held at that rate
(:mod:`controllers.firmware.loop_rate_env`).
"""

from .ardupilot import ArduPilotHeli, ArduPilotHeliParams
from .errors import FirmwareMappingError, FirmwareParamError
from .loop import FirmwareLoop
from .rotorflight import Rotorflight, RotorflightParams

__all__ = ["ArduPilotHeli", "ArduPilotHeliParams", "FirmwareLoop", "FirmwareMappingError", "FirmwareParamError",
           "Rotorflight", "RotorflightParams"]
