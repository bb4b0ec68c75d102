"""End-to-end demo: fly a synthetic helicopter, identify its model, read the report.

Runs the data flow of heli-env on data it generates itself::

    heli simulate-flight  ->  flight.csv (+ truth, + true wind)
    heli identify         ->  model.json, report.md, rates.png, attitude.png

Usage::

    python scripts/demo.py [--out demo-out] [--duration 300] [--seed 1]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from heli_cli.main import main as heli


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="demo-out")
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    out = Path(args.out)
    flight = out / "flight.csv"
    steps = [
        ["simulate-flight", "--duration", str(args.duration), "--seed", str(args.seed), "--out", str(flight)],
        ["identify", str(flight), "--out", str(out / "model")],
    ]
    for step in steps:
        print(f"\n$ heli {' '.join(step)}", flush=True)
        code = heli(step)
        if code:
            return code
    print(f"\nDemo finished: open {out / 'model' / 'report.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
