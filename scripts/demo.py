"""End-to-end demo: fly a synthetic helicopter, identify it, design and sweep PD gains, fly them in its gusts.

Runs the whole data flow of heli-env on data it generates itself::

    heli simulate-flight  ->  flight.csv (+ truth, + true wind)
    heli identify         ->  model/ (model.json, report.md, figures, disturbance library)
    heli design           ->  pd/ (pd.json, design.md, step and Bode figures)
    heli sweep            ->  sweep/ (error distribution per Kp x Kd pair, heat map, histograms)
    heli evaluate         ->  evaluation/ (the designed PD in the identified gusts of the environment)

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
        # a realistic flight (the bench's "independent" cell: a PD pilot fighting slow and broadband gusts, gyro
        # noise and vibration lines) of an aircraft whose servos lag 40/40/25 ms, identified with its delay
        ["simulate-flight", "--duration", str(args.duration), "--seed", str(args.seed), "--cell", "independent",
         "--effect", "servo_delay", "--effect-scale", "0.5", "--out", str(flight)],
        ["identify", str(flight), "--delay", "auto", "--out", str(out / "model")],
        ["design", "--model", str(out / "model"), "--out", str(out / "pd")],
        ["sweep", "--model", str(out / "model"), "--kp", "5:120:8", "--kd", "0:10:8", "--axis", "roll",
         "--duration", "30", "--out", str(out / "sweep")],
        ["evaluate", str(out / "pd" / "pd.json"), "--model", str(out / "model"), "--traces", "all",
         "--out", str(out / "evaluation")],
    ]
    for step in steps:
        print(f"\n$ heli {' '.join(step)}", flush=True)
        code = heli(step)
        if code:
            return code
    print(f"\nDemo finished: open {out / 'model' / 'report.html'}, {out / 'sweep' / 'sweep.html'} and "
          f"{out / 'evaluation' / 'evaluation.html'} in a browser (figures inside), or the .md beside each; "
          f"the PD design: {out / 'pd' / 'design.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
