"""Named exceptions of the firmware loops: parameter files and gains that cannot be used as given.

Each derives from :class:`heli_core.errors.HeliError` (one line and exit status 2 in the ``heli``
command) and from ``ValueError``, and says what was expected and what came.
"""

from __future__ import annotations

from heli_core.errors import HeliError


class FirmwareParamError(HeliError, ValueError):
    """A firmware parameter cannot be used: a malformed line or name, an unknown name of a family this
    package reads, a value outside the firmware's documented range in a file the user gave, a log without
    parameters."""


class FirmwareMappingError(HeliError, ValueError):
    """The model cannot be flown by the firmware as asked: an axis the model cannot control (zero control
    gain), a command scale that is zero or not finite, a loop rate that is not a whole multiple of the
    control period."""
