"""How the house reads: module sizes, long functions and long argument lists, layering and import depth.

The figures of the redesign (issue 14) are measured here, not counted by hand:

* modules over ``--max-lines`` lines (default 600) and functions over ``--max-function`` lines (default 80,
  from the ``def`` line to the end of the body);
* functions taking more than ``--max-args`` settings (default 8; ``self``/``cls`` and ``*args``/``**kwargs``
  not counted). Such a function should take a configuration object (:mod:`heli_core.config`) or a small
  dataclass of what belongs together. The constructors of scikit-learn-style estimators (a class with a
  ``fit`` method) and of Gymnasium environments (a class on ``Env`` or ``VectorEnv``) are listed apart,
  as "estimator/env constructors, keyword hyperparameters by convention", and not counted: those
  libraries want each hyperparameter as a keyword of ``__init__`` (scikit-learn's ``get_params`` and
  ``set_params`` read the signature, ``gymnasium.make`` passes keywords), so the figure printed is that
  of the functions a config object would improve;
* the package imports: every absolute import between the packages, the ones that go *upward* (against
  the data flow ``heli_core -> model_store -> identification -> heli_env -> controllers -> heli_cli``; none
  allowed, except that ``heli_env`` may import only ``heli_core`` and ``model_store``), the import depth
  of each package (the longest chain of package-to-package imports below it) and of the modules (the longest
  chain of first-party module imports that visits no module twice: imports inside functions and under
  ``if TYPE_CHECKING:`` count, a package's ``__init__`` is a module of its own, and ``from pkg import
  name`` is an import of ``pkg``'s ``__init__`` as well as of ``pkg.name`` when that is a module;
  issue 14 asked for 11 or fewer, issue 34 for 10 or fewer), printed with the chain itself;
* how many modules import each module from another package (fan-in);
* first-party imports of a deprecated name: an old module or name of a package's deprecation tables
  (:data:`DEPRECATION_TABLES`: ``MOVED_MODULES``, old module -> its new homes, and ``MOVED_NAMES``, module ->
  names it re-exported), e.g. ``from identification.ml_estimator import ...`` or ``from identification.errors
  import ModelFileError``. A moved name has one home, and first-party code imports it from there;
* import circles between files: the groups of modules that import each other, directly or through others
  (strongly connected components of the module imports counted as above). Issue 34 asks for none: inside a
  package the direction holds too (algorithm -> result (plain data) <- report, the workflow or CLI on top);
* shim modules still in the tree (a module of imports only, re-exporting another module's names) and the
  first-party modules importing them, listed for a package that has no deprecation table yet.

Usage::

    python scripts/structure_report.py [--max-lines 600] [--max-function 80] [--max-args 8]

Exit status 1 when an upward import, an import circle, a first-party import of a deprecated name or a first-party
import of a shim module exists (so a script, CI and ``tests/test_structure_report.py`` can rely on it), 0 otherwise.
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("heli_core", "model_store", "identification", "heli_env", "controllers", "heli_cli")
"""The packages in the order data flows through them; each may import only those before it."""
ALLOWED = {"heli_env": {"heli_core", "model_store"}}
"""Packages that may import fewer than all those before them."""
DEPRECATION_TABLES = ("identification/_deprecated.py", "controllers/_deprecated.py", "heli_env/_deprecated.py",
                      "model_store/_deprecated.py")
"""Modules holding a package's old names (``MOVED_MODULES`` and ``MOVED_NAMES`` dictionaries)."""


def _modules():
    for pkg in LAYERS:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            yield pkg, path


