"""How much worse an agent flies when the aircraft is not the model: extra servo delay, control gain off.

:func:`robustness_check` evaluates one agent (a PD or an RL policy, through the one evaluator
:func:`controllers.evaluate.evaluate_agent`) on the model as identified and on perturbed copies of it —
by default 20 ms more servo delay on every axis (eq. 31), and the control gains (k2, k6, k10) 20 % lower
and 20 % higher — on the same gust windows, and reports per case and axis the p90 |attitude error| and its
ratio to the nominal one. An episode that ends early (|roll| or |pitch| beyond 60°) counts as a failure.
"""

from __future__ import annotations

from heli_core.deprecation import module_getattr
from heli_core.terms import AXES
from heli_env.env_model import as_env_model, perturbed

CASES = {"nominal": {}, "+20 ms servo delay": {"delay": 0.02}, "gain -20 %": {"gain": 0.8},
         "gain +20 %": {"gain": 1.2}}
"""The perturbations flown: extra servo delay [s] added to every axis, control-gain factor
(:func:`heli_env.env_model.perturbed`'s arguments)."""


def robustness_check(agent, model=None, cases=None, evaluate=None, **evaluate_kwargs) -> dict:
    """p90 |attitude error| per case and axis, its ratio to the nominal, and the episodes that ended early.

    Parameters
    ----------
    agent : PD controller or policy with ``predict``
    model : str, Path, EnvModel or None
    cases : dict of str to dict, optional
        Name → ``perturbed`` arguments (default :data:`CASES`); the first is the reference.
    evaluate : callable, optional
        ``evaluate(agent, model, **evaluate_kwargs)`` returning an EvaluationResult (default
        :func:`controllers.evaluate.evaluate_agent`; :func:`controllers.firmware.loop_rate_env.evaluate_firmware`
        flies a firmware loop at its own rate).
    **evaluate_kwargs
        Passed to ``evaluate``: ``config=`` an
        :class:`~controllers.evaluate.EvaluationConfig`, or its fields (traces, episodes_per_trace, seed, ...).

    Returns
    -------
    dict
        ``{case: {"p90_deg": {axis: float}, "ratio": {axis: float}, "ended_early": int}}``.
    """
    from .evaluate import evaluate_agent

    evaluate = evaluate_agent if evaluate is None else evaluate
    env_model = as_env_model(model)
    cases = CASES if cases is None else cases
    out, reference = {}, None
    for name, change in cases.items():
        res = evaluate(agent, perturbed(env_model, **change), **evaluate_kwargs)
        p90 = {axis: res.metrics[axis]["att_p90_deg"] for axis in AXES}
        reference = reference or p90
        out[name] = {"p90_deg": p90, "ratio": {a: p90[a] / reference[a] for a in AXES},
                     "ended_early": res.n_terminated}
    return out


__getattr__ = module_getattr(__name__)
