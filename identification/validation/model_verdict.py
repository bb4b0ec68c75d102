"""Judge a fitted model: usable, doubtful or unusable, with the reasons (stored as ``model.json``'s verdict).

An estimator returns numbers for any flight; on a flight that does not show an axis' dynamics they are
confident nonsense (a Betaflight quad: both dampings at the search's bound of 200 1/s, a roll gain of
-2125 rad/s² where the integral method finds +788). :func:`judge_fit` reads the fitted identifier's
per-axis summary and says so, once, for every command that writes a model (``heli identify``,
``heli diagnose``, ``heli refresh``). The verdict's type and its place in ``model.json`` are
:mod:`model_store.verdict`'s.

What makes a model **unusable** (each on the parameters the fit estimated):

* a damping (``k3``, ``k7``, ``k11``) at a bound of the estimator's search (:data:`ML_DAMPING_BOUNDS` for
  the maximum-likelihood fit): the likelihood kept improving towards the bound, so the data did not place it;
* a damping that is not positive: a rotor damps its rates; an axis that does not is unstable on its own and
  a fit that finds one has fitted something else (a controller's loop, a misread input);
* a control gain (``k2``, ``k6``, ``k10``) whose sign the other estimator on the same flight contradicts,
  both clear of zero by :data:`SIGN_Z` standard errors, their sticks aligned alike within :data:`SAME_ALIGNMENT`:
  the data do not say which way the stick turns the aircraft, and a controller with the wrong sign pushes the
  wrong way;
* a simulation from the flight's sticks that diverges (passed in by the caller that ran it).

What makes it **doubtful**:

* an axis whose sticks-only simulation explains less than :data:`MIN_R2` of the rate variance (R²) *and*
  whose gain or damping the data do not pin down: a standard error above :data:`PLACED_SE` of the value, or
  the integral method on the same flight more than :data:`ESTIMATOR_RATIO` times it or less than its
  inverse. A low R² alone is no doubt about the model: the rest of the rate is wind, and on the project's
  own synthetic flights yaw's R² is near 0 with its parameters within a few % of the truth. Where the
  closed-loop check flew the axis, the integral method's reading is first rid of its bias there: less the
  difference between its reading on the model's own flights in that loop (the check's ``integral``) and the
  model's value. The integral method has no wind model, and a pilot or controller that answers the gusts biases it
  (on the bench, 2x low on a slow aircraft's axes behind held sticks, near zero behind an autopilot, where the
  likelihood's dampings were within 4-14 % of the truth);
* a control gain within :data:`SIGN_Z` standard errors of zero: the data do not show the stick's effect;
* a damping the closed-loop check corrected by a factor above :data:`LOOP_CORRECTION` (fitted over corrected): a
  flight controller's loop that corrects the aircraft inside each logged sample reads as damping, and a value
  corrected this far rests on the check's simulated loop more than on the data. On the bench's autopilot
  (``scripts/aircraft_generalisation.py``, loops 4-8x faster than 25-100 Hz logs, three aircraft, 99 axes) the
  corrected dampings of the axes at or below that factor lay within -11 to +13 % of the truth; above it, -18 to
  +76 % (the large, slow aircraft logged at 25 Hz, its fits 1.6-2.9 times the check's values). On conditions the
  factor was not drawn from (a stated gyro filter of 10, 20 or 30 Hz at 100 Hz, two aircraft, 36 axes) it held
  less well: below it -12 to +31 % (the slow aircraft's pitch behind a 10 Hz filter), above it -19 to +19 %. It
  marks the largest failures, not a bound on the rest; no factor from 1.25 to 1.6 separates the two kinds.

The function is pure: summaries in, a :class:`~model_store.verdict.ModelVerdict` out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from heli_core.terms import AXES, TERMS
from model_store.verdict import DOUBTFUL, UNUSABLE, USABLE, ModelVerdict

from .fit_warnings import MIN_R2

ML_DAMPING_BOUNDS = (-2.0, 200.0)
"""1/s: the interval the maximum-likelihood estimator searches each damping in, as it says itself
(:attr:`identification.likelihood.estimator.MaximumLikelihoodIdentifier.damping_bounds`; a test holds them equal)."""
BOUND_TOLERANCE = 1e-3
"""A damping closer to a bound than this share of the bounds' span sits at the bound."""
SIGN_Z = 2.0
"""Standard errors a gain must be clear of zero for its sign to count (about 95 %)."""
PLACED_SE = 0.20
"""A gain or damping whose standard error exceeds this share of its value is not pinned down by the data."""
ESTIMATOR_RATIO = 2.0
"""Two estimators whose gain or damping differ by more than this factor do not agree on it."""
LOOP_CORRECTION = 1.5
"""A fitted damping more than this factor above the value the closed-loop check corrected it to is doubtful
(module docstring): the check took a third of it or more."""