def _dotted(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _from_module(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    """The absolute module a ``from ... import`` in ``module`` (a package's ``__init__`` when ``is_package``)
    reads from, its relative dots resolved."""
    if not node.level:
        return node.module or ""
    base = module.split(".")
    base = base[: len(base) - node.level + (1 if is_package else 0)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(tree: ast.AST, module: str, is_package: bool) -> set[str]:
    """Absolute names of the modules ``tree`` imports (relative imports resolved)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            name = _from_module(node, module, is_package)
            out.add(name)
            out.update(f"{name}.{alias.name}" for alias in node.names)  # a submodule imported by name
    return out


ENV_BASES = {"Env", "VectorEnv"}
"""Base classes that make a class a Gymnasium environment (``gym.Env``, ``gymnasium.vector.VectorEnv``)."""


def _keyword_hyperparameters(cls: ast.ClassDef) -> bool:
    """A scikit-learn-style estimator (it has a ``fit`` method) or a Gymnasium environment (a base in
    :data:`ENV_BASES`): its ``__init__`` takes each hyperparameter by keyword, by those libraries' convention."""
    methods = {n.name for n in cls.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
    bases = {b.attr if isinstance(b, ast.Attribute) else getattr(b, "id", None) for b in cls.bases}
    return "fit" in methods or bool(bases & ENV_BASES)


def _functions(tree: ast.AST):
    """(qualified name, first line, lines, settings, by convention) of every function and method; the last is
    True for the constructor of an estimator or environment (:func:`_keyword_hyperparameters`)."""
    def walk(node, prefix, convention=False):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = child.args
                names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
                settings = len([n for n in names if n not in ("self", "cls")])
                yield (f"{prefix}{child.name}", child.lineno, child.end_lineno - child.lineno + 1, settings,
                       convention and child.name == "__init__")
                yield from walk(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                yield from walk(child, f"{prefix}{child.name}.", _keyword_hyperparameters(child))
    yield from walk(tree, "")


def _deprecation_tables() -> tuple[dict, dict, set]:
    """``(moved_modules, moved_names, table modules)`` of :data:`DEPRECATION_TABLES`, read without importing."""
    modules, names, homes = {}, {}, set()
    for rel in DEPRECATION_TABLES:
        path = ROOT / rel
        if not path.exists():
            continue
        homes.add(_dotted(path))
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            target = node.target if isinstance(node, ast.AnnAssign) else (
                node.targets[0] if isinstance(node, ast.Assign) else None)
            if isinstance(target, ast.Name) and target.id == "MOVED_MODULES":
                modules.update(ast.literal_eval(node.value))
            elif isinstance(target, ast.Name) and target.id == "MOVED_NAMES":
                names.update(ast.literal_eval(node.value))
    return modules, names, homes


def _deprecated_imports(tree: ast.AST, module: str, is_package: bool, known: set, tables) -> list[str]:
    """The deprecated names ``tree`` imports, as ``"line: old.name"``."""
    moved_modules, moved_names, _ = tables
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [f"{node.lineno}: {a.name}" for a in node.names
                      if a.name in moved_modules and a.name not in known]
        elif isinstance(node, ast.ImportFrom):
            src = _from_module(node, module, is_package)
            for alias in node.names:
                sub = f"{src}.{alias.name}"
                old_module = src in moved_modules and src not in known  # an old module of no file
                old_in_folder = src in moved_modules and src in known and sub not in known  # a folder's old name
                if (old_module or old_in_folder or alias.name in moved_names.get(src, {})
                        or (sub in moved_modules and sub not in known)):
                    found.append(f"{node.lineno}: {sub}")
    return found


def _is_shim(tree: ast.AST) -> bool:
    """A module of a docstring, imports of first-party names and ``__all__`` only: a re-export."""
    body = [n for n in tree.body if not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))]
    imports = [n for n in body if isinstance(n, (ast.Import, ast.ImportFrom))]
    first_party = [n for n in imports if isinstance(n, ast.ImportFrom) and
                   (n.level or (n.module or "").split(".")[0] in LAYERS)]
    rest = [n for n in body if n not in imports and not (
        isinstance(n, ast.Assign) and all(isinstance(t, ast.Name) for t in n.targets)
        and (any(t.id == "__all__" for t in n.targets) or isinstance(n.value, ast.Name)))]
    return bool(first_party) and not rest


def _circles(edges: dict) -> list[list[str]]:
    """The import circles of ``edges`` (module -> modules it imports): each group of two or more modules that
    reach one another, sorted, the groups in order (Tarjan's strongly connected components, iteratively)."""
    index, low, on_stack, stack, groups = {}, {}, set(), [], []
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges.get(root, ()))))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                group = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    group.append(m)
                    if m == node:
                        break
                if len(group) > 1:
                    groups.append(sorted(group))
    return sorted(groups)


