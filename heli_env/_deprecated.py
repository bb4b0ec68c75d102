"""The old homes of heli_env's names, kept for one release with a ``DeprecationWarning`` (issue 34).

``heli_env.model_dir`` is now :mod:`heli_env.env_model` (the environment's model; :mod:`model_store.model_dir`
is the model folder), and :data:`~heli_env.observation.OBS_DIM` is no longer re-exported by :mod:`heli_env.env`; the observation and
action layout left :mod:`heli_env.spec` for :mod:`heli_env.observation` (the kernels need the layout, not the
spec). The
old names keep working until :data:`heli_core.deprecation.REMOVAL`, answered by the mechanism every package
shares (:class:`heli_core.deprecation.Deprecations`; ``heli_env/__init__.py`` installs it).

First-party code never imports an old name: ``scripts/structure_report.py`` reads the two tables below and
fails when it finds one.
"""

from __future__ import annotations

MOVED_MODULES: dict[str, tuple[str, ...]] = {
    "heli_env.model_dir": ("heli_env.env_model",),
}
"""Old module -> the modules its public names live in now, searched in this order."""

MOVED_NAMES: dict[str, dict[str, str]] = {
    "heli_env.env": {"OBS_DIM": "heli_env.observation"},
    "heli_env.spec": {"MAX_RATE": "heli_env.observation", "OBS_DIM": "heli_env.observation",
                      "action_space": "heli_env.observation", "observation_space": "heli_env.observation"},
}
"""Module that stays -> {old name it re-exported: the module that defines it}."""
