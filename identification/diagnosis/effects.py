"""The catalogue of candidate physical effects a diagnosis can name (issue 6).

An *effect* is a named family of model terms from :mod:`heli_core.terms`
(every term carries an ``effect`` tag), or, for ``servo_delay``, the alignment
in time between the command and the response, or, for ``servo_lag``, the servo's
first-order lag (eq. 31 with the lag added to ``d1``; only the likelihood
diagnosis fits it, behind a servo delay found). The catalogue only *describes*:
it says which terms (or which delay) a candidate adds on an axis; the fitter
(:class:`identification.integral.method.IntegralIdentifier`) receives them as
ordinary ``structure`` / ``delay`` arguments and knows nothing of effects. So
adding an effect is adding terms with a new tag to :data:`heli_core.terms.TERMS`
and a line to :data:`DESCRIPTIONS` (the layout of pysindy's feature library
versus its optimizers).

Time alignment. ``servo_delay`` covers both signs: a positive alignment ``s``
is a transport delay of the servo, modelled in the aircraft by the first-order
Padé approximation of eq. (31) (``tau_<axis>`` of the model); a negative one
means the log's input column lags the response — no aircraft answers a command
before it is given, so this is a time misalignment of the log, corrected by
advancing the logged input (:func:`identification.preprocess.shift_inputs`) before the model sees it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from heli_core.terms import AXES, TERMS

from ..errors import NotFittedError

NONE = "none"
"""The verdict when nothing significant is missing."""
UNDECIDED = "undecided"
"""The verdict when the flight is too short or too poorly excited to decide."""
SERVO_DELAY = "servo_delay"
SERVO_LAG = "servo_lag"

DESCRIPTIONS: dict[str, str] = {
    SERVO_DELAY: "transport delay between command and response: the servo response time, first-order Padé "
                 "approximation of eq. (31) (Section 2.5.1); a negative value is a log whose input column lags "
                 "the response (time misalignment), corrected by advancing the input",
    SERVO_LAG: "the servo lags its command by a first-order time constant (eq. 31 with the lag added to d1, "
               "Section 2.5.1): at low frequency a delay of the same length, above 1/(2 pi T) a loss of gain "
               "a transport delay does not have",
    "cross_coupling": "another axis' rate drives this one: the flybar term C3 of eq. (13), k4·q in roll "
                      "(eq. 18-19) and -k8·p in pitch (eq. 21-22)",
    "gyroscopic": "rigid-body gyroscopic coupling, the product of the other two rates times an inertia ratio "
                  "(eq. 5): k1·q·r, k5·p·r, k9·p·q (eqs. 19, 22, 23)",
    "collective_torque": "the collective drives the axis: main-rotor reaction torque -k12·δo in yaw (eqs. 15, 17, "
                         "21) and its cyclic analogue when the rotor disc is tilted (Section 2.2)",
    "nonlinear_damping": "damping that grows faster than linearly with the rate (quadratic, e.g. nld1·p|p|); "
                         "beyond the paper's linear damping k3, k7, k11",
    "gain_scheduling": "control effectiveness k2, k6, k10 (eqs. 19, 23) varying with the collective, i.e. "
                       "with rotor load (terms u·δo)",
}
"""One line of physics per effect, citing the paper where it applies."""

PHYSICAL_BOUNDS: dict[str, tuple[float, float, str]] = {
    **{k: (-1.0, 1.0, "an inertia ratio such as (Iyy - Izz)/Ixx lies in [-1, 1] for any rigid body (eq. 5)")
       for k in ("k1", "k5", "k9")},
    **{k: (0.0, np.inf, "quadratic damping takes energy out of the rotation, so it is positive")
       for k in ("nld1", "nld2", "nld3")},
}
"""Term name -> (lowest, highest, why) for the terms whose physics bounds their value. A candidate
effect whose fitted terms fall outside is not a physical explanation of the data, whatever its
likelihood (it fits something else: a controller's loop, a misread input)."""


def implausible(values: dict) -> str | None:
    """Why fitted term ``values`` (name -> value) cannot be physical, or None when they can.

    Examples
    --------
    >>> implausible({"nld1": -3.0})
    'nld1 = -3 outside [0, inf]: quadratic damping takes energy out of the rotation, so it is positive'
    >>> implausible({"k1": 0.8}) is None
    True
    """
    for name, value in values.items():
        if name in PHYSICAL_BOUNDS:
            lo, hi, why = PHYSICAL_BOUNDS[name]
            if not lo <= value <= hi:
                return f"{name} = {value:.3g} outside [{lo:g}, {hi:g}]: {why}"
    return None


MAX_ALIGNMENT = 0.6
"""Largest |time alignment| the ``servo_delay`` search covers [s]."""


class DiagnosisResult:
    """What both diagnosers (:class:`~identification.diagnosis.heldout_diagnoser.Diagnoser`,
    :class:`~identification.diagnosis.likelihood_diagnoser.LikelihoodDiagnoser`) answer alike once fitted: the
    verdict, the effects found and the steps that added them."""

    def _check_fitted(self):
        if not hasattr(self, "verdict_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call fit(flight) first")

    def _summary_head(self) -> dict:
        """The JSON-ready verdict, effects found and steps every diagnosis summary starts with."""
        self._check_fitted()
        return {"verdict": self.verdict_, "effects_found": [{"effect": e, "axis": a} for e, a in self.effects_found_],
                "steps": [s.to_dict() for s in self.steps_]}


@dataclass(frozen=True)
class Effect:
    """One candidate effect of the catalogue.

    Attributes
    ----------
    name : str
        Catalogue name (``"cross_coupling"``, ...).
    description : str
        One line of physics (:data:`DESCRIPTIONS`).
    terms : tuple of str
        The terms of :data:`heli_core.terms.TERMS` tagged with this
        effect, on every axis (empty for ``servo_delay`` and ``servo_lag``).
    """

    name: str
    description: str
    terms: tuple

    @property
    def is_alignment(self) -> bool:
        """True for ``servo_delay``: the candidate is a time alignment, not a term."""
        return self.name == SERVO_DELAY

    @property
    def is_servo_lag(self) -> bool:
        """True for ``servo_lag``: the candidate is the servo's first-order lag, not a term (the likelihood
        diagnosis fits it; the held-out one has no servo filter)."""
        return self.name == SERVO_LAG

    def terms_on(self, axis: int) -> tuple:
        """The effect's terms acting on ``axis`` (0 roll, 1 pitch, 2 yaw)."""
        return tuple(p for p in self.terms if TERMS[p].axis == axis)

    def acts_on(self, axis: int) -> bool:
        """Whether the effect can be added on ``axis``."""
        return self.is_alignment or self.is_servo_lag or bool(self.terms_on(axis))


def _catalogue() -> dict[str, Effect]:
    out = {}
    for name, text in DESCRIPTIONS.items():
        terms = tuple(p for p, t in TERMS.items() if t.effect == name)
        out[name] = Effect(name, text, terms)
    return out


CATALOGUE: dict[str, Effect] = _catalogue()
"""Every effect a diagnosis can name, by name (``none`` and ``undecided`` are verdicts, not effects)."""


def alignment_parts(alignment) -> tuple[tuple, tuple]:
    """Split per-axis time alignments into servo delays (>= 0, eq. 31) and input shifts (<= 0) [s]."""
    a = [float(v) for v in alignment]
    return tuple(max(v, 0.0) for v in a), tuple(min(v, 0.0) for v in a)


def describe(name: str, axis: int | None = None) -> str:
    """One line naming an effect (and its terms on ``axis``) for reports."""
    if name in (NONE, UNDECIDED):
        return name
    eff = CATALOGUE[name]
    if eff.is_alignment:
        return f"{name} ({AXES[axis]} command/response alignment)" if axis is not None else name
    if eff.is_servo_lag:
        return f"{name} (lag_{AXES[axis]})" if axis is not None else name
    terms = eff.terms_on(axis) if axis is not None else eff.terms
    return f"{name} ({', '.join(terms)})"