DAMPING = {a: next(p for p, t in TERMS.items() if t.axis == i and t.effect == "damping") for i, a in enumerate(AXES)}
"""The damping parameter of each axis: roll ``k3``, pitch ``k7``, yaw ``k11``."""
GAIN = {a: next(p for p, t in TERMS.items() if t.axis == i and t.effect == "control") for i, a in enumerate(AXES)}
"""The control gain of each axis: roll ``k2``, pitch ``k6``, yaw ``k10``."""


def _value(stats: Mapping, name: str) -> tuple[float, float] | None:
    """(value, standard error) of ``name`` in one axis' summary, None when the fit did not estimate it."""
    params = stats.get("params") or {}
    if name not in params or params[name] is None:
        return None
    se = (stats.get("std_errors") or {}).get(name)
    return float(params[name]), (float(se) if se is not None and math.isfinite(float(se)) else math.nan)


def _clear_of_zero(value: float, se: float) -> bool:
    """Whether ``value`` is at least :data:`SIGN_Z` standard errors from zero (no standard error: it is)."""
    return not math.isfinite(se) or abs(value) >= SIGN_Z * se


def bound_side(value: float, bounds) -> str | None:
    """``"upper"`` or ``"lower"`` when ``value`` lies within :data:`BOUND_TOLERANCE` of the interval ``bounds``'
    end (a value the search did not place), else None (also for ``bounds`` None)."""
    if bounds is None:
        return None
    lo, hi = bounds
    tol = BOUND_TOLERANCE * (hi - lo)
    return next((side for bound, side in ((hi, "upper"), (lo, "lower")) if abs(value - bound) <= tol), None)


def _damping_findings(axis: str, stats: Mapping, bounds) -> list[str]:
    name = DAMPING[axis]
    got = _value(stats, name)
    if got is None:
        return []
    value, _ = got
    side = bound_side(value, bounds)
    if side is not None:
        return [f"{axis}: damping {name} = {value:.4g} 1/s is at the {side} bound of the estimator's search "
                "(the data did not place it)"]
    if not value > 0.0:
        return [f"{axis}: damping {name} = {value:.4g} 1/s is not positive (an axis that does not settle by "
                "itself: the fit describes something else, a controller's loop or a misread input)"]
    return []


def _gain_findings(axis: str, stats: Mapping, reference: Mapping | None) -> tuple[list[str], list[str]]:
    """(unusable, doubtful) findings about the axis' control gain."""
    name = GAIN[axis]
    got = _value(stats, name)
    if got is None:
        return [], []
    value, se = got
    if not _clear_of_zero(value, se):
        return [], [f"{axis}: control gain {name} = {value:.4g} ± {se:.2g} rad/s² is within {SIGN_Z:g} standard "
                    "errors of zero (the data do not show which way the stick turns the aircraft)"]
    ref = _value(reference.get(axis) or {}, name) if reference else None
    if ref is not None and _clear_of_zero(*ref) and math.copysign(1.0, ref[0]) != math.copysign(1.0, value):
        return [f"{axis}: control gain {name} = {value:.4g} rad/s² against {ref[0]:+.4g} by the integral method on "
                "the same flight (the data do not say which way the stick turns the aircraft)"], []
    return [], []


