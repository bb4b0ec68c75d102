"""Build the model and disturbance library that ship with heli_env (``heli_env/data/default``).

heli-env identifies its default model itself: it flies its truth model
(:mod:`identification.synthetic`, the paper's values with the paper's wind level)
for three seeded flights, identifies the decoupled model from them with the
integral method, and stores each flight's identified wind as a library trace.
Rerunning this script reproduces the files bit for bit except the creation
timestamps.

Usage::

    python scripts/build_default_model.py [--out heli_env/data/default] [--duration 200]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

from identification.report import identify_and_report
from identification.synthetic import simulate_flight

SEEDS = (101, 102, 103)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "heli_env" / "data" / "default"))
    ap.add_argument("--duration", type=float, default=200.0)
    args = ap.parse_args(argv)
    out = Path(args.out)
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for seed in SEEDS:
            path = Path(tmp) / f"synthetic-seed{seed}.csv"
            simulate_flight(args.duration, seed=seed).save(path)
            paths.append(path)
        from identification.io import read_csv_flight
        from identification.report import source_entry

        flights = [read_csv_flight(p) for p in paths]
        staging = Path(tmp) / "model"
        identify_and_report(flights, staging, sources=[source_entry(p) for p in paths], flight_paths=paths,
                            plots=False, progress=True)
        if out.exists():
            shutil.rmtree(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.copytree(staging, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
