"""The old homes of identification's names, kept for one release with a ``DeprecationWarning`` (issue 34).

Until issue 34 :mod:`identification` was one flat room of modules, some of them re-exports of names that
had moved (``identification.model`` of :mod:`heli_core`, ``identification.files`` of
:mod:`heli_core.files`, ``identification.model_file`` of :mod:`model_store.model_file`, ...). Each stage now
has a folder and each name one home. Code written against the old names keeps working until
:data:`heli_core.deprecation.REMOVAL`: this module is the only place that knows them, and
:class:`heli_core.deprecation.Deprecations` (the mechanism every package shares) answers for them.

* An old module that no longer exists (``identification.ml_estimator``) is imported as an alias module
  (installed by ``identification/__init__.py``); each name read from it is looked up in its new homes
  (:data:`MOVED_MODULES`) and warns, naming the module to import it from.
* An old module whose name is now a stage's folder (``identification.disturbance``,
  ``identification.validation``, ``identification.bench``) answers its old names from the folder's
  ``__getattr__``.
* A module that stays but lent its name to others' names (``identification.errors`` re-exported the errors
  of :mod:`heli_core.errors` and :mod:`model_store.errors`) does the same for those names only
  (:data:`MOVED_NAMES`).

First-party code never imports an old name: ``scripts/structure_report.py`` reads the two tables below and
fails when it finds one (``tests/test_structure_report.py`` runs it).
"""

from __future__ import annotations

MOVED_MODULES: dict[str, tuple[str, ...]] = {
    # the shims of earlier moves: the physics core, the term library, files, backends, the model folder
    "identification.model": ("heli_core.params", "heli_core.physics", "heli_core.discrete", "heli_core.servo",
                             "heli_core.quaternion"),
    "identification.terms": ("heli_core.terms",),
    "identification.files": ("heli_core.files",),
    "identification.backends": ("heli_core.backends",),
    "identification.model_file": ("model_store.model_file",),
    "identification.disturbance_library": ("model_store.disturbance_library",),
    # integral/
    "identification.integral_method": ("identification.integral.method", "identification.integral.axis"),
    "identification.integral_axis": ("identification.integral.axis",),
    "identification.interval_integrals": ("identification.integral.intervals",),
    "identification.bootstrap": ("identification.integral.bootstrap",),
    # likelihood/
    "identification.ml_estimator": ("identification.likelihood.estimator", "identification.likelihood.axis_search"),
    "identification.ml_axis_fit": ("identification.likelihood.axis_fit",),
    "identification.axis_likelihood": ("identification.likelihood.axis_likelihood",),
    "identification.state_space": ("identification.likelihood.state_space",),
    "identification.servo_lag": ("identification.likelihood.servo_lag",),
    "identification.input_hold": ("identification.likelihood.input_hold",),
    "identification.axis_pool": ("identification.likelihood.axis_pool",),
    "identification.ahead_prediction": ("identification.likelihood.ahead_prediction",),
    # disturbance/ (the old module's name is now the folder's)
    "identification.disturbance": ("identification.disturbance.equivalent_input", "identification.disturbance.profile",
                                   "identification.disturbance.smoothing", "identification.reports.disturbance"),
    "identification.disturbance_smoothing": ("identification.disturbance.smoothing",),
    "identification.wind_posterior": ("identification.disturbance.wind_posterior",),
    # validation/ (the old module's name is now the folder's)
    "identification.validation": ("identification.validation.forward_simulation", "identification.validation.result",
                                  "identification.reports.validation"),
    "identification.validation_result": ("identification.validation.result",),
    "identification.validation_flights": ("identification.validation.other_flights",),
    "identification.frequency_response": ("identification.validation.frequency_response",),
    "identification.model_verdict": ("identification.validation.model_verdict",),
    "identification.fit_warnings": ("identification.validation.fit_warnings", "identification.excitation"),
    "identification.parameter_drift": ("identification.validation.parameter_drift",),
    # diagnosis/
    "identification.effects": ("identification.diagnosis.effects", "identification.preprocess"),
    "identification.heldout": ("identification.diagnosis.heldout",),
    "identification.residual_tests": ("identification.diagnosis.residual_tests",),
    "identification.diagnose": ("identification.diagnosis.heldout_diagnoser",),
    "identification.ml_diagnosis": ("identification.diagnosis.likelihood_diagnoser",
                                    "identification.diagnosis.axis_scores"),
    "identification.alignment_check": ("identification.diagnosis.alignment_check",),
    # bench/ (the old module's name is now the folder's)
    "identification.bench": ("identification.bench.cells", "identification.bench.flight_config",
                             "identification.bench.synthetic"),
    "identification.synthetic": ("identification.bench.synthetic", "identification.bench.flight_config"),
    "identification.method_comparison": ("identification.bench.method_comparison",
                                         "identification.bench.comparison_config", "identification.bench.method_runs"),
    "identification.method_runs": ("identification.bench.method_runs",),
    # reports/
    "identification.figures": ("identification.reports.figures",),
    "identification.markdown_tables": ("identification.reports.tables",),
    "identification.identify_report": ("identification.reports.identify",),
    "identification.validation_report": ("identification.reports.validation",),
    "identification.disturbance_report": ("identification.reports.disturbance",),
    "identification.frequency_response_report": ("identification.reports.frequency_response",),
    "identification.diagnose_report": ("identification.reports.diagnosis", "identification.workflows.diagnose"),
    "identification.ml_diagnosis_report": ("identification.reports.likelihood_diagnosis",
                                           "identification.workflows.diagnose"),
    "identification.refresh_report": ("identification.reports.refresh",),
    "identification.method_comparison_report": ("identification.reports.method_comparison",),
    # workflows/
    "identification.report": ("identification.workflows.identify", "identification.reports.identify"),
    "identification.refresh": ("identification.workflows.refresh", "identification.workflows.refresh_result",
                               "identification.workflows.refresh_sources", "identification.validation.parameter_drift"),
    "identification.refresh_validation": ("identification.workflows.refresh_validation",),
    "identification.fleet": ("identification.workflows.fleet",),
}
"""Old module -> the modules its public names live in now, searched in this order."""

