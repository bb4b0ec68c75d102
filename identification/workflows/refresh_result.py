"""What a refresh found and wrote, as data: :class:`RefreshResult`.

:func:`identification.workflows.refresh.refresh_model` returns it, and ``refresh.md`` is drawn from it by
:mod:`identification.reports.refresh`, which therefore imports this module and not the refresh.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..integral.bootstrap import BootstrapResult


@dataclass
class RefreshResult:
    """What :func:`refresh_model` found and wrote.

    Attributes
    ----------
    drift : list of ParameterDrift
    criterion : dict
        ``alpha``, ``z``, ``n_parameters``, ``min_relative`` and the rule in words.
    fit : str
        ``"pooled"`` (previous + new flights) or ``"new"`` (new flights alone).
    reason : str
        Why that fit was chosen.
    previous_flights : dict
        ``found`` (list of {file, sha256, path}) and ``missing`` (list of {file, sha256}).
    bootstrap_new, bootstrap_old, bootstrap_model : BootstrapResult or None
        New flights; previous flights (when at hand); the written model.
    run : IdentificationRun
        The identification that wrote ``model.json``, ``report.md`` and the library version.
    library_version : int or None
    paths : dict of str to Path
    """

    drift: list
    criterion: dict
    fit: str
    reason: str
    previous_flights: dict
    bootstrap_new: BootstrapResult
    bootstrap_old: BootstrapResult | None
    bootstrap_model: BootstrapResult
    run: object
    library_version: int | None
    paths: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    @property
    def flagged(self) -> list[str]:
        """Names of the parameters whose change is significant."""
        return [row.name for row in self.drift if row.flagged]
