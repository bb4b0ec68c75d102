"""Aircraft the bench flies besides the paper's (eqs. 68-70): truth parameters for the studies and tests that ask
whether the identification holds on helicopters it was not tuned on (``scripts/aircraft_generalisation.py``)."""

from __future__ import annotations

from heli_core.params import ModelParams

from .flight_config import PAPER_PARAMS

AIRCRAFT: dict[str, ModelParams] = {
    # a 450-class flybarless helicopter: three times the control power, more than twice the damping
    "agile": ModelParams(k2=4.0, k3=6.0, kd1=0.10, k6=-2.7, k7=6.5, kd2=0.05, k10=35.0, k11=7.0, k12=-1.0, kd3=0.20),
    # a large scale helicopter: half the control power and damping of the paper's
    "sluggish": ModelParams(k2=0.7, k3=1.2, kd1=0.02, k6=-0.5, k7=1.1, kd2=0.01, k10=6.0, k11=1.6, k12=-0.3,
                            kd3=0.05),
    # roll three times as fast as pitch, a stiff tail
    "asymmetric": ModelParams(k2=2.5, k3=7.5, kd1=0.05, k6=-0.6, k7=1.3, kd2=0.01, k10=20.0, k11=8.0, k12=-0.8,
                              kd3=0.1),
    # the sticks mapped the other way round (a log whose channels' signs differ from the paper's)
    "mirrored": ModelParams(k2=-1.1, k3=2.0, kd1=0.03, k6=1.2, k7=3.0, kd2=-0.02, k10=-10.0, k11=4.0, k12=0.4,
                            kd3=-0.05),
}
"""Truth parameters of the aircraft flown besides the paper's (``"paper"``)."""


def aircraft_truth(name: str) -> ModelParams:
    """The truth of aircraft ``name``: ``"paper"`` (eqs. 68-70) or a key of :data:`AIRCRAFT`.

    Raises
    ------
    KeyError
        ``name`` is neither, naming the aircraft there are.
    """
    if name == "paper":
        return PAPER_PARAMS
    if name not in AIRCRAFT:
        raise KeyError(f"expected an aircraft of {['paper', *AIRCRAFT]}, got {name!r}")
    return AIRCRAFT[name]
