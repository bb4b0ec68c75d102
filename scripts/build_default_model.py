"""Build the model and disturbance library that ship with heli_env (``heli_env/data/default``).

heli-env identifies its default model itself, by the pipeline a user runs on real logs: it flies its truth
model (:mod:`identification.bench.synthetic`: the paper's values) in realistic conditions — a pilot who fights
the gusts with a PD on attitude and rate after a 0.18 s reaction and sweeps one stick at a time, slow plus
broadband gusts at the paper's level, gyro noise, rotor vibration lines and attitude noise (the bench's
``independent`` cell, :data:`identification.bench.cells.BENCH_CELLS`) — and with a servo delay of
:data:`SERVO_DELAY` (Padé, eq. 31), for three seeded flights saved as CSV; then ``heli identify`` does the
rest: the decoupled model by maximum likelihood with the servo delay profiled (``--delay auto``), the
sensors (noise levels and vibration lines), and each flight's wind as a library trace. Rerunning this
script reproduces the files bit for bit except the creation timestamps.

Usage::

    python scripts/build_default_model.py [--out heli_env/data/default] [--duration 200]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

from identification.bench.cells import BENCH_CELLS
from identification.bench.flight_config import PAPER_PARAMS
from identification.bench.synthetic import simulate_flight

SEEDS = (101, 102, 103)
SERVO_DELAY = {"tau_roll": 0.045, "tau_pitch": 0.045, "tau_yaw": 0.035}
"""The truth's servo delays [s]: within the 30-60 ms of hobby servos at 50-333 Hz frame rates."""
CELL = "independent"
"""The bench cell the flights are flown in (pilot, wind, sensors)."""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "heli_env" / "data" / "default"))
    ap.add_argument("--duration", type=float, default=200.0)
    args = ap.parse_args(argv)
    out = Path(args.out)
    truth = PAPER_PARAMS.with_values(**SERVO_DELAY)
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for seed in SEEDS:
            path = Path(tmp) / f"synthetic-seed{seed}.csv"
            simulate_flight(args.duration, seed=seed, config=BENCH_CELLS[CELL], truth=truth).save(path)
            paths.append(path)
        from identification.io import read_csv_flight
        from identification.workflows.identify import identify_and_report, source_entry

        flights = [read_csv_flight(p) for p in paths]
        staging = Path(tmp) / "model"
        identify_and_report(flights, staging, sources=[source_entry(p) for p in paths], flight_paths=paths,
                            identifier_kwargs={"delay": "auto"}, plots=False, progress=True)
        if out.exists():
            shutil.rmtree(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        # the writers' lock files stay behind: the shipped folder is read, never written, by the package
        shutil.copytree(staging, out, ignore=shutil.ignore_patterns(".heli-lock", ".heli-commit-lock"))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
