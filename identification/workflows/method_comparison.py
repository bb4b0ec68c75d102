"""What ``heli compare-methods`` writes: ``comparison.json`` and ``comparison.md`` of a method comparison.

The comparison (:func:`identification.bench.method_comparison.compare_methods`) returns data; its Markdown is
the report's (:func:`identification.reports.method_comparison.comparison_markdown`); this module writes both.
"""

from __future__ import annotations

import json
from pathlib import Path

from heli_core.files import write_text

from ..bench.method_comparison import MethodComparison
from ..reports.method_comparison import comparison_markdown


def write_comparison(comparison: MethodComparison, directory) -> dict[str, Path]:
    """Write ``comparison.json`` (:meth:`MethodComparison.to_dict`) and ``comparison.md`` (Tables 3-5 in the
    paper's layout) into ``directory``, each atomically; returns their paths by ``"json"`` and ``"markdown"``."""
    directory = Path(directory)
    paths = {"json": directory / "comparison.json", "markdown": directory / "comparison.md"}
    write_text(paths["json"], json.dumps(comparison.to_dict(), indent=2, allow_nan=False) + "\n")
    write_text(paths["markdown"], comparison_markdown(comparison))
    return paths