def measure():
    """Everything the report prints, as data (for tests and for the printout)."""
    sizes, functions, edges, by_convention = {}, [], defaultdict(set), set()
    fan_in = Counter()
    known = {_dotted(p) for _, p in _modules()}
    module_edges = defaultdict(set)  # first-party module -> first-party modules it imports
    tables = _deprecation_tables()
    deprecated, shims = {}, set()
    for pkg, path in _modules():
        text = path.read_text(encoding="utf-8")
        tree = ast.parse(text)
        module = _dotted(path)
        sizes[module] = text.count("\n") + (not text.endswith("\n"))
        for name, line, n, settings, convention in _functions(tree):
            functions.append((module, name, line, n, settings))
            if convention:
                by_convention.add(f"{module}.{name}")
        if module not in tables[2]:
            found = _deprecated_imports(tree, module, path.name == "__init__.py", known, tables)
            if found:
                deprecated[module] = found
        if path.name != "__init__.py" and _is_shim(tree):  # a package's facade is no shim
            shims.add(module)
        for imp in _imports(tree, module, path.name == "__init__.py"):
            if imp in known and imp != module:
                module_edges[module].add(imp)
            top = imp.split(".")[0]
            if top in LAYERS and top != pkg:
                edges[pkg].add(top)
                if imp in known:
                    fan_in[imp] += 1
    upward = sorted((a, b) for a, bs in edges.items() for b in bs
                    if b not in ALLOWED.get(a, set(LAYERS[: LAYERS.index(a)])))

    def depth(pkg, seen=()):
        below = [b for b in edges.get(pkg, ()) if b not in seen]
        return 1 + max((depth(b, seen + (pkg,)) for b in below), default=0)

    def reaches(start):
        seen, todo = set(), list(module_edges.get(start, ()))
        while todo:
            m = todo.pop()
            if m not in seen:
                seen.add(m)
                todo.extend(module_edges.get(m, ()))
        return seen

    in_cycle = {m for m in known if m in reaches(m)}
    memo = {}

    def module_chain(mod, stack=()):
        """Longest chain of first-party imports below ``mod`` (``mod`` first) that visits no module twice (a
        cycle is cut where it closes). Only a module on no cycle is remembered: what lies below it cannot
        include the modules above it, so its chain is the same whatever the path to it (remembering one on a
        cycle made the figure depend on the order the modules were visited in)."""
        if mod in memo:
            return memo[mod]
        below = [module_chain(m, stack + (mod,)) for m in sorted(module_edges.get(mod, ())) if m not in stack]
        chain = (mod,) + max(below, key=len, default=())
        if mod not in in_cycle:
            memo[mod] = chain
        return chain

    chains = {m: module_chain(m) for m in sorted(known)}
    depths = {m: len(c) for m, c in chains.items()}
    deprecated.update(_outside_imports(known, tables))
    outside = _outside_edges(known)
    shim_users = {shim: sorted(m for m, below in {**module_edges, **outside}.items() if shim in below)
                  for shim in sorted(shims)}
    deepest = max(depths, key=depths.get)
    return {"sizes": sizes, "functions": functions, "by_convention": by_convention,
            "edges": {k: sorted(v) for k, v in edges.items()},
            "upward": upward, "depth": {p: depth(p) for p in LAYERS}, "fan_in": fan_in,
            "module_depth": depths[deepest], "deepest_module": deepest, "deepest_chain": chains[deepest],
            "deprecated": deprecated, "shims": shim_users, "circles": _circles(module_edges)}


def _outside_files():
    for folder in ("scripts", "tests"):
        yield from sorted((ROOT / folder).rglob("*.py"))


