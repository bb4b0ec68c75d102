"""The control period a controller is designed for when ``--dt`` is not given: ``heli design`` (PD and
``--lqg``) picks it, and ``heli evaluate`` names it when a PD's period does not fit a model.

The environment steps whole samples of a gust trace (:func:`heli_env.spec.build_spec`), so the period is
:data:`DEFAULT_DT` or, for a model whose traces are sampled more slowly, the shortest whole number of their
sample periods above it.
"""

from __future__ import annotations

import math

DEFAULT_DT = 0.01
"""Control period designed for unless told [s]: the environment's."""


def control_period(sample_rate: float) -> tuple[float, str | None]:
    """The default control period [s] for a model whose gust traces are sampled at ``sample_rate`` [Hz]:
    :data:`DEFAULT_DT`, or the shortest whole number of sample periods above it (the environment steps whole
    samples of a trace: a PD designed for 0.01 s could not be flown on a 50 Hz log's model), and a note then."""
    periods = max(1, math.ceil(DEFAULT_DT * sample_rate - 1e-6))
    dt = round(periods / sample_rate, 9)  # a measured 50.000000001 Hz still designs for 0.02 s
    if abs(dt - DEFAULT_DT) <= 1e-9:
        return DEFAULT_DT, None
    what = "the sample period" if periods == 1 else f"{periods} sample periods"
    return dt, (f"note: control period {dt:.4g} s, {what} of the model's {sample_rate:g} Hz gust traces (the "
                f"default {DEFAULT_DT:g} s is not a whole number of them); pass --dt to choose")
