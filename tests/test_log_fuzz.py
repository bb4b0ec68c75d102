"""A few hundred seeded byte mutations of the fixture logs through ``heli import`` (``scripts/fuzz_loaders.py``).

Every case must import, or be refused with one of the package's own errors and
leave nothing written; a parser's or numpy's exception escaping, or a hang, fails
the test and names the case to replay with ``python scripts/fuzz_loaders.py --case N
--seed 7 --max-bytes 40960``. The long run (2,000+ cases on larger heads of the logs)
is the script itself.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "fuzz_loaders.py"
CASES = 300
SEED = 7
MAX_BYTES = 40 * 1024
"""Bytes of each fixture's head: small, so a few hundred cases run in seconds."""


def _script():
    spec = importlib.util.spec_from_file_location("fuzz_loaders_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# slow (6 s): the seeded fuzz of every fixture; scripts/fuzz_loaders.py runs the long version
@pytest.mark.slow
def test_mutated_logs_import_or_are_refused_by_our_own_errors():
    fz = _script()
    folder = fz.fixture_dir()
    if folder is None:
        pytest.skip("fixture logs not found: set HELI_FIXTURES to their folder or provide ../shared/fixtures/logs")
    for module in ("pyulog", "pymavlink", "orangebox"):
        pytest.importorskip(module, reason=f"parser {module!r} of the 'logs' extra is not installed")
    rows = fz.run(CASES, SEED, MAX_BYTES, timeout=20.0, folder=folder, progress=False)
    print("\n" + fz.table(rows))
    foreign = [r for r in rows if fz.is_foreign(r)]
    assert not foreign, "\n".join(f"case {r['case']} {r['fixture']} {r['mutations']} {r['options']}: "
                                  f"{r['outcome']}: {r['detail']}" for r in foreign)
    outcomes = {r["outcome"] for r in rows}
    assert "imported" in outcomes and len(outcomes) >= 3  # the mutations reach both sides
