"""The log's input hold decided again in the closed loop's world, where the loop's bias reaches the hold.

:func:`~identification.likelihood.input_hold.decide_hold` reads the hold from the likelihood of the gyro
conditioned on the sticks. A pilot who sees the aircraft puts into his sticks motion the gyro did not measure
(:mod:`identification.likelihood.closed_loop`), and on a slow aircraft behind a noisy gyro that leak makes a
pilot's interpolated sticks look held: the sluggish aircraft's flights in the noisy-gyro cell were decided
0.00-0.16 for a pilot's hand, and the check then measured its bias in the wrong world (dampings 20-23 % RMS).

The hold's evidence is itself a statistic the closed-loop check can reproduce. Per named hold ``h`` (0 held, 1
interpolated), the flight is fitted at ``h`` (the checked axes without a servo delay or lag, as the check fits their
flights) and that model is flown under the pilot fitted to the sticks; each simulated flight is fitted at both
holds, and the log-likelihood ratio ``LR = nll(held) - nll(interpolated)``, summed over the checked axes, is
recorded. Each world gives the LR its own distribution, and the flight's LR is read against both: on the
sluggish aircraft behind a 0.03 rad/s gyro, a pilot's hand gave -12.5 on the flight, -2.8 +- 4.3 in the
interpolated world and -25.4 +- 3.7 in the held one; held sticks gave -35.0 against -5.5 +- 4.0 and
-32.4 +- 4.1 (the world's mean +- the spread of one flight). The hold whose world makes the flight's LR the
more probable (normal densities) is the log's; when it is not the one decided, the checked axes take their fit
at it, the other axes are searched again at it, and the closed-loop check runs again there.

The LR is summed over the checked axes without a servo delay or lag: a delay shapes the phase as a hold does
(a held stick is about half a sample late), so on an axis with one the hold is not the log's alone. On the
sluggish aircraft with a real 10 ms pitch delay and a pilot's hand, the delay-free pitch fits put the summed LR at
-21.5, in the held world (-26.8 +- 2.9), and the hand's roll and yaw were fitted held, their dampings +20 %.

The axes vote as well: each axis' own LR is read against its own worlds' in the same way, and where a strict
majority of three or more axes points to the other hold than their sum, the majority decides. A
delay the search did not find is the case: on seed 302 (the sluggish aircraft, a pilot's hand, a real 10 ms
pitch delay fitted as none) the delay-free pitch put the sum in the held world while roll and yaw pointed to
the interpolated one; one axis whose hold is confounded with something else should not carry the others.

The leak can also stop short of a named hold: logged at 25 Hz behind a 0.03 rad/s gyro, a pilot's hand on the
paper aircraft was read as a fraction 0.72 (both named holds rejected), its dampings 12-18 % high, and a check
flown at that fraction measured its own world's 1-5 %. A fraction decided is therefore read the same way, against
three worlds: both named holds' and its own (LR +66 on the flight; +88 +- 13 interpolated, -185 +- 18 held,
+18 +- 15 at the fraction: the hand's). A log whose sticks really are stamped part-way through their sample
sits in its fraction's world, and the fraction stands. The axes do not vote there: a fraction's world lies
between the named ones, each axis' own worlds closer still, and on seed 2 of the same cell two axes' votes kept
a fraction 0.73 (dampings 18-26 % high) where the sum, by a hair, chose the hand's world (4-11 %).

It runs only where it can matter: the hold was decided by ``input_hold="auto"`` (a hold the user gives is not
second-guessed), and the closed-loop check found a bias the loop's way beyond its significance (elsewhere the
loop does not reach the likelihood far enough to move a named hold), or the hold decided is a fraction and the
check flew at least one axis: flown at the fraction the check measures its own world's bias, which may be small
where the fraction is the loop's doing. A named world that cannot be flown (its pilot fit reads a flight
controller) is left out of a fraction's comparison. A flight whose LR no world reproduces (all beyond
:data:`MAX_Z` spreads) keeps the hold decided, and says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from heli_core.terms import AXES

from ..errors import IdentifiabilityError
from .axis_pool import map_axes
from .axis_search import BURN_IN
from .axis_fit import model_values
from .closed_loop import SIGNIFICANCE, axis_refit
from .loop_world import flown_flights, has_servo, with_fits, world_loops
from .input_hold import HOLDS

MAX_Z = 3.0
"""A flight's hold LR further than this many spreads from both worlds' means is reproduced by neither."""


@dataclass(frozen=True)
class HoldCheck:
    """The hold decided in the closed loop's world.

    Attributes
    ----------
    decided : str
        The hold :func:`~identification.likelihood.input_hold.decide_hold` chose ("zoh", "linear", or a fraction
        as :func:`decided_label` names it, "fraction 0.72").
    chosen : str
        The hold this check found the flight's (the decided one when ``reason`` says why it was kept).
    axes : tuple of str
        The axes whose LRs are summed.
    flight_lr : float or None
        The flight's ``nll(zoh) - nll(linear)`` over ``axes``.
    worlds : dict
        Per hold, the simulated flights' LRs (``lr``), their ``mean``, ``sd`` and the flight's ``z``.
    reason : str
        Why the decided hold was kept without a comparison, why no world reproduces the flight, or that the
        axes' majority overrode their sum.
    applied : bool
        The fit was moved to the chosen hold (:func:`switch_hold`, the check's mode "auto").
    votes : dict
        Axis -> the hold its own LR chose against its own worlds' (None: neither reproduces it).
    by_majority : bool
        The axes' majority chose the hold against their sum.
    """

    decided: str
    chosen: str
    axes: tuple = ()
    flight_lr: float | None = None
    worlds: dict = field(default_factory=dict)
    reason: str = ""
    applied: bool = False
    votes: dict = field(default_factory=dict)  # axis -> the hold its own LR chose (axis_votes), None: neither
    by_majority: bool = False  # the axes' majority overrode their sum (reason says so)
    fits: dict = field(default_factory=dict, repr=False, compare=False)  # the chosen hold's axis fits

    @property
    def switched(self) -> bool:
        return self.chosen != self.decided

    def describe(self) -> dict:
        """JSON-ready."""
        return {"decided": self.decided, "chosen": self.chosen, "axes": list(self.axes), "flight_lr": self.flight_lr,
                "worlds": self.worlds, "reason": self.reason, "switched": self.switched,
                "applied": self.applied, "votes": self.votes, "by_majority": self.by_majority}

    def line(self) -> str:
        """One line for a report or the terminal."""
        if not self.worlds:
            return f"hold: {self.decided} kept ({self.reason})"
        seen = "; ".join(f"{h} world {w['mean']:+.1f} ± {w['sd']:.1f}" for h, w in self.worlds.items())
        why = self.reason if self.by_majority else f"the {self.chosen} hold's world reproduces it"
        verdict = (f"{why}: hold {self.decided} -> {self.chosen}" + ("" if self.applied else " (reported, not applied)")
                   if self.switched else f"hold {self.chosen} kept" + (f" ({self.reason})" if self.reason else ""))
        return (f"hold in the loop's world: the flight's LR (held - interpolated) {self.flight_lr:+.1f} over "
                f"{', '.join(self.axes)}; {seen}: {verdict}")


def needs_hold_check(ident, check) -> str:
    """Why the hold is not checked (empty when it is): only a hold the estimator decided, and only where the
    closed-loop check found a bias the loop's way beyond its significance or, for a fraction, checked an axis
    (module docstring)."""
    decision = getattr(ident, "hold_decision_", None) or {}
    if ident.input_hold != "auto" or "fraction" not in decision:
        return "the hold was not decided by the estimator"
    if any(c.checked and c.loop_ticks > 1 for c in check.axes.values()):
        return ("a flight controller's loop faster than the log was flown at its own rate: it holds its command over "
                "each of its ticks, and the log's hold is how its commands were sampled, not a hand's (held where "
                "the data do not reject it)")
    if not decision.get("named") and any(c.checked for c in check.axes.values()):
        return ""  # a fraction may be the loop's own doing: the check at it measures its own world's bias only
    for c in check.axes.values():
        if c.checked and c.loops_direction:
            damping = list(c.bias)[1]
            if c.bias[damping] > SIGNIFICANCE * c.bias_se[damping]:
                return ""
    return "no bias the loop's way: the loop does not reach the hold"


def _lr(ident, world, loops: dict, names: dict, seed: int, tag: int, b: int):
    """Replicate ``b`` of ``world``: each checked axis flown and fitted at both holds; each axis' LR (a dict), or
    the refusal's message."""
    rng = np.random.default_rng([seed, b, tag])
    out = {}
    for axis, kept in names.items():
        flights = flown_flights(world, axis, loops[axis], rng)
        try:
            nll = {h: axis_refit(ident, axis, kept, flights, h).axes_[axis].nll for h in HOLDS}
        except IdentifiabilityError as exc:
            return str(exc)
        out[axis] = nll["zoh"] - nll["linear"]
    return out


def decided_label(decision: dict) -> str:
    """The hold the estimator decided, as :class:`HoldCheck` names it: "linear", "zoh" or "fraction 0.77"."""
    return decision.get("named") or f"fraction {decision['fraction']:.2f}"


def decide_hold_in_loop(ident, check, n_flights: int, seed: int = 0, workers=None) -> HoldCheck:
    """Decide the log's hold in the closed loop's world (module docstring). Does not change ``ident``;
    :func:`switch_hold` does."""
    why = needs_hold_check(ident, check)
    if why:
        decision = getattr(ident, "hold_decision_", None) or {}
        given = decided_label(decision) if "fraction" in decision else str(ident.input_hold)
        return HoldCheck(given, given, reason=why)
    decided = decided_label(ident.hold_decision_)
    candidates = {h: h for h in HOLDS}  # world -> the hold its fits take: each named hold, and a fraction decided
    if decided not in HOLDS:
        candidates[decided] = float(ident.hold_decision_["fraction"])
    axes = tuple(a for a, c in check.axes.items() if c.checked and not has_servo(ident.axes_[a]))
    if not axes:
        return HoldCheck(decided, decided, reason="every checked axis has a servo delay or lag, and a delay shapes "
                         "the phase as a hold does: the hold is read on axes without one")
    names = {axis: ident._kept_terms(AXES.index(axis), ident.axes_[axis]) for axis in axes}
    fitted = {h: {axis: axis_refit(ident, axis, kept, ident.flights_, value) for axis, kept in names.items()}
              for h, value in candidates.items()}
    flight_lrs = {a: float(fitted["zoh"][a].axes_[a].nll - fitted["linear"][a].axes_[a].nll) for a in axes}
    flight_lr = float(sum(flight_lrs.values()))
    worlds, fits, unflown = {}, {}, []
    for tag, h in enumerate(candidates, start=1):
        fits[h] = {a: replace(fitted[h][a].axes_[a], dropped=ident.axes_[a].dropped) for a in axes}
        world = with_fits(ident, fits[h])
        loops, unfit = world_loops(world, axes)
        if unfit and (h == decided or len(candidates) == 2):  # nothing left to compare the decision with
            return HoldCheck(decided, decided, axes, flight_lr, reason=f"the {h} hold's world cannot be flown: {unfit}")
        if unfit:  # a fraction decided is compared with the named world that can be flown
            unflown.append(f"the {h} hold's world cannot be flown: {unfit}")
            continue
        lrs = map_axes(lambda b: _lr(ident, world, loops, names, seed, tag, b), range(n_flights), workers)
        refused = next((r for r in lrs if isinstance(r, str)), None)
        if refused is not None:
            return HoldCheck(decided, decided, axes, flight_lr,
                             reason=f"a flight of the {h} hold's world could not be fitted ({refused})")
        worlds[h] = lrs
    chosen, summary, reason = choose_hold(flight_lr, {h: [sum(r.values()) for r in lrs] for h, lrs in worlds.items()},
                                          decided)
    votes = axis_votes(flight_lrs, worlds, decided)
    majority = majority_hold(votes) if decided in HOLDS else None  # a fraction's world lies between: the sum decides
    overridden = not reason and majority is not None and majority != chosen
    if overridden:
        reason = (f"the axes' majority ({', '.join(a for a, v in votes.items() if v == majority)}) points to "
                  f"{majority} where their sum pointed to {chosen}")
        chosen = majority
    return HoldCheck(decided, chosen, axes, flight_lr, summary, "; ".join([reason] * bool(reason) + unflown),
                     votes=votes, by_majority=overridden, fits=fits[chosen])


def axis_votes(flight_lrs: dict, worlds: dict, decided: str) -> dict:
    """Each axis' hold: the world (hold -> list of per-axis LR dicts) whose own LRs of the axis make its
    ``flight_lrs`` value the more probable (:func:`choose_hold`), None where neither reproduces it."""
    votes = {}
    for axis, lr in flight_lrs.items():
        chosen, _, reason = choose_hold(lr, {h: [r[axis] for r in lrs] for h, lrs in worlds.items()}, decided)
        votes[axis] = None if reason else chosen
    return votes


def majority_hold(votes: dict) -> str | None:
    """The hold more than half of the axes chose, where there are at least three (an axis whose own LR neither
    world reproduces chooses none), or None."""
    cast = [v for v in votes.values() if v is not None]
    if len(votes) < 3 or not cast:
        return None
    best = max(sorted(set(cast)), key=cast.count)
    return best if cast.count(best) > len(votes) / 2 else None


def choose_hold(flight_lr: float, lrs: dict, decided: str) -> tuple[str, dict, str]:
    """The hold whose world makes the flight's LR the more probable, from each world's simulated LRs ``lrs``
    (hold -> list): a normal density per world, its mean and spread those of its flights. Returns the hold,
    the worlds' summaries (``lr``, ``mean``, ``sd``, the flight's ``z``) and a reason when ``decided`` is kept
    because no world reproduces the flight (each beyond :data:`MAX_Z` spreads)."""
    worlds = {}
    for h, values in lrs.items():
        values = np.asarray(values, dtype=float)
        sd = float(max(values.std(ddof=1), 1e-9))
        worlds[h] = {"lr": [float(v) for v in values], "mean": float(values.mean()), "sd": sd,
                     "z": float((flight_lr - values.mean()) / sd)}
    density = {h: -0.5 * w["z"] ** 2 - np.log(w["sd"]) for h, w in worlds.items()}
    if min(abs(w["z"]) for w in worlds.values()) > MAX_Z:
        return decided, worlds, f"no world reproduces the flight's LR (beyond {MAX_Z:g} spreads)"
    return max(density, key=density.get), worlds, ""


def switch_hold(ident, hold: HoldCheck) -> HoldCheck:
    """Give ``ident`` the hold ``hold`` chose when it is not the one decided: the checked axes take their fit at
    it, every other axis is searched again at it from its optimum; ``params_`` and ``hold_decision_`` follow.
    Returns ``hold``, marked ``applied`` when the fit moved."""
    if not hold.switched:
        return hold
    fraction = HOLDS[hold.chosen]
    burn = int(round(BURN_IN * ident.flights_[0].sample_rate))
    ident._decided_hold = fraction
    try:
        for axis, fit in ident.axes_.items():
            ident.axes_[axis] = hold.fits[axis] if axis in hold.fits else replace(
                ident._refit_at_hold(axis, fit, ident.flights_, burn), input_shift=fit.input_shift)
    finally:
        ident._decided_hold = None
    ident.params_ = ident.params_.with_values(**model_values(ident.axes_))
    ident.hold_decision_ = {**ident.hold_decision_, "fraction": fraction, "named": hold.chosen}
    ident.hold_alternative_ = None  # the loop's world decided between the two holds
    return replace(hold, applied=True)
