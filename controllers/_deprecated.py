"""The old homes of controllers' names, kept for one release with a ``DeprecationWarning`` (issue 34).

Moves of the RL and PD code left modules and names that only re-exported others: ``controllers.residual`` and
``controllers.rl.residual`` (the residual agent of :mod:`controllers.rl.residual_agent` and
:func:`controllers.rl.train.residual_setup`), ``controllers.sb3_vec_env`` (:mod:`controllers.rl.vec_env`),
``controllers.backends`` (:mod:`heli_core.backends`), the PD names of the package itself and the report's tables
``controllers.evaluate`` lent its name to (and its result's ``markdown()`` and ``plot_episode()``, which the
report renders now: :func:`heli_core.deprecation.moved_method`). Each name now has one home; the old names keep working until
:data:`heli_core.deprecation.REMOVAL`, answered by the mechanism every package shares
(:class:`heli_core.deprecation.Deprecations`; ``controllers/__init__.py`` installs it).

First-party code never imports an old name: ``scripts/structure_report.py`` reads the two tables below and
fails when it finds one.
"""

from __future__ import annotations

MOVED_MODULES: dict[str, tuple[str, ...]] = {
    "controllers.backends": ("heli_core.backends",),
    "controllers.residual": ("controllers.rl.residual_agent", "controllers.rl.train"),
    "controllers.rl.residual": ("controllers.rl.residual_agent", "controllers.rl.train"),
    "controllers.sb3_vec_env": ("controllers.rl.vec_env",),
}
"""Old module -> the modules its public names live in now, searched in this order."""

MOVED_NAMES: dict[str, dict[str, str]] = {
    "controllers": {
        "PDController": "controllers.pd.controller", "PDGains": "controllers.pd.controller",
        "design_gains": "controllers.pd.design", "propose_gains": "controllers.pd.design",
        "loop_analysis": "controllers.pd.analysis", "plant": "controllers.pd.linearisation",
    },
    "controllers.evaluate": {
        "comparison_markdown": "controllers.evaluate_report", "metrics_table": "controllers.evaluate_report",
        "evaluation_markdown": "controllers.evaluate_report", "plot_episode": "controllers.evaluate_report",
    },
    "controllers.flight_test": {"KS_TARGET": "controllers.flight_test_result"},
    "controllers.pd.linearisation": {"control_sign": "controllers.pd.law"},
    "controllers.robustness": {"perturbed": "heli_env.env_model"},
    "controllers.sweep": {
        "COLUMNS": "controllers.sweep_result", "FD_COLUMNS": "controllers.sweep_result",
        "SweepResult": "controllers.sweep_result", "MAX_ANGLE_DEG": "controllers.sweep_replay",
        "TASK_STATES": "controllers.sweep_replay", "TD_COLUMNS": "controllers.sweep_replay",
        "MAX_EXTENSIONS": "controllers.sweep_extend", "ROBUST_GAIN_MARGIN_DB": "controllers.sweep_margins",
        "ROBUST_PHASE_MARGIN_DEG": "controllers.sweep_margins", "check_gains": "controllers.sweep_inputs",
        "parse_range": "controllers.sweep_inputs",
    },
    "controllers.sweep_report": {"write_csv": "controllers.sweep_result", "write_json": "controllers.sweep_result"},
}
"""Module that stays -> {old name it re-exported: the module that defines it}."""
