"""The old homes of identification's names, kept for one release with a ``DeprecationWarning`` (issue 34).

Until issue 34 :mod:`identification` was one flat room of modules, some of them re-exports of names that
had moved (``identification.model`` of :mod:`heli_core`, ``identification.files`` of
:mod:`heli_core.files`, ``identification.model_file`` of :mod:`model_store.model_file`, ...). Each stage now
has a folder and each name one home. Code written against the old names keeps working until
:data:`REMOVAL`: this module is the only place that knows them.

* An old module that no longer exists (``identification.ml_estimator``) is imported as an alias module made
  here (:class:`_Finder`, installed by ``identification/__init__.py``); each name read from it is looked up
  in its new homes (:data:`MOVED_MODULES`) and warns, naming the module to import it from.
* An old module whose name is now a stage's folder (``identification.disturbance``,
  ``identification.validation``, ``identification.bench``) answers its old names from the folder's
  ``__getattr__``, which asks :func:`moved_name`.
* A module that stays but lent its name to others' names (``identification.errors`` re-exported the errors
  of :mod:`heli_core.errors` and :mod:`model_store.errors`) does the same for those names only
  (:data:`MOVED_NAMES`).

First-party code never imports an old name: ``scripts/structure_report.py`` reads the two tables below and
fails when it finds one (``tests/test_structure_report.py`` runs it).
"""

from __future__ import annotations

import ast
import importlib
import importlib.abc
import importlib.machinery
import sys
import types
import warnings

REMOVAL = "0.2.0"
"""The release that removes the old names."""

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
}
"""Module that stays -> {old name it re-exported: the module that defines it}."""


def _warn(old: str, name: str, home: str, stacklevel: int) -> None:
    warnings.warn(f"{old}.{name} is deprecated: import {name} from {home} (the old name goes in {REMOVAL})",
                  DeprecationWarning, stacklevel=stacklevel + 1)


def _defines(module, name: str) -> bool:
    """Whether ``module``'s own source assigns or defines ``name`` at its top level (not imports it)."""
    path = getattr(module, "__file__", None)
    if path not in _DEFINED:
        names = set()
        if path:
            with open(path, encoding="utf-8") as f:
                for node in ast.parse(f.read()).body:
                    targets = (node.targets if isinstance(node, ast.Assign) else
                               [node.target] if isinstance(node, ast.AnnAssign) else [])
                    names.update(t.id for t in targets if isinstance(t, ast.Name))
                    if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                        names.add(node.name)
        _DEFINED[path] = names
    return name in _DEFINED[path]


_DEFINED: dict = {}


def moved_name(old: str, name: str, stacklevel: int = 2):
    """The object old module ``old`` offered as ``name``, from its new home, with a ``DeprecationWarning``.

    Raises
    ------
    AttributeError
        ``old`` had no such public name (as a module's ``__getattr__`` must, so that ``from package import
        submodule`` still finds a submodule).
    """
    if name in MOVED_NAMES.get(old, {}):
        home = MOVED_NAMES[old][name]
        _warn(old, name, home, stacklevel + 1)
        return getattr(importlib.import_module(home), name)
    if not name.startswith("_"):
        homes = [importlib.import_module(home) for home in MOVED_MODULES.get(old, ())]
        holding = [m for m in homes if name in vars(m)]
        if holding:  # named by the module that defines it: among the homes, else a function's or class's own
            module = next((m for m in holding if _defines(m, name)), holding[0])
            obj = vars(module)[name]
            own = getattr(obj, "__module__", None)
            home = module.__name__ if _defines(module, name) or not isinstance(own, str) else own
            _warn(old, name, home, stacklevel + 1)
            return obj
    raise AttributeError(f"module {old!r} has no attribute {name!r}")


class _OldModule(types.ModuleType):
    """An old module of :data:`MOVED_MODULES`: every name read from it comes from its new home, with a warning."""

    def __getattr__(self, name):
        return moved_name(self.__name__, name)

    def __dir__(self):
        return sorted({n for home in MOVED_MODULES[self.__name__]
                       for n in vars(importlib.import_module(home)) if not n.startswith("_")})


class _Loader(importlib.abc.Loader):
    def create_module(self, spec):
        return _OldModule(spec.name, f"Deprecated: the names of {spec.name} now live in "
                                     f"{', '.join(MOVED_MODULES[spec.name])} (removed in {REMOVAL}).")

    def exec_module(self, module):
        pass


class _Finder(importlib.abc.MetaPathFinder):
    """Finds the old modules of :data:`MOVED_MODULES` that no longer exist as files."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in MOVED_MODULES or importlib.machinery.PathFinder.find_spec(fullname, path):
            return None  # not an old name, or a real module or package of that name (a stage's folder)
        return importlib.machinery.ModuleSpec(fullname, _Loader())


def install() -> None:
    """Let ``import identification.<old module>`` find its alias (once per process), before any other finder
    (an editable install's finder would otherwise look for the old file in the source tree)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.insert(0, _Finder())


def old_module(name: str):
    """``identification.<name>`` for an old module name read as an attribute of :mod:`identification`."""
    if f"identification.{name}" in MOVED_MODULES:
        return importlib.import_module(f"identification.{name}")
    raise AttributeError(f"module 'identification' has no attribute {name!r}")
