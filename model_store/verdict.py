"""A model's verdict: whether an identified model can be used, and why not.

An estimator returns numbers for any flight. Whether they describe the aircraft is judged once, where the
model is identified (:mod:`identification.validation.model_verdict`), and stored in ``model.json`` beside the
parameters::

    "verdict": {"level": "unusable",
                "reasons": ["roll: the damping k3 = 200 1/s sits at the estimator's search bound (200 1/s) ..."]}

Every report shows it first, and the commands that build on a model (``heli design``, ``sweep``,
``evaluate``, ``train``) refuse an unusable one unless told otherwise
(:func:`model_store.model_file.require_usable`) and print the doubts of a doubtful one. A model file written
before verdicts existed, or by hand, has none: it reads as :data:`NOT_JUDGED` and is used as before.

The levels, from best to worst:

``usable``
    Nothing found against the model.
``doubtful``
    The model may hold, but something weakens it (a fit that explains little of the rates, a gain the data do
    not tell from zero); the reasons say what.
``unusable``
    The numbers cannot describe an aircraft (a parameter at the search's bound, a gain whose sign the other
    estimator contradicts, a damping that is not positive, a simulation that diverges); a controller designed
    on it is designed on nothing.

This module is the verdict as plain data, with no import of the store: reading it from a file (and naming the
file when it is malformed) is the file format's (:func:`model_store.model_file.verdict_of`), and refusing an
unusable model is the commands' gate (:func:`model_store.model_file.require_usable`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from heli_core.deprecation import module_getattr

USABLE, DOUBTFUL, UNUSABLE = "usable", "doubtful", "unusable"
LEVELS = (USABLE, DOUBTFUL, UNUSABLE)
"""The levels of a verdict, best first."""
NOT_JUDGED = "not judged"
"""The level of a model file that carries no verdict (written before verdicts, or by hand)."""


@dataclass(frozen=True)
class ModelVerdict:
    """Whether a model can be used, with the reasons.

    Attributes
    ----------
    level : str
        One of :data:`LEVELS`, or :data:`NOT_JUDGED`.
    reasons : tuple of str
        One sentence per finding that sets the level; empty for ``usable`` and ``not judged``.
    doubts : tuple of str
        Of an unusable model, the findings that alone would make it doubtful (a doubtful model's are its
        ``reasons``).
    """

    level: str
    reasons: tuple = ()
    doubts: tuple = ()

    def __post_init__(self):
        if self.level not in LEVELS + (NOT_JUDGED,):
            raise ValueError(f"verdict level must be one of {', '.join(LEVELS + (NOT_JUDGED,))}, got {self.level!r}")
        reasons = tuple(self.reasons)
        if not all(isinstance(r, str) and r for r in reasons):
            raise ValueError(f"verdict reasons must be non-empty strings, got {list(reasons)!r}")
        if self.level in (DOUBTFUL, UNUSABLE) and not reasons:
            raise ValueError(f"a {self.level} verdict needs at least one reason")
        doubts = tuple(self.doubts)
        if not all(isinstance(r, str) and r for r in doubts):
            raise ValueError(f"verdict doubts must be non-empty strings, got {list(doubts)!r}")
        if doubts and self.level != UNUSABLE:
            raise ValueError(f"only an unusable verdict carries doubts beside its reasons, got a {self.level} one")
        object.__setattr__(self, "reasons", reasons)
        object.__setattr__(self, "doubts", doubts)

    @property
    def unusable(self) -> bool:
        return self.level == UNUSABLE

    @property
    def doubtful(self) -> bool:
        return self.level == DOUBTFUL

    def to_dict(self) -> dict:
        """The ``"verdict"`` entry of ``model.json`` (``doubts`` only when there are some)."""
        return {"level": self.level, "reasons": list(self.reasons)} | ({"doubts": list(self.doubts)}
                                                                       if self.doubts else {})

    @classmethod
    def from_dict(cls, entry) -> ModelVerdict:
        """The verdict of a ``"verdict"`` entry; None reads as :data:`NOT_JUDGED`.

        Raises
        ------
        ValueError
            An entry that is not ``{"level": ..., "reasons": [...]}`` with a known level. Read from a model file
            (:func:`model_store.model_file.verdict_of`), it is a ``ModelFileError`` naming the file.
        """
        if entry is None:
            return cls(NOT_JUDGED)
        if not isinstance(entry, Mapping) or not all(isinstance(entry.get(k, []), list) for k in ("reasons", "doubts")):
            raise ValueError(f"'verdict' must be an object {{\"level\": ..., \"reasons\": [...]}}, got {entry!r}")
        return cls(str(entry.get("level")), tuple(entry.get("reasons", [])), tuple(entry.get("doubts", [])))

    def sentence(self) -> str:
        """The verdict in one line: ``"unusable: reason; reason"`` (``"usable"`` alone without reasons)."""
        return self.level + (": " + "; ".join(self.reasons) if self.reasons else "")

    def lines(self) -> list[str]:
        """Every finding, the reasons first, then an unusable model's doubts (marked so)."""
        return list(self.reasons) + [f"also doubtful: {d}" for d in self.doubts]

    def markdown(self) -> list[str]:
        """The lines a report opens with: the level in bold, then each reason as a bullet."""
        head = f"**Model verdict: {self.level}**"
        if self.level == NOT_JUDGED:
            return [head + " (the model file carries no verdict).", ""]
        if not self.reasons:
            return [head + ": nothing found against the model (parameters inside the search's bounds, "
                    "positive dampings, gains of one sign by both estimators).", ""]
        return [head + (" — do not design a controller on it:" if self.unusable else ":"), ""] + \
            [f"- {r}" for r in self.lines()] + [""]


__getattr__ = module_getattr(__name__)