def _unplaced(axis: str, stats: Mapping, reference: Mapping | None, in_loop: Mapping | None = None) -> list[str]:
    """Why the axis' gain and damping are not pinned down (empty when both are). ``in_loop``: per name, what the
    integral method read on the model's own flights in the flight's loop (the closed-loop check's ``integral``) and
    the value they were flown at (None: the model's); where given, its reading on the flight less that bias,
    ``reading - (in_loop - flown at)``, is compared with the model's value (the additive correction of a
    parametric bootstrap, which stays meaningful where a biased reading lies near zero, as the integral method's
    dampings behind an autopilot do: -0.05 and 0.18 on the flight and in its loop where the model reads 1.12)."""
    out = []
    for name in (GAIN[axis], DAMPING[axis]):
        got = _value(stats, name)
        if got is None or got[0] == 0.0:
            continue
        value, se = got
        if math.isfinite(se) and se > PLACED_SE * abs(value):
            out.append(f"{name} ±{100 * se / abs(value):.0f} %")
        ref = _value(reference.get(axis) or {}, name) if reference else None
        if ref is None:
            continue
        expected, flown_at = (in_loop or {}).get(name, (None, None))
        if expected is not None:  # its bias in the model's own loop removed (a parametric bootstrap's correction)
            corrected = ref[0] - (expected - (value if flown_at is None else flown_at))
            if not 1.0 / ESTIMATOR_RATIO <= corrected / value <= ESTIMATOR_RATIO:
                out.append(f"{name} {value:.4g}, by the integral method {ref[0]:.4g}, which reads {expected:.4g} on the "
                           f"model's own flights in the flight's loop ({corrected:.4g} without that bias)")
        elif not 1.0 / ESTIMATOR_RATIO <= ref[0] / value <= ESTIMATOR_RATIO:
            out.append(f"{name} {value:.4g}, by the integral method {ref[0]:.4g}")
    return out


def _integral_in_loop(closed_loop: Mapping | None, axis: str) -> Mapping | None:
    """Per name, the integral method's gain and damping on the flights the closed-loop check flew of ``axis``
    (median; its record's ``integral``, kept wherever it flew them: to measure the likelihood's bias, or for this
    reading alone where the loop closes on the logged sensors) and the value the model was flown at (the check's
    ``fitted``: the model's value may be the check's correction of it), else None."""
    c = ((closed_loop or {}).get("axes") or {}).get(axis) or {}
    fitted = c.get("fitted") or {}
    return {k: (v, fitted.get(k)) for k, v in c["integral"].items()} if c.get("integral") else None


def _r2_finding(axis: str, stats: Mapping, reference: Mapping | None, min_r2: float,
                in_loop: Mapping | None = None) -> list[str]:
    r2 = stats.get("r2")
    if r2 is None or not math.isfinite(float(r2)) or float(r2) >= min_r2:
        return []
    unplaced = _unplaced(axis, stats, reference, in_loop)
    if not unplaced:
        return []
    return [f"{axis}: the sticks explain {100 * max(float(r2), 0.0):.0f} % of the rate in simulation "
            f"(R² {float(r2):.2f}) and the data do not pin its parameters down ({'; '.join(unplaced)})"]


def _loop_findings(closed_loop: Mapping | None) -> list[str]:
    """Doubts about the dampings the closed-loop check corrected by more than :data:`LOOP_CORRECTION` (``closed_loop``:
    :meth:`~identification.likelihood.closed_loop.ClosedLoopCheck.describe`, or None)."""
    out = []
    for axis, c in ((closed_loop or {}).get("axes") or {}).items():
        name = DAMPING.get(axis)
        fitted, corrected = (c.get("fitted") or {}).get(name), (c.get("corrected") or {}).get(name)
        if name not in (c.get("removed") or ()) or not fitted or not corrected or corrected <= 0.0:
            continue
        if fitted / corrected > LOOP_CORRECTION:
            who = (f"a flight controller's loop {c['loop_ticks']}x faster than the log corrects the aircraft inside "
                   "each sample" if c.get("loop_ticks", 1) > 1 else "the pilot's loop biases the fit")
            out.append(f"{axis}: the closed-loop check put damping {name} at {corrected:.4g} 1/s where the fit read "
                       f"{fitted:.4g} ({fitted / corrected:.2g} times it): {who}, and a damping corrected this far "
                       "rests on the check's simulated loop more than on the data (on the bench such dampings lay "
                       "-19 to +76 % from the truth; docs/method.md); log the commands and the gyro at the loop's "
                       "rate to identify it")
    return out


