"""Why a fit came out unphysical, tested rather than guessed: is the log's input column late?

A model fitted at the logged timing can come out with a damping of the wrong sign
(k3 = -0.37, k7 = -1.02 on the T-REX 550 hover of ``../shared/fixtures/logs``): the
response comes before the input that caused it, which a causal model can only fit by
running unstable. Several logs are written so: an RC receiver's channel logged after
the flybarless unit acted on it, a stick column stamped when a packet was stored.
:func:`check_alignment` answers the question by fitting again with the alignment
searched (``delay="auto"``: servo delays and negative shifts of the stick, -0.6 to
+0.5 s) and reports per axis what it found, whether the model is then physical
(every damping positive) and whether the aligned model is stable when simulated from
the flight's sticks. Only then does the caller advise ``--delay auto``: advice that
follows a test, never advice that sends the user round in a circle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from heli_core.deprecation import module_getattr
from heli_core.errors import HeliError
from heli_core.terms import AXES

from ..likelihood.estimator import MaximumLikelihoodIdentifier

DAMPING = {"roll": "k3", "pitch": "k7", "yaw": "k11"}
"""Each axis' damping parameter (eqs. 18, 21)."""

MIN_EXPLAINED = 0.2
"""Least share of an axis' rate variance its stick explains for the axis to count as excited here."""

RESOLUTION_S = 0.02
"""Shifts smaller than this [s] (two samples at 100 Hz) are the log's timing convention, not a late input."""


@dataclass(frozen=True)
class AlignmentFinding:
    """What fitting with the alignment searched found.

    Attributes
    ----------
    shifts : dict of str to float
        Per axis, the stick's shift [s] (< 0: the log's input lags the response).
    delays : dict of str to float
        Per axis, the servo delay found [s] (>= 0).
    dampings : dict of str to float
        Per axis, the damping of the aligned fit [1/s].
    explained : dict of str to float
        Per axis, the share of the rate's variance the aligned model explains from the sticks alone: an axis
        below :data:`MIN_EXPLAINED` is not excited enough by its stick for its alignment to mean much.
    physical : bool
        Every fitted axis' damping is positive.
    stable : bool
        The aligned model stays bounded when simulated from the flight's sticks.
    seconds : float
        Time the check took [s].
    """

    shifts: dict
    delays: dict
    dampings: dict
    explained: dict
    physical: bool
    stable: bool
    seconds: float

    @property
    def helps(self) -> bool:
        """Whether identifying with the alignment searched gives a physical, stable model."""
        return self.physical and self.stable

    @property
    def excited(self) -> list:
        """Axes whose stick explains at least :data:`MIN_EXPLAINED` of the rate (their alignment is found)."""
        return [a for a, r2 in self.explained.items() if r2 >= MIN_EXPLAINED]

    @property
    def late_axes(self) -> list:
        """Excited axes whose input was found late by more than :data:`RESOLUTION_S`."""
        return [a for a, s in self.shifts.items() if s < -RESOLUTION_S and a in self.excited]

    def describe(self) -> str:
        """One sentence: what the aligned fit found, and whether the model is then physical."""
        late = self.late_axes
        parts = []
        weak = [a for a in self.explained if a not in self.excited]
        if late:
            same = max(self.shifts[a] for a in late) - min(self.shifts[a] for a in late) < 0.05
            parts.append("the sticks are logged late: " + ", ".join(f"{a} by {-self.shifts[a]:.2f} s" for a in late)
                         + (" (one lag for every axis: the log's timing, not the aircraft)" if same and len(late) > 1
                            else ""))
        delayed = [a for a, d in self.delays.items() if d > RESOLUTION_S]
        if delayed:
            parts.append("servo delays " + ", ".join(f"{a} {self.delays[a]:.2f} s" for a in delayed))
        if not parts:
            parts.append("no alignment beyond the log's timing resolution")
        if weak:
            parts.append(", ".join(f"{a} ({100 * max(self.explained[a], 0.0):.0f} % of its rate from its stick)"
                                   for a in weak) + " too weakly excited by its stick to place its alignment")
        damp = ", ".join(f"{DAMPING[a]}={v:.3g}" for a, v in self.dampings.items())
        state = ("physical and stable" if self.helps else
                 "still not physical" if not self.physical else "physical but unstable in simulation")
        return f"{'; '.join(parts)}; the model is then {state} ({damp})"


def check_alignment(flights, identifier_kwargs: dict | None = None) -> AlignmentFinding:
    """Fit ``flights`` with the alignment searched (``delay="auto"``) and the other settings of
    ``identifier_kwargs``, and say what it found (:class:`AlignmentFinding`)."""
    import time

    from heli_core.physics import forward_rates

    from ..validation.forward_simulation import DIVERGED_RATE

    t0 = time.perf_counter()
    kwargs = {k: v for k, v in (identifier_kwargs or {}).items() if k not in ("delay", "delay_grid")}
    ident = MaximumLikelihoodIdentifier(delay="auto", **kwargs).fit(flights)
    dampings = {a: float(ident.params_.get(DAMPING[a])) for a in ident.axes_}
    try:
        with np.errstate(all="ignore"):
            sim = forward_rates(ident.params_, ident.flights_[0])
        stable = bool(np.all(np.abs(sim) <= DIVERGED_RATE))
    except (HeliError, ValueError, FloatingPointError):
        stable = False
    return AlignmentFinding(
        shifts={a: float(ident.input_shifts_.get(a, 0.0)) for a in ident.axes_},
        delays={a: float(f.delay) for a, f in ident.axes_.items()},
        dampings=dampings, explained={a: float(f.r2) for a, f in ident.axes_.items()}, physical=all(v > 0.0 for v in dampings.values()), stable=stable,
        seconds=time.perf_counter() - t0)


def unphysical_axes(params) -> list:
    """Axes whose damping is not positive in ``params``."""
    return [a for a in AXES if not params.get(DAMPING[a]) > 0.0]


__getattr__ = module_getattr(__name__)
