"""What the log actually flew: the attitude error against the desired attitude, where the log records both.

ArduPilot logs the attitude controller's target beside the attitude (``ATT.DesRoll``, ``DesPitch``,
``DesYaw`` and ``Roll``, ``Pitch``, ``Yaw`` [deg]). :func:`flown_errors` takes the airborne segment the
importer chose, cuts it into blocks of :data:`BLOCK_S` seconds, keeps the blocks where the desired attitude
moved less than :data:`STEADY_DEG` (no large commanded move: the error there is the gusts' and the loop's,
as the prediction's is) and reports p50/p90/p99 of |desired − attitude| per axis (yaw wrapped to ±180°).
Rotorflight's blackbox logs rate set-points, not a desired attitude: there is nothing to compare and the
result says so. The comparison is only meaningful where the log flew the gains read from it, in the mode
the loop models (Stabilize/AltHold; ArduPilot's Acro has no attitude target to hold).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from heli_core.terms import AXES

BLOCK_S = 2.0
"""Length of the blocks the segment is cut into [s]."""
STEADY_DEG = 2.0
"""A block counts when each desired angle spans less than this [deg] over it."""


@dataclass(frozen=True)
class FlownErrors:
    """The log's own attitude error (module docstring).

    Attributes
    ----------
    available : bool
    reason : str
        Why not, or which stream and segment were used.
    seconds : float
        Time in the blocks kept [s].
    axes : dict
        Per axis ``{"p50_deg", "p90_deg", "p99_deg"}``.
    """

    available: bool
    reason: str
    seconds: float = 0.0
    axes: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"available": self.available, "reason": self.reason, "seconds": self.seconds, "axes": self.axes}


def _att_records(path: Path):
    from heli_core.errors import require

    dfreader = require("pymavlink.DFReader", "logs")
    f = dfreader.DFReader_binary(str(path), zero_time_base=False)
    rows = []
    while True:
        m = f.recv_match(type=["ATT"])
        if m is None:
            break
        t = getattr(m, "TimeUS", None)
        t = t * 1e-6 if t is not None else getattr(m, "TimeMS", 0) * 1e-3
        rows.append((t, m.DesRoll, m.Roll, m.DesPitch, m.Pitch, m.DesYaw, m.Yaw))
    return np.array(rows, dtype=float).reshape(-1, 7)


def steady_errors(t, desired, actual) -> FlownErrors:
    """Statistics of |desired − actual| [deg] (3, n) over the steady blocks of ``t`` [s] (module docstring)."""
    err = desired - actual
    err[2] = (err[2] + 180.0) % 360.0 - 180.0
    block = np.floor((t - t[0]) / BLOCK_S).astype(int)
    keep = np.zeros(t.size, dtype=bool)
    for b in np.unique(block):
        sel = block == b
        span = np.ptp(np.unwrap(np.radians(desired[:, sel]), axis=1), axis=1)
        if np.all(np.degrees(span) < STEADY_DEG) and sel.sum() >= 3:
            keep |= sel
    if keep.sum() < 10:
        return FlownErrors(False, f"fewer than 10 samples in blocks of {BLOCK_S:g} s without a commanded move of "
                           f"{STEADY_DEG:g} deg or more")
    axes = {a: {f"p{q}_deg": float(np.percentile(np.abs(err[i, keep]), q)) for q in (50, 90, 99)}
            for i, a in enumerate(AXES)}
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    return FlownErrors(True, "", float(keep.sum() * dt), axes)


def flown_errors(log_path, segment=None) -> FlownErrors:
    """The log's attitude error against its desired attitude in steady blocks (module docstring).

    Parameters
    ----------
    log_path : path
    segment : (t0, t1), optional
        The airborne segment on the log's clock [s] (``flight.metadata["segment"]``); default the whole log.
    """
    from identification.io import detect_format

    path = Path(log_path)
    fmt = detect_format(path)
    if fmt != "ardupilot-dataflash":
        what = {"csv": "a CSV flight holds no desired attitude",
                "blackbox": "a blackbox log records rate set-points, not a desired attitude"}.get(
            fmt, f"a {fmt} log: its desired attitude is not read here")
        return FlownErrors(False, what)
    rows = _att_records(path)
    if rows.shape[0] < 10:
        return FlownErrors(False, "the log has fewer than 10 ATT messages")
    t = rows[:, 0]
    sel = np.ones(t.size, dtype=bool) if segment is None else (t >= segment[0]) & (t <= segment[1])
    if sel.sum() < 10:
        return FlownErrors(False, "fewer than 10 ATT messages in the airborne segment")
    t = t[sel]
    desired = rows[sel][:, [1, 3, 5]].T
    actual = rows[sel][:, [2, 4, 6]].T
    out = steady_errors(t, desired, actual)
    if not out.available:
        return out
    where = "the whole log" if segment is None else f"{segment[0]:.1f}-{segment[1]:.1f} s"
    return FlownErrors(True, f"ATT DesRoll/DesPitch/DesYaw against Roll/Pitch/Yaw over {where}, blocks of "
                       f"{BLOCK_S:g} s whose desired attitude moved less than {STEADY_DEG:g} deg", out.seconds,
                       out.axes)
