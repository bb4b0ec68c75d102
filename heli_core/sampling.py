"""Uniform sampling: the one test of it that every stage applies.

A flight's samples, and the disturbance traces identified from them, are taken as a uniform time grid by every
estimator, simulator and the env's replay. :func:`is_uniform` says whether a time column is one, to a tolerance
that float stamps computed as ``t0 + k dt`` or accumulated ``t += dt`` meet and a clock rounded to a
millisecond, jitter or a missing sample do not.
"""

from __future__ import annotations

import numpy as np

UNIFORM_RTOL = 1e-6
"""Every interval within this of the median interval, relative to ``max(median, 1 s)`` (plus 1 ns), is uniform."""


def is_uniform(time) -> bool:
    """Whether every interval of ``time`` (s, at least 2 samples) is within :data:`UNIFORM_RTOL` of their median."""
    dt = np.diff(np.asarray(time, dtype=float))
    med = float(np.median(dt))
    return bool(med > 0 and np.max(np.abs(dt - med)) <= UNIFORM_RTOL * max(med, 1.0) + 1e-9)
