"""The README's and the docs' Python examples run as written, and the README's links lead somewhere."""

import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README] + sorted((ROOT / "docs").glob("*.md"))


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_python_blocks_run(page, tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)
    monkeypatch.chdir(tmp_path)
    for code in blocks:
        exec(compile(code, str(page), "exec"), {})


def test_readme_has_a_python_example():
    assert re.search(r"```python\n", README.read_text())


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_relative_links_resolve(page):
    links = re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", page.read_text())
    missing = [link for link in links if not (page.parent / link).exists()]
    assert not missing, f"{page.name} links to missing files: {missing}"


def test_readme_names_the_two_commands_ci_runs():
    text = README.read_text()
    assert "make demo" in text and "make test" in text
    ci = (ROOT / ".ci" / "run").read_text()
    assert "make test" in ci


def test_every_docs_check_finds_its_row_in_the_text():
    """scripts/docs_check.py (make docs-check) re-runs these rows; an edit of the text must keep them."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_check", ROOT / "scripts" / "docs_check.py")
    docs_check = importlib.util.module_from_spec(spec)
    sys.modules["docs_check"] = docs_check  # dataclasses look their module up there
    spec.loader.exec_module(docs_check)
    for check in docs_check.CHECKS:
        row = docs_check.find_row((ROOT / check.page).read_text(), check.row)
        assert row is not None, f"{check.page} has no row {check.row!r}"
        assert all(docs_check.numbers(row[c]) for c in check.columns), (check.page, check.row)
