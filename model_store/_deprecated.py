"""The old homes of model_store's names, kept for one release with a ``DeprecationWarning`` (issue 34).

:mod:`model_store.verdict` is the verdict as plain data; reading it from a model document
(:func:`~model_store.model_file.verdict_of`, a malformed entry a ``ModelFileError`` naming the file) and refusing
an unusable model (:func:`~model_store.model_file.require_usable`) moved to :mod:`model_store.model_file`, the
file format that raises the store's errors. The old names keep working until
:data:`heli_core.deprecation.REMOVAL`, answered by the mechanism every package shares
(:class:`heli_core.deprecation.Deprecations`; :mod:`model_store.verdict` takes ``module_getattr``).

First-party code never imports an old name: ``scripts/structure_report.py`` reads the two tables below and
fails when it finds one.
"""

from __future__ import annotations

MOVED_MODULES: dict[str, tuple[str, ...]] = {}
"""Old module -> the modules its public names live in now, searched in this order."""

MOVED_NAMES: dict[str, dict[str, str]] = {
    "model_store.verdict": {"verdict_of": "model_store.model_file", "require_usable": "model_store.model_file"},
}
"""Module that stays -> {old name it re-exported: the module that defines it}."""