def _outside_edges(known: set) -> dict:
    """File of ``scripts/`` or ``tests/`` -> the first-party modules it imports."""
    return {str(path.relative_to(ROOT)): {imp for imp in _imports(ast.parse(path.read_text(encoding="utf-8")),
                                                                   _dotted(path), False) if imp in known}
            for path in _outside_files()}


def _outside_imports(known: set, tables) -> dict:
    """:func:`_deprecated_imports` of the first-party code outside the packages (``scripts/``, ``tests/``)."""
    out = {}
    for path in _outside_files():
        found = _deprecated_imports(ast.parse(path.read_text(encoding="utf-8")), _dotted(path), False, known, tables)
        if found:
            out[str(path.relative_to(ROOT))] = found
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--max-lines", type=int, default=600)
    ap.add_argument("--max-function", type=int, default=80)
    ap.add_argument("--max-args", type=int, default=8)
    args = ap.parse_args(argv)
    m = measure()
    sizes = m["sizes"]
    print(f"Command: python scripts/structure_report.py --max-lines {args.max_lines} --max-function "
          f"{args.max_function} --max-args {args.max_args}\n")
    print(f"{len(sizes)} modules, {sum(sizes.values())} lines; median {sorted(sizes.values())[len(sizes) // 2]} lines")
    big = sorted(((n, mod) for mod, n in sizes.items() if n > args.max_lines), reverse=True)
    print(f"\nModules over {args.max_lines} lines: {len(big)}")
    for n, mod in big:
        print(f"  {n:5d}  {mod}")
    long_f = sorted(((n, f"{mod}.{name}") for mod, name, _, n, _ in m["functions"] if n > args.max_function),
                    reverse=True)
    print(f"\nFunctions over {args.max_function} lines: {len(long_f)}")
    for n, name in long_f:
        print(f"  {n:5d}  {name}")
    many = sorted(((k, f"{mod}.{name}") for mod, name, _, _, k in m["functions"] if k > args.max_args),
                  reverse=True)
    apart = [(k, name) for k, name in many if name in m["by_convention"]]
    counted = [(k, name) for k, name in many if name not in m["by_convention"]]
    print(f"\nFunctions taking more than {args.max_args} settings: {len(counted)}")
    for k, name in counted:
        print(f"  {k:5d}  {name}")
    print(f"\nEstimator/env constructors, keyword hyperparameters by convention: {len(apart)}")
    for k, name in apart:
        print(f"  {k:5d}  {name}")
    print("\nPackage imports (data flows left to right: " + " -> ".join(LAYERS) + ")")
    for pkg in LAYERS:
        print(f"  {pkg:15s} imports {', '.join(m['edges'].get(pkg, [])) or 'no package of ours'}"
              f"  (depth {m['depth'][pkg]})")
    print(f"\nModule import depth: {m['module_depth']} levels (the longest chain of first-party imports, below "
          f"{m['deepest_module']}):\n  " + " -> ".join(m["deepest_chain"]))
    print(f"\nUpward imports: {len(m['upward'])}" + "".join(f"\n  {a} -> {b}" for a, b in m["upward"]))
    print(f"\nImport circles between files: {len(m['circles'])}" + "".join(
        f"\n  {' <-> '.join(group)}" for group in m["circles"]))
    print("\nMost imported modules from other packages:")
    for mod, n in m["fan_in"].most_common(10):
        print(f"  {n:4d}  {mod}")
    n_deprecated = sum(len(v) for v in m["deprecated"].values())
    print(f"\nFirst-party imports of a deprecated name ({', '.join(DEPRECATION_TABLES)}): {n_deprecated}")
    for where, found in sorted(m["deprecated"].items()):
        for item in found:
            print(f"  {where}:{item}")
    print(f"\nShim modules (imports only, re-exporting other modules' names): {len(m['shims'])}")
    for shim, users in m["shims"].items():
        print(f"  {shim}" + (f"  <- {', '.join(users)}" if users else ""))
    used = {shim: users for shim, users in m["shims"].items() if users}
    return 1 if m["upward"] or m["circles"] or m["deprecated"] or used else 0


if __name__ == "__main__":
    sys.exit(main())
