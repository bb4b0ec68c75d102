"""Re-run the quick figures of the README's pages and fail when one drifts from the text.

Every figure in ``docs/`` is printed by the command shown beside it. This script re-runs the
commands that take under about a minute (a row of each table, at the table's own settings and
seeds), finds the same row in the command's output, and compares the numbers of the chosen
columns with the text's. A figure that moved by more than its stated noise fails the check: the
text must then be re-measured (the command beside it) or the change that moved it explained.

Same seeds give the same flights, so most figures reproduce exactly; the noise allowed covers
floating-point differences between machines (BLAS, numba) and, for the diagnosis' counts, one
flight of twenty.

Usage::

    python scripts/docs_check.py            # all checks, 10-11 minutes on 2 busy cores (2026-11-27)
    python scripts/docs_check.py --list     # what is checked
    make docs-check
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NUMBER = re.compile(r"[-+−]?\d+(?:\.\d+)?")


@dataclass(frozen=True)
class Check:
    """One table row of a page, the command that prints it, and how much it may move."""

    page: str
    """Page under the repository root, e.g. ``docs/method.md``."""
    row: str
    """The row's first cell, as it opens the line (``"| default |"``)."""
    command: tuple
    """The script and its arguments (run with this Python from the repository root)."""
    columns: tuple
    """Indices of the row's cells to compare (0 is the first cell after the leading ``|``)."""
    noise: float
    """Largest absolute difference allowed per number."""
    out_row: str | None = None
    """The row's first cell in the command's output, when the page words it differently."""


CHECKS = (
    Check("docs/method.md", "| default |", ("scripts/smoother_wind.py", "--seeds", "5", "--workers", "2",
                                            "--cells", "default", "dryden-2Hz-pd"), (1, 2), 0.002),
    Check("docs/method.md", "| dryden-2Hz-pd |", ("scripts/smoother_wind.py", "--seeds", "5", "--workers", "2",
                                                  "--cells", "default", "dryden-2Hz-pd"), (1, 2), 0.002),
    Check("docs/diagnosis.md", "| cross_coupling (k4 0.8, k8 0.7) |",
          ("scripts/likelihood_diagnosis_study.py", "--seeds", "20", "--duration", "180", "--workers", "2",
           "--cases", "cross_coupling"), (1, 2, 3), 1.0, out_row="| cross_coupling |"),
    Check("docs/diagnosis.md", "| none |",
          ("scripts/likelihood_diagnosis_study.py", "--seeds", "20", "--duration", "180", "--workers", "2",
           "--cases", "none"), (3,), 1.0),
    Check("docs/method.md", "| paper | broadband-autopilot | 100 Hz |",
          ("scripts/aircraft_generalisation.py", "--aircraft", "paper", "--cells", "broadband-autopilot", "--seeds",
           "2", "--first-seed", "1501", "--set", "gyro_filter_hz=20.0", "log_every=4"), (3, 4, 5, 6, 7, 8), 0.3),
)


def cells(line: str) -> list:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def numbers(cell: str) -> list:
    return [float(n.replace("−", "-")) for n in NUMBER.findall(cell)]


def find_row(text: str, start: str) -> list | None:
    for line in text.splitlines():
        if line.startswith(start):
            return cells(line)
    return None


def compare(check: Check, page_row, out_row) -> list:
    """The differences beyond the noise, as readable strings (empty: the figure holds)."""
    bad = []
    for c in check.columns:
        want, got = numbers(page_row[c]), numbers(out_row[c])
        if len(want) != len(got):
            bad.append(f"column {c}: text '{page_row[c]}' vs now '{out_row[c]}'")
            continue
        for w, g in zip(want, got):
            if abs(w - g) > check.noise:
                bad.append(f"column {c}: text {w:g} vs now {g:g} (noise {check.noise:g})")
    return bad


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--list", action="store_true", help="list the checks and exit")
    args = ap.parse_args(argv)
    if args.list:
        for c in CHECKS:
            print(f"{c.page}: row {c.row!r} by python {' '.join(c.command)}")
        return 0
    outputs, failures = {}, 0
    for check in CHECKS:
        page_row = find_row((ROOT / check.page).read_text(), check.row)
        if page_row is None:
            print(f"FAIL {check.page}: no row {check.row!r} in the text")
            failures += 1
            continue
        if check.command not in outputs:
            t0 = time.perf_counter()
            done = subprocess.run([sys.executable, *check.command], cwd=ROOT, capture_output=True, text=True)
            if done.returncode != 0:
                print(f"FAIL python {' '.join(check.command)} exited {done.returncode}:\n{done.stderr[-2000:]}")
                failures += 1
                outputs[check.command] = ""
                continue
            outputs[check.command] = done.stdout
            print(f"ran python {' '.join(check.command)} ({time.perf_counter() - t0:.0f} s)")
        out_row = find_row(outputs[check.command], check.out_row or check.row)
        if out_row is None:
            print(f"FAIL {check.page} {check.row}: the command printed no such row")
            failures += 1
            continue
        bad = compare(check, page_row, out_row)
        print(("FAIL " if bad else "ok   ") + f"{check.page} {check.row} " + "; ".join(bad))
        failures += bool(bad)
    print(f"\n{len(CHECKS) - failures} of {len(CHECKS)} figures hold")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
