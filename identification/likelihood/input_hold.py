"""How a log's sticks move between samples: the input's hold, as a fraction, and the log's decision.

A log rarely says whether its sticks were a pilot's hand sampled (linearly interpolated between samples,
MATLAB's ``InterSample`` 'foh') or commands held over each sample (a digital radio link, a flight
controller: 'zoh'). Read the wrong way, a held stick is half a sample of lead that the damping absorbs
(14-19 % on flights no one here made). The maximum-likelihood estimator
(:mod:`identification.likelihood.estimator`) therefore fits a hold *fraction* per axis with every other parameter
(:func:`hold_fraction` gives the discretisation's input weights their meaning) and :func:`decide_hold`
turns the axes' estimates into one hold for the log.
"""

from __future__ import annotations

import numpy as np

HOLDS = {"linear": 1.0, "zoh": 0.0}
"""The named holds as fractions of linear interpolation: a pilot's hand sampled (``"linear"``, first-order
hold, MATLAB's ``InterSample`` 'foh') and a command held over its sample (``"zoh"``, a digital link or a
flight controller)."""


def hold_fraction(hold) -> float:
    """The input's hold as a fraction ``a`` in [0, 1]: between samples ``u(t) = u_k + a (u_{k+1} - u_k) s``,
    ``s = (t - t_k)/dt``; 0 is a zero-order hold, 1 linear interpolation (:data:`HOLDS` names both).

    A number is taken as it is (the likelihood's derivatives step just past either end); the settings a
    user gives are checked to lie in [0, 1] where they come in.

    Raises
    ------
    ValueError
        Neither a name of :data:`HOLDS` nor a finite number.
    """
    if isinstance(hold, str):
        if hold in HOLDS:
            return HOLDS[hold]
    elif isinstance(hold, (int, float, np.integer, np.floating)) and not isinstance(hold, bool):
        if np.isfinite(hold):
            return float(hold)
    raise ValueError(f"input hold must be 'linear', 'zoh' or a fraction in [0, 1], got {hold!r}")


HOLD_START = 0.5
"""The hold fraction an estimating search starts from."""

HOLD_BIC = 0.5
"""Per log-sample, the negative log-likelihood a free hold fraction must gain over the nearer named hold to be
kept (Schwarz's criterion: one parameter costs ``HOLD_BIC * ln n``)."""


def decide_hold(estimates: dict, n: float, prefer: str | None = None) -> dict:
    """One hold for a log from each axis' estimate ``{axis: (fraction, se)}`` over ``n`` samples per axis.

    The axes' likelihoods are independent given the hold, and near its optimum each is quadratic in it, so
    their sum is ``sum (a - a_i)^2 / (2 se_i^2)``: its minimum is the pooled fraction. A named hold (1 a
    pilot's hand sampled, 0 a held command) is taken unless the pooled likelihood gains more than Schwarz's
    ``HOLD_BIC * ln n`` over it; then the pooled fraction stands (a log whose sticks are stamped part-way
    through their sample). A lone axis' weak estimate (0.03 +- 0.32 on a noisy pitch gyro, whose damping it
    biased 13 %) is so outvoted by the others and by the evidence it needs.

    With ``prefer`` (a named hold), that hold is taken wherever the data do not reject it, the other named hold
    only where they reject ``prefer`` and not it: a flight controller's commands logged slower than its loop are
    held over each of its ticks, while the loop moves them inside each logged sample, and the likelihood alone
    reads both ways there (:meth:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier._controller_hold`).

    Returns
    -------
    dict
        ``fraction`` (the decision), ``pooled`` and ``pooled_se``, ``named`` ("linear", "zoh" or None),
        ``nll_gain`` per named hold (how much worse than the pooled fraction) and ``threshold``.
    """
    used = {a: (f, se) for a, (f, se) in estimates.items() if se is not None and se > 0 and np.isfinite(se)}
    if not used:
        frac = float(np.mean([f for f, _ in estimates.values()]))
        return {"fraction": frac, "pooled": frac, "pooled_se": None, "named": None, "nll_gain": {}, "threshold": None}
    w = np.array([1.0 / se ** 2 for _, se in used.values()])
    f = np.array([v for v, _ in used.values()])
    pooled = float(np.clip(w @ f / w.sum(), 0.0, 1.0))

    def cost(a):
        return float(0.5 * np.sum(w * (a - f) ** 2))

    threshold = HOLD_BIC * float(np.log(max(n, 2.0)))
    gain = {name: cost(HOLDS[name]) - cost(pooled) for name in ("linear", "zoh")}
    named = min(gain, key=gain.get)
    if prefer is not None and gain[prefer] < threshold:
        named = prefer
    keep = gain[named] < threshold
    return {"fraction": HOLDS[named] if keep else pooled, "pooled": pooled, "pooled_se": float(w.sum() ** -0.5),
            "named": named if keep else None, "nll_gain": gain, "threshold": threshold}


