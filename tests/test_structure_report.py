"""scripts/structure_report.py as a check: it fails (exit 1) when first-party code imports a deprecated name.

A moved name has one home (issue 34): code of this project imports it from the module that defines it, never
through an old module or name of a package's ``_deprecated`` tables (``identification``, ``controllers``,
``heli_env``), nor through a shim module.
"""

import ast
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "structure_report.py"


@pytest.fixture(scope="module")
def report():
    spec = importlib.util.spec_from_file_location("structure_report", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_tree_imports_no_deprecated_name():
    out = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True, cwd=ROOT)
    assert "First-party imports of a deprecated name (identification/_deprecated.py, controllers/_deprecated.py, " \
           "heli_env/_deprecated.py, model_store/_deprecated.py): 0" in out.stdout, out.stdout
    assert "Shim modules (imports only, re-exporting other modules' names): 0" in out.stdout
    assert "Upward imports: 0" in out.stdout
    assert "Import circles between files: 0" in out.stdout
    assert out.returncode == 0


def test_each_form_of_a_deprecated_import_is_found(report):
    """An old module, an old name of a module that became a stage's folder, a re-exported name of a module
    that stays, and an old module imported by name from the package; a folder's submodule is no old name."""
    known = {report._dotted(p) for _, p in report._modules()}
    tables = report._deprecation_tables()
    source = (
        "from identification.ml_estimator import MaximumLikelihoodIdentifier\n"  # 1: an old module
        "import identification.synthetic as synthetic\n"  # 2: the same, imported whole
        "from identification.validation import validate_models\n"  # 3: the folder's old name
        "from identification.validation import result\n"  # 4: a submodule of the folder: fine
        "from identification.errors import ModelFileError, FlightLogError\n"  # 5: one re-export, one own
        "from identification import fleet, io\n"  # 6: an old module by name; io is a package
        "from identification.likelihood.axis_search import BURN_IN\n"  # 7: the new home: fine
        "from controllers.residual import ResidualAgent\n"  # 8: controllers' old module
        "from controllers import PDController\n"  # 9: a name the package re-exported
        "from controllers.evaluate import evaluate_agent, metrics_table\n"  # 10: one own, one re-export
        "from controllers.pd import PDController\n"  # 11: a package's facade: fine
    )
    found = report._deprecated_imports(ast.parse(source), "tests.example", False, known, tables)
    assert found == ["1: identification.ml_estimator.MaximumLikelihoodIdentifier", "2: identification.synthetic",
                     "3: identification.validation.validate_models", "5: identification.errors.ModelFileError",
                     "6: identification.fleet", "8: controllers.residual.ResidualAgent", "9: controllers.PDController",
                     "10: controllers.evaluate.metrics_table"]


def test_a_deprecated_import_fails_the_report(report, monkeypatch, capsys):
    found = {"tests/example.py": ["1: identification.model.ModelParams"]}
    monkeypatch.setattr(report, "_outside_imports", lambda known, tables: found)
    assert report.main([]) == 1
    assert "tests/example.py:1: identification.model.ModelParams" in capsys.readouterr().out


def test_a_first_party_import_of_a_shim_fails_the_report(report, monkeypatch, capsys):
    """A module of imports only, re-exporting another's names, is a second home: importing it fails the report."""
    real = report.measure

    def measure():
        return {**real(), "shims": {"controllers.example": ["tests/example.py"]}}

    monkeypatch.setattr(report, "measure", measure)
    assert report.main([]) == 1
    assert "controllers.example  <- tests/example.py" in capsys.readouterr().out


def test_import_circles_are_the_groups_of_modules_that_reach_one_another(report):
    """A result importing its report that imports the result back is a circle, so is a longer loop; a module
    that only imports into a circle, or two that import a third, are not."""
    edges = {"evaluate": {"evaluate_report", "metrics"}, "evaluate_report": {"evaluate"},
             "sweep": {"sweep_report"}, "sweep_report": {"flight_test"}, "flight_test": {"sweep", "metrics"},
             "cli": {"evaluate", "sweep"}, "metrics": set(), "a": {"c"}, "b": {"c"}}
    assert report._circles(edges) == [["evaluate", "evaluate_report"], ["flight_test", "sweep", "sweep_report"]]
    assert report._circles({"a": {"b"}, "b": {"c"}}) == []


def test_an_import_circle_fails_the_report(report, monkeypatch, capsys):
    real = report.measure
    monkeypatch.setattr(report, "measure", lambda: {**real(), "circles": [["controllers.a", "controllers.b"]]})
    assert report.main([]) == 1
    assert "Import circles between files: 1\n  controllers.a <-> controllers.b" in capsys.readouterr().out
