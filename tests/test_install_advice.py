"""Set-up: every install advice ``heli`` prints is a command the Makefile runs and that exits 0 (issue #31).

``heli_core.errors.require`` names the command in its ``MissingDependency``. No pip runs here (no network in
the suite): the commands are checked against what ``make setup`` does, which was run in a fresh venv from PyPI
when this was written (2026-11: ``make setup`` exit 0; ``python -m pip install 'heli-env[logs]'`` exit 0;
the orangebox line exit 0 although pip's own status is 1).
"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from pathlib import Path

import pytest

from heli_core.errors import BLACKBOX_INSTALL, MissingDependency, install_advice, require

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("heli_core", "model_store", "identification", "heli_env", "controllers", "heli_cli")
BROKEN_WHEELS = ("orangebox",)
"""Distributions whose wheel makes pip exit 1 (orangebox 0.5.0: console scripts without a callable)."""


def _require_calls() -> list[tuple[str, str]]:
    """``(module, extra)`` of every ``require("module", "extra")`` call in the packages."""
    calls = []
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            text = path.read_text(encoding="utf-8")
            if "require(" not in text:  # parsed only where a call can be: collection in every worker runs this
                continue
            for node in ast.walk(ast.parse(text)):
                if (isinstance(node, ast.Call) and getattr(node.func, "id", None) == "require"
                        and len(node.args) == 2 and all(isinstance(a, ast.Constant) for a in node.args)):
                    calls.append((node.args[0].value, node.args[1].value))
    return sorted(set(calls))


def _makefile() -> str:
    return (ROOT / "Makefile").read_text(encoding="utf-8")


def _extras() -> dict[str, list[str]]:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]


def test_every_optional_import_is_found():
    assert {m for m, _ in _require_calls()} >= {"pyulog", "pymavlink.DFReader", "orangebox", "stable_baselines3", "ray"}


@pytest.mark.parametrize("module, extra", _require_calls())
def test_the_advice_is_a_command_that_exits_0(module, extra):
    advice = install_advice(module, extra)
    pip_extra = re.fullmatch(r"python -m pip install 'heli-env\[(\w+)\]'", advice)
    if pip_extra:
        requirements = _extras()[pip_extra.group(1)]
        assert module.split(".")[0] not in BROKEN_WHEELS
        assert not [r for r in requirements if r.split(">")[0].split("=")[0] in BROKEN_WHEELS], requirements
        distribution = module.split(".")[0].replace("_", "-")  # pymavlink.DFReader -> pymavlink
        assert any(r.startswith(distribution) for r in requirements), (distribution, requirements)
    else:
        assert advice == BLACKBOX_INSTALL and module == "orangebox"


def test_the_blackbox_advice_is_the_makefiles_own_line():
    text = _makefile()
    decoder = re.search(r"^LOG_DECODER := (.+)$", text, re.M).group(1)
    recipe = re.search(r"^\t\$\(BIN\)/python -m pip install \$\(LOG_DECODER\) \|\| .*$", text, re.M).group(0)
    assert recipe.strip().replace("$(LOG_DECODER)", decoder).replace("$(BIN)/", "") == BLACKBOX_INSTALL
    assert "orangebox" not in " ".join(_extras()["logs"])  # in the extra it would fail the whole pip install


def test_make_setup_installs_every_extra_an_advice_names_and_the_blackbox_decoder():
    text = _makefile()
    extras = set(re.search(r"^EXTRAS \?= (.+)$", text, re.M).group(1).split(","))
    assert {extra for _, extra in _require_calls()} <= extras
    setup = re.search(r"^setup: (.+)$", text, re.M).group(1)
    assert "$(VENV)/.installed-blackbox" in setup.split()
    assert re.search(r"^test: setup$", text, re.M)


def test_the_readme_set_up_is_make_setup():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    section = readme.split("## Set-up and tests", 1)[1].split("\n## ", 1)[0]
    assert "make setup" in section and "log parser" in section
    assert "heli-env[logs]" not in readme or "orangebox" in section


def test_require_prints_the_advice(monkeypatch):
    monkeypatch.setitem(sys.modules, "orangebox", None)  # import fails as if not installed
    with pytest.raises(MissingDependency, match=re.escape(f"install it with: {BLACKBOX_INSTALL}")):
        require("orangebox", "logs")
    monkeypatch.setitem(sys.modules, "pyulog", None)
    with pytest.raises(MissingDependency, match=re.escape("install it with: python -m pip install 'heli-env[logs]'")):
        require("pyulog", "logs")
