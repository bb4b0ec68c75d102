"""Old homes of moved names, kept for one release with a ``DeprecationWarning``: the one mechanism every package
uses (issue 34).

A package whose names moved keeps two tables, and nothing else, in its ``_deprecated`` module
(``identification/_deprecated.py``, ``controllers/_deprecated.py``, ``heli_env/_deprecated.py``); this module
reads them by that name (:func:`deprecations`) into one :class:`Deprecations`, so that the tables import
nothing and a module answering for old names imports only this one:

* ``MOVED_MODULES``, old module -> the modules its public names live in now, searched in order. An old module
  that no longer exists as a file (``identification.ml_estimator``, ``controllers.residual``) is imported as an
  alias module made here (:class:`_Finder`, installed once per process); each name read from it is looked up in
  its new homes and warns, naming the module to import it from. An old module whose name is now a folder
  (``identification.disturbance``) answers its old names from the folder's ``__getattr__``, which asks
  :meth:`Deprecations.moved_name`.
* ``MOVED_NAMES``, module that stays -> {old name it re-exported: the module that defines it}
  (``identification.errors`` re-exported :mod:`heli_core.errors`' classes; ``controllers.evaluate`` its report's
  tables): the module's ``__getattr__`` (:func:`module_getattr`) asks :meth:`Deprecations.moved_name` for those
  names only.

A package installs its table (``install(__name__)`` in its ``__init__``) and takes ``module_getattr(__name__)``
as its own ``__getattr__``, which also answers an old module read as an attribute (``identification.fleet``).

A method of a result whose work moved to its report (a result never imports its report: issue 34) answers for
one release through :func:`moved_method`, which warns and calls the report's function.

First-party code never imports an old name: ``scripts/structure_report.py`` reads the tables (without importing
them) and fails when it finds one.
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


def _warn(old: str, name: str, home: str, removal: str, stacklevel: int) -> None:
    warnings.warn(f"{old}.{name} is deprecated: import {name} from {home} (the old name goes in {removal})",
                  DeprecationWarning, stacklevel=stacklevel + 1)


def moved_method(old: str, home: str, function: str, *args, removal: str = REMOVAL, **kwargs):
    """What a deprecated method ``old`` (``"EvaluationResult.markdown"``) did: ``home.function(*args,
    **kwargs)``, with a ``DeprecationWarning`` naming the function to call.

    A result class keeps no import of its report (issue 34: algorithm -> result <- report); the method it had
    to render itself calls this for one release, and the report module is imported here, by name, as the
    moved names of the tables are.
    """
    warnings.warn(f"{old}() is deprecated: call {home}.{function}() (the method goes in {removal})",
                  DeprecationWarning, stacklevel=2)
    return getattr(importlib.import_module(home), function)(*args, **kwargs)


_DEFINED: dict = {}


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


class Deprecations:
    """The old names of one package (module docstring).

    Parameters
    ----------
    package : str
        The package whose old names these are (``"identification"``).
    moved_modules : dict of str to tuple of str
        Old module -> the modules its public names live in now, searched in this order.
    moved_names : dict of str to dict of str to str
        Module that stays -> {old name it re-exported: the module that defines it}.
    removal : str
        The release that removes the old names.
    """

    def __init__(self, package: str, moved_modules: dict, moved_names: dict, removal: str = REMOVAL):
        self.package = package
        self.moved_modules = moved_modules
        self.moved_names = moved_names
        self.removal = removal

    def moved_name(self, old: str, name: str, stacklevel: int = 2):
        """The object old module ``old`` offered as ``name``, from its new home, with a ``DeprecationWarning``.

        Raises
        ------
        AttributeError
            ``old`` had no such public name (as a module's ``__getattr__`` must, so that ``from package import
            submodule`` still finds a submodule).
        """
        if name in self.moved_names.get(old, {}):
            home = self.moved_names[old][name]
            _warn(old, name, home, self.removal, stacklevel + 1)
            return getattr(importlib.import_module(home), name)
        if not name.startswith("_"):
            homes = [importlib.import_module(home) for home in self.moved_modules.get(old, ())]
            holding = [m for m in homes if name in vars(m)]
            if holding:  # named by the module that defines it: among the homes, else a function's or class's own
                module = next((m for m in holding if _defines(m, name)), holding[0])
                obj = vars(module)[name]
                own = getattr(obj, "__module__", None)
                home = module.__name__ if _defines(module, name) or not isinstance(own, str) else own
                _warn(old, name, home, self.removal, stacklevel + 1)
                return obj
        raise AttributeError(f"module {old!r} has no attribute {name!r}")

    def attribute(self, module: str, name: str):
        """What ``module.name`` was before the move: an old module of the package (``identification.fleet``)
        or a moved name (:meth:`moved_name`)."""
        if f"{module}.{name}" in self.moved_modules:
            return importlib.import_module(f"{module}.{name}")
        return self.moved_name(module, name, stacklevel=3)


_TABLES: dict[str, Deprecations] = {}


def deprecations(package: str) -> Deprecations:
    """The old names of ``package``, read from the tables of ``<package>._deprecated`` (once per process)."""
    if package not in _TABLES:
        tables = importlib.import_module(f"{package}._deprecated")
        _TABLES[package] = Deprecations(package, tables.MOVED_MODULES, tables.MOVED_NAMES,
                                        getattr(tables, "REMOVAL", REMOVAL))
    return _TABLES[package]


def module_getattr(module: str):
    """A ``__getattr__`` for ``module`` (a package, a module that stays, or a folder that took an old module's
    name): its old names and old submodules (:meth:`Deprecations.attribute`)."""
    table = deprecations(module.split(".")[0])

    def __getattr__(name):
        return table.attribute(module, name)

    return __getattr__


def install(package: str) -> None:
    """Let ``import <package>.<old module>`` find its alias, before any other finder (an editable install's
    finder would otherwise look for the old file in the source tree). Once per package and process."""
    _FINDER.tables[package] = deprecations(package)
    if _FINDER not in sys.meta_path:
        sys.meta_path.insert(0, _FINDER)


class _OldModule(types.ModuleType):
    """An old module of a ``MOVED_MODULES`` table: every name read from it comes from its new home, with a
    warning."""

    def __init__(self, name: str, table: Deprecations):
        super().__init__(name, f"Deprecated: the names of {name} now live in "
                               f"{', '.join(table.moved_modules[name])} (removed in {table.removal}).")
        self.__dict__["_table"] = table

    def __getattr__(self, name):
        return self.__dict__["_table"].moved_name(self.__name__, name)

    def __dir__(self):
        table = self.__dict__["_table"]
        return sorted({n for home in table.moved_modules[self.__name__]
                       for n in vars(importlib.import_module(home)) if not n.startswith("_")})


class _Loader(importlib.abc.Loader):
    def __init__(self, table: Deprecations):
        self.table = table

    def create_module(self, spec):
        return _OldModule(spec.name, self.table)

    def exec_module(self, module):
        pass


class _Finder(importlib.abc.MetaPathFinder):
    """Finds the old modules of the installed tables that no longer exist as files."""

    def __init__(self):
        self.tables: dict[str, Deprecations] = {}

    def find_spec(self, fullname, path=None, target=None):
        table = self.tables.get(fullname.split(".")[0])
        if (table is None or fullname not in table.moved_modules
                or importlib.machinery.PathFinder.find_spec(fullname, path)):
            return None  # not an old name, or a real module or package of that name (a stage's folder)
        return importlib.machinery.ModuleSpec(fullname, _Loader(table))


_FINDER = _Finder()