MOVED_NAMES: dict[str, dict[str, str]] = {
    "identification.errors": {
        "HeliError": "heli_core.errors", "MissingDependency": "heli_core.errors", "BackendError": "heli_core.errors",
        "TaskFailed": "heli_core.errors", "require": "heli_core.errors", "LibraryError": "model_store.errors",
        "ModelDirBusyError": "model_store.errors", "ModelDirError": "model_store.errors",
        "ModelFileError": "model_store.errors",
    },
    # the paper's table settings are data of their own, and the percentile convention a leaf both tables share
    "identification.baselines.ekf": {
        "TABLE4_M0": "identification.baselines.paper_tables", "TABLE4_Q": "identification.baselines.paper_tables",
        "TABLE5_LENGTHS": "identification.baselines.paper_tables",
    },
    "identification.baselines.nlr": {"TABLE3_STARTS": "identification.baselines.paper_tables"},
    "identification.diagnosis.alignment_check": {"STABILISED_NOTE": "identification.reports.identify"},
    "identification.io.ardupilot": {"vehicle_of": "identification.io.ardupilot_vehicle"},
    "identification.validation.fit_warnings": {
        "AHEAD_LABEL": "identification.validation.judged_fit", "judged_r2": "identification.validation.judged_fit",
    },
    "identification.likelihood.ahead_prediction": {
        "AHEAD_S": "identification.likelihood.ahead_score", "DIVERGED": "identification.likelihood.ahead_score",
        "DIVERGED_R2": "identification.likelihood.ahead_score", "is_diverged": "identification.likelihood.ahead_score",
        "format_r2": "identification.likelihood.ahead_score",
    },
    "identification.validation.forward_simulation": {"PERCENTILE_METHOD": "identification.percentile"},
}
"""Module that stays -> {old name it re-exported: the module that defines it}."""
