"""Which ArduPilot vehicle a DataFlash log comes from, read from its text messages and parameters.

Both ArduPilot readers name the vehicle: the binary one (:mod:`identification.io.ardupilot`) to warn about a log
that is not a rotorcraft's and to read its servos, the text one (:mod:`identification.io.dataflash_text`) to
describe the log it refuses. The rule is one and lives here, so that neither reader imports the other.
"""

from __future__ import annotations


def vehicle_of(texts: list, params: dict) -> tuple[str, str, bool]:
    """(firmware string, vehicle, whether a helicopter) from the log's texts and parameters."""
    firmware = next((t for t in texts if "Copter" in t or "Plane" in t or "Rover" in t), "ArduPilot")
    heli = ("heli" in firmware.lower() or any(k.startswith(("H_SW", "H_SV", "H_COL")) for k in params)
            or params.get("FRAME_CLASS") == 6)
    vehicle = ("helicopter" if heli else "fixed-wing" if "Plane" in firmware
               else "ground vehicle" if "Rover" in firmware else "multirotor")
    return firmware, vehicle, heli