def check_hold(hold) -> None:
    """Raise ``ValueError`` unless ``hold`` is "auto", "linear", "zoh" or a fraction in [0, 1]."""
    if hold == "auto" or hold in HOLDS:
        return
    if isinstance(hold, (int, float, np.integer, np.floating)) and not isinstance(hold, bool) and 0 <= hold <= 1:
        return
    raise ValueError(f"input_hold must be 'auto', 'linear', 'zoh' or a fraction in [0, 1], got {hold!r}")


def other_hold(named: str) -> str:
    """The named hold that is not ``named``."""
    return "zoh" if named == "linear" else "linear"


def undecided_against(decision: dict | None) -> str | None:
    """The other named hold where the data leave the log's named hold in doubt, else None.

    :func:`decide_hold` takes a named hold unless the data reject it; they may reject neither. Read from the
    axes' pooled estimate, the log-likelihood ratio between the two named holds is the difference of their
    ``nll_gain``; below the decision's own threshold (Schwarz's ``HOLD_BIC * ln n``) the other hold is as
    admissible as the one taken. On a 60 s flight of a slow aircraft with held sticks the axes put it at 2.3 for
    interpolated sticks (threshold 4.3), and the dampings fitted at the two holds differ by 10-20 %: four times
    their standard errors, which assume the hold known.
    """
    if not decision or not decision.get("named") or not decision.get("nll_gain"):
        return None
    named = decision["named"]
    other = other_hold(named)
    return other if decision["nll_gain"][other] - decision["nll_gain"][named] < decision["threshold"] else None


def hold_alternative(other: str, fits: dict, alternative: dict, threshold: float) -> dict:
    """What the log's fit would be at the ``other`` named hold, and how much the data prefer the one taken.

    ``fits`` and ``alternative`` map axes to their fits (``params``, ``std_errors``, ``nll``) at the hold taken and
    at the other. ``lr`` is the summed ``nll(other) - nll(taken)`` (> 0: the taken hold is the likelier) and
    ``weight`` the other hold's posterior probability under equal prior odds, ``1 / (1 + exp(lr))``: what
    :func:`std_errors_with_hold` weighs the other fit by.
    """
    lr = float(sum(alternative[a].nll for a in alternative) - sum(fits[a].nll for a in alternative))
    weight = float(1.0 / (1.0 + np.exp(min(lr, 700.0))))
    return {"hold": other, "lr": lr, "threshold": float(threshold), "weight": weight,
            "axes": {a: {"params": dict(f.params), "std_errors": dict(f.std_errors)} for a, f in alternative.items()}}


def std_errors_with_hold(params: dict, std_errors: dict, alternative: dict | None, axis: str) -> dict:
    """``std_errors`` of an axis' ``params`` widened by the hold's doubt (``alternative`` from
    :func:`hold_alternative`, None: unchanged): the root mean square error of the values taken under the two holds'
    posterior weights, ``sqrt((1 - w) se^2 + w (se_o^2 + (p_o - p)^2))`` with ``p_o``, ``se_o`` the value and
    standard error at the other hold and ``w`` its weight."""
    other = (alternative or {}).get("axes", {}).get(axis)
    if other is None:
        return dict(std_errors)
    w = alternative["weight"]
    out = {}
    for name, se in std_errors.items():
        if name in other["params"] and name in params:
            se_o = other["std_errors"].get(name, se)
            gap = other["params"][name] - params[name]
            out[name] = float(np.sqrt((1 - w) * se ** 2 + w * (se_o ** 2 + gap ** 2)))
        else:
            out[name] = se
    return out
