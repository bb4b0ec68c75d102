"""The control period a command uses when ``--dt`` is not given, and the note that says so: ``heli design``
(PD and ``--lqg``) and ``heli sweep`` take it, and ``heli evaluate`` names it when a PD's period does not fit a
model.

The period is the environment's own default (:func:`heli_core.control_period.default_dt`): :data:`DEFAULT_DT`, or, where
that is not a whole number of the model's gust-trace sample periods, the shortest whole number of them above it.
"""

from __future__ import annotations

from heli_core.control_period import DEFAULT_DT, default_dt

__all__ = ["DEFAULT_DT", "control_period"]


def control_period(sample_rate: float) -> tuple[float, str | None]:
    """The default control period [s] for a model whose gust traces are sampled at ``sample_rate`` [Hz]
    (:func:`heli_core.control_period.default_dt`: a PD designed for 0.01 s could not be flown on a 50 Hz log's model),
    and a note when it is not :data:`DEFAULT_DT`."""
    dt = default_dt(sample_rate)
    if dt == DEFAULT_DT:
        return DEFAULT_DT, None
    periods = round(dt * sample_rate)
    what = "the sample period" if periods == 1 else f"{periods} sample periods"
    return dt, (f"note: control period {dt:.4g} s, {what} of the model's {sample_rate:g} Hz gust traces (the "
                f"default {DEFAULT_DT:g} s is not a whole number of them); pass --dt to choose")
