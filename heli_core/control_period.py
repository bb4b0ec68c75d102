"""The control period an environment, a sweep or a design uses unless told (imports nothing numeric, so that the
command line can name it in its help).

An environment steps whole samples of a gust trace (:func:`heli_env.spec.build_spec`), so the default period is
:data:`DEFAULT_DT` where that is a whole number of the traces' sample periods, else the shortest whole number of
them above it.
"""

from __future__ import annotations

import math

DEFAULT_DT = 0.01
"""The control period [s] used unless told, where it is a whole number of the gust traces' sample periods."""


def default_dt(sample_rate: float) -> float:
    """The control period [s] for a model whose gust traces are sampled at ``sample_rate`` [Hz] unless told:
    :data:`DEFAULT_DT` where it is a whole number of sample periods, else the shortest whole number of them above
    it: 0.02 s for a model identified from a 50 Hz log, 0.012 s (three samples) for one from a 250 Hz log, where
    0.01 s could not be flown at all.
    """
    periods = max(1, math.ceil(DEFAULT_DT * sample_rate - 1e-6))
    dt = round(periods / sample_rate, 9)  # a measured 50.000000001 Hz still steps at 0.02 s
    return DEFAULT_DT if abs(dt - DEFAULT_DT) <= 1e-9 else dt
