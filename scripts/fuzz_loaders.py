"""Fuzz the log importers: seeded byte mutations of every fixture log through ``heli import``.

Each case takes one fixture log (at most ``--max-bytes`` of its head: the header,
format definitions and the first stretch of data, where a mutation reaches the most
decoder state; cutting there is itself a realistic cut log), applies one to three
seeded mutations (bit flips, overwritten runs, truncation, inserted bytes or
padding, deleted or duplicated chunks, leading/trailing 0xFF/0x00 padding), and
runs ``heli import`` on it with one of three option sets (default, ``--segment
all``, ``--allow-damaged --segment all``).

A case passes when the import either succeeds (exit 0, the CSV and its metadata
written) or is refused with one of the package's own errors (exit 2, a one-line
message, *nothing* written). Anything else -- an exception of a parser or of
numpy escaping, a hang beyond ``--timeout`` -- is a *foreign* outcome, listed with
its case number so it can be replayed (``--case N``).

Prints a table of outcomes per fixture and the count of foreign exceptions; exits
with status 1 when there is any. Run::

    python scripts/fuzz_loaders.py --cases 2000            # the long run
    python scripts/fuzz_loaders.py --case 1234 --keep DIR  # replay one case, keep its file

The fixtures are found through ``HELI_FIXTURES`` or ``../shared/fixtures/logs``
(relative to the repository). ``tests/test_log_fuzz.py`` runs a few hundred small
cases of the same generator in the suite.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import signal
import sys
import tempfile
import time
import warnings
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OPTION_SETS = ([], ["--segment", "all"], ["--allow-damaged", "--segment", "all"])
"""Command-line options a case runs with (chosen per case)."""
MUTATIONS = ("bitflip", "overwrite", "truncate", "insert", "insert_pad", "delete", "duplicate", "pad_lead",
             "pad_trail")


def fixture_dir() -> Path | None:
    """The fixture logs: ``$HELI_FIXTURES`` if set, else ``../shared/fixtures/logs`` beside the repository."""
    env = os.environ.get("HELI_FIXTURES")
    for candidate in ([Path(env)] if env else []) + [ROOT.parent / "shared" / "fixtures" / "logs"]:
        if candidate.is_dir():
            return candidate
    return None


def fixture_logs(folder: Path) -> list[Path]:
    """Every log in the fixture folder (not its README), sorted by name."""
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() != ".md")


def mutate(data: bytes, rng: np.random.Generator) -> tuple[bytes, list[str]]:
    """Apply one to three seeded mutations; returns the bytes and a description of each mutation."""
    b = bytearray(data)
    done = []
    for _ in range(int(rng.integers(1, 4))):
        kind = MUTATIONS[int(rng.integers(len(MUTATIONS)))]
        n = len(b)
        pos = int(rng.integers(0, max(n, 1)))
        if kind == "bitflip" and n:
            k = int(rng.integers(1, 9))
            for p in rng.integers(0, n, size=k):
                b[int(p)] ^= 1 << int(rng.integers(8))
            done.append(f"bitflip x{k}")
        elif kind == "overwrite" and n:
            k = int(rng.integers(1, 64))
            b[pos:pos + k] = rng.integers(0, 256, size=len(b[pos:pos + k]), dtype=np.uint8).tobytes()
            done.append(f"overwrite {k}@{pos}")
        elif kind == "truncate":
            b = b[:pos]
            done.append(f"truncate@{pos}")
        elif kind == "insert":
            k = int(rng.integers(1, 64))
            b[pos:pos] = rng.integers(0, 256, size=k, dtype=np.uint8).tobytes()
            done.append(f"insert {k}@{pos}")
        elif kind == "insert_pad":
            k = int(rng.integers(1, 4096))
            b[pos:pos] = (b"\xff" if rng.random() < 0.5 else b"\x00") * k
            done.append(f"insert-pad {k}@{pos}")
        elif kind == "delete" and n:
            k = int(rng.integers(1, 256))
            del b[pos:pos + k]
            done.append(f"delete {k}@{pos}")
        elif kind == "duplicate" and n:
            k = int(rng.integers(1, 2048))
            b[pos:pos] = b[pos:pos + k]
            done.append(f"duplicate {k}@{pos}")
        elif kind == "pad_lead":
            k = int(rng.integers(1, 4096))
            b[0:0] = (b"\xff" if rng.random() < 0.5 else b"\x00") * k
            done.append(f"pad-lead {k}")
        elif kind == "pad_trail":
            k = int(rng.integers(1, 8192))
            b.extend((b"\xff" if rng.random() < 0.5 else b"\x00") * k)
            done.append(f"pad-trail {k}")
    return bytes(b), done


class _Timeout(BaseException):
    pass


def _alarm(signum, frame):
    raise _Timeout()


def run_case(source: Path, data: bytes, case: int, seed: int, workdir: Path, timeout: float) -> dict:
    """Mutate ``data`` with the case's seed, run ``heli import`` on it, and classify the outcome.

    Returns
    -------
    dict
        ``{"fixture", "case", "mutations", "options", "outcome": "imported" | error class name | "FOREIGN
        <type>" | "HANG", "detail", "wrote": files left in the output folder}``.
    """
    from heli_cli.main import main

    rng = np.random.default_rng([seed, case])
    mutated, done = mutate(data, rng)
    options = OPTION_SETS[int(rng.integers(len(OPTION_SETS)))]
    case_dir = workdir / f"case{case}"
    case_dir.mkdir()
    log = case_dir / source.name
    log.write_bytes(mutated)
    out_dir = case_dir / "out"
    out_dir.mkdir()
    err, out = io.StringIO(), io.StringIO()
    row = {"fixture": source.name, "case": case, "mutations": done, "options": " ".join(options) or "(default)"}
    use_alarm = timeout > 0 and hasattr(signal, "SIGALRM")
    if use_alarm:
        previous = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            status = main(["import", str(log), "--out", str(out_dir / "flight.csv"), *options])
        if status == 0:
            row["outcome"], row["detail"] = "imported", ""
        else:
            line = err.getvalue().strip().splitlines()[-1] if err.getvalue().strip() else ""
            name = line.split("error: ", 1)[-1].split(":", 1)[0] if "error: " in line else f"exit {status}"
            row["outcome"], row["detail"] = name, line[:300]
    except _Timeout:
        row["outcome"], row["detail"] = "HANG", f"no answer within {timeout} s"
    except SystemExit as e:  # argparse: cannot happen with these options
        row["outcome"], row["detail"] = f"FOREIGN SystemExit({e.code})", err.getvalue()[-300:]
    except BaseException as e:  # noqa: BLE001 - exactly what must not happen: report it
        if isinstance(e, KeyboardInterrupt):
            raise
        row["outcome"], row["detail"] = f"FOREIGN {type(e).__name__}", f"{e}"[:300]
    finally:
        if use_alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
    row["wrote"] = sorted(p.name for p in out_dir.iterdir())
    if row["outcome"] != "imported" and row["wrote"]:
        row["outcome"] = f"WROTE-ON-REFUSAL {row['outcome']}"
    return row


def is_foreign(row: dict) -> bool:
    """True for an outcome that is not an import or a refusal by the package's own errors."""
    return row["outcome"].startswith(("FOREIGN", "HANG", "WROTE-ON-REFUSAL", "exit "))


def run(cases: int, seed: int, max_bytes: int, timeout: float, only: int | None = None, keep: Path | None = None,
        folder: Path | None = None, progress: bool = True) -> list[dict]:
    """Run ``cases`` fuzz cases round-robin over the fixtures; returns one row per case."""
    folder = folder or fixture_dir()
    if folder is None:
        raise SystemExit("no fixture logs: set HELI_FIXTURES or provide ../shared/fixtures/logs")
    sources = fixture_logs(folder)
    heads = {p: p.read_bytes()[:max_bytes] for p in sources}
    rows = []
    indices = [only] if only is not None else range(cases)
    with tempfile.TemporaryDirectory(prefix="heli-fuzz-") as tmp:
        workdir = Path(keep) if keep else Path(tmp)
        workdir.mkdir(parents=True, exist_ok=True)
        start = time.time()
        for case in indices:
            source = sources[case % len(sources)]
            rows.append(run_case(source, heads[source], case, seed, workdir, timeout))
            if not keep:
                for p in sorted((workdir / f"case{case}").rglob("*"), reverse=True):
                    p.rmdir() if p.is_dir() else p.unlink()
                (workdir / f"case{case}").rmdir()
            if progress and (case + 1) % 100 == 0:
                print(f"  {case + 1} cases, {time.time() - start:.0f} s", file=sys.stderr)
    return rows


def table(rows: list[dict]) -> str:
    """Markdown table: outcomes per fixture, then the foreign ones in detail."""
    per = defaultdict(Counter)
    for r in rows:
        per[r["fixture"]][r["outcome"]] += 1
    outcomes = sorted({o for c in per.values() for o in c}, key=lambda o: (o != "imported", o))
    lines = ["| fixture | cases | " + " | ".join(outcomes) + " |", "|---|---|" + "---|" * len(outcomes)]
    for name in sorted(per):
        c = per[name]
        lines.append(f"| {name} | {sum(c.values())} | " + " | ".join(str(c.get(o, 0)) for o in outcomes) + " |")
    total = Counter(r["outcome"] for r in rows)
    lines.append(f"| **all** | {len(rows)} | " + " | ".join(str(total.get(o, 0)) for o in outcomes) + " |")
    foreign = [r for r in rows if is_foreign(r)]
    lines.append("")
    lines.append(f"foreign exceptions: {len(foreign)} of {len(rows)} cases")
    for r in foreign[:50]:
        lines.append(f"  case {r['case']} {r['fixture']} [{', '.join(r['mutations'])}] {r['options']}: "
                     f"{r['outcome']}: {r['detail']}")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=2000, help="number of cases (default 2000)")
    parser.add_argument("--seed", type=int, default=16, help="seed of the mutations (default 16)")
    parser.add_argument("--max-bytes", type=int, default=192 * 1024,
                        help="bytes of each fixture's head to mutate (default 196608)")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per case before it counts as a hang")
    parser.add_argument("--case", type=int, default=None, help="replay one case number")
    parser.add_argument("--keep", type=Path, default=None, help="keep the mutated files in this folder")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    start = time.time()
    rows = run(args.cases, args.seed, args.max_bytes, args.timeout, only=args.case, keep=args.keep)
    print(table(rows))
    print(f"{len(rows)} cases in {time.time() - start:.0f} s (seed {args.seed}, "
          f"max {args.max_bytes} bytes per fixture)")
    return 1 if any(is_foreign(r) for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