def judge_fit(summary: Mapping, *, damping_bounds=None, reference: Mapping | None = None,
              diverged: str | None = None, min_r2: float = MIN_R2, closed_loop: Mapping | None = None,
              sign_reference: Mapping | None = None) -> ModelVerdict:
    """The verdict on a fitted model (module docstring).

    Parameters
    ----------
    summary : mapping of str to mapping
        Per axis (``"roll"``, ``"pitch"``, ``"yaw"``) the fit's statistics as the identifiers'
        ``summary()`` returns them: ``"params"`` {name: value}, ``"std_errors"`` {name: se} and ``"r2"``
        (the share of the rate variance the sticks-only simulation explains; the integral fit's R²).
    damping_bounds : (float, float), optional
        The interval the estimator searched the dampings in [1/s] (:data:`ML_DAMPING_BOUNDS` for the
        maximum-likelihood fit); None for an estimator without bounds (the integral method).
    reference : mapping, optional
        Another estimator's summary on the same flights (the integral method beside a maximum-likelihood fit),
        against whose control gains the signs are checked and whose gains and dampings an axis the sticks explain
        little of must be near (within :data:`ESTIMATOR_RATIO`).
    sign_reference : mapping, optional
        Where given, the signs are checked against it instead (:func:`judge_identifier`: the axes aligned alike
        within :data:`SAME_ALIGNMENT`, where ``reference`` holds only those aligned exactly alike, since a delay
        that cannot turn a sign still moves the magnitudes).
    diverged : str, optional
        Why the model diverged when simulated from the flight's sticks, when it did.
    min_r2 : float
        The least R² that raises no doubt (default :data:`identification.validation.fit_warnings.MIN_R2`).
    closed_loop : mapping, optional
        The closed-loop check's record (``model.json``'s ``fit_statistics.closed_loop``), whose large damping
        corrections are doubts (:data:`LOOP_CORRECTION`), and whose integral method on the model's own flights is
        what the integral method on the flight is compared with (module docstring).

    Returns
    -------
    model_store.verdict.ModelVerdict
        ``unusable`` with its reasons (and the doubts beside them), ``doubtful`` with the doubts, or ``usable``.
    """
    unusable, doubts = [], []
    for axis in AXES:
        stats = summary.get(axis)
        if stats is None:
            continue
        unusable += _damping_findings(axis, stats, damping_bounds)
        bad, doubt = _gain_findings(axis, stats, reference if sign_reference is None else sign_reference)
        unusable += bad
        doubts += doubt + _r2_finding(axis, stats, reference, min_r2, _integral_in_loop(closed_loop, axis))
    doubts += _loop_findings(closed_loop)
    if diverged:
        unusable.append(f"diverges when simulated from the flight's sticks ({diverged})")
    if unusable:
        return ModelVerdict(UNUSABLE, tuple(unusable), tuple(doubts))
    return ModelVerdict(DOUBTFUL, tuple(doubts)) if doubts else ModelVerdict(USABLE)


SAME_ALIGNMENT = 0.025
"""s: two fits whose sticks' alignments (a shift of the stick plus a servo delay) differ by no more than this are
compared (:func:`judge_identifier`). A stick moved by ``tau`` turns its gain's sign only where its motion lies near
``1 / (4 tau)``: 10 Hz for this, below 1 Hz for the T-REX hover's 0.29 s. A servo lag turns no sign (its phase stays
below 90°) and is not counted. Until 2026-12-05 any difference excluded the axis: the Betaflight quad's roll, its
stick advanced one 10 ms sample, kept a gain of -909 rad/s² beside the integral method's +737, unflagged."""


def judge_identifier(ident, reference=None, diverged: str | None = None) -> ModelVerdict:
    """:func:`judge_fit` on a fitted identifier (its ``summary()``), with the search's bounds of its estimator
    and ``reference`` another fitted identifier on the same flights (or None): the gains' signs compared on the
    axes where both aligned the stick alike within :data:`SAME_ALIGNMENT` (a stick advanced or delayed further by
    one fit changes the other's gains, even their sign: the T-REX hover's sticks, 0.29 s late, give the unaligned
    integral fit k2 = -10.5), their sizes where both aligned it exactly alike."""
    bounds = getattr(ident, "damping_bounds", None)  # the estimator says where it searched (the integral: nowhere)
    summary = ident.summary()
    ref = reference.summary() if reference is not None else None
    signs = None
    if ref is not None:  # compare only axes both fitted on the same alignment of sticks and response
        shifts = getattr(ident, "input_shifts_", None) or {}
        apart = {a: abs(float(shifts.get(a) or 0.0)) + abs(float(summary[a].get("delay_s") or 0.0)
                                                           - float(s.get("delay_s") or 0.0))
                 for a, s in ref.items() if a in summary}
        signs = {a: ref[a] for a, t in apart.items() if t <= SAME_ALIGNMENT}
        ref = {a: ref[a] for a, t in apart.items() if t == 0.0}
    check = getattr(ident, "closed_loop_", None)
    return judge_fit(summary, damping_bounds=bounds, reference=ref, diverged=diverged,
                     closed_loop=None if check is None else check.describe(), sign_reference=signs)
