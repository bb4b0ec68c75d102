"""End to end: does the sweep's prediction on an identified model hold for flights of the truth?

Per seed: a realistic flight of the bench's ``independent`` cell (a PD pilot fighting slow plus broadband
Gauss-Markov gusts, gyro noise, vibration lines) of the paper's aircraft with a 40/40/25 ms servo delay,
300 s; ``heli identify`` (maximum likelihood, ``--delay auto``, the sensors and the smoother's winds) into a
scratch folder; then per axis three PD pairs — the design of ``heli design`` (45°) scaled by 0.5, 1 and 2 —
predicted by the sweep on the identified model (its library, its sensors; 8 windows of 30 s) and flown on
the *truth* (RK4) in fresh wind of a different model (``gusts="corner"``: coloured low-pass noise at the
library's level and bandwidth, not surrogates of its spectrum) on the flight generator's sensors, 10 flights
of 60 s per pair (:func:`controllers.flight_test.validate_against_flights`). Prints per pair the predicted
and flown p90 |attitude error| and their ratio, and the mean and worst |ratio - 1| over everything (target:
within 15 %).

Usage::

    python scripts/end_to_end_prediction.py [--seeds 3] [--duration 300]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

FACTORS = (0.5, 1.0, 2.0)


def one_seed(seed: int, duration: float, tmp: Path) -> list:
    from controllers.flight_test import validate_against_flights
    from controllers.pd import design_gains
    from controllers.sweep import sweep_pairs
    from identification.bench import BENCH_CELLS
    from identification.report import identify_and_report
    from identification.synthetic import simulate_flight

    sim = simulate_flight(duration, seed=seed, config=BENCH_CELLS["independent"], effects=("servo_delay",),
                          effect_scale=0.5)
    out = tmp / f"model{seed}"
    identify_and_report([sim.flight], out, identifier_kwargs={"delay": "auto"}, plots=False)
    from heli_env.model_dir import load_env_model

    model = load_env_model(out)
    gains = design_gains(model.params)
    rows = []
    for a, axis in enumerate(("roll", "pitch", "yaw")):
        pairs = [(f * gains.kp[a], f * gains.kd[a]) for f in FACTORS]
        pred = sweep_pairs(model, pairs, axis=axis, duration=30.0, windows=8, keep_samples=True, progress=False,
                           seed=seed)
        flown = validate_against_flights(model, pairs, axis=axis, n_flights=10, duration=60.0, seed=seed,
                                         truth=sim.truth, prediction=pred, gusts="corner", progress=False)
        for r in flown.rows():
            if r["status"] == "flown":
                rows.append((seed, axis, r["kp"], r["kd"], r["pred_td_att_p90_deg"], r["att_p90_deg"], r["ks_att"]))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--duration", type=float, default=300.0)
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(1, args.seeds + 1):
            rows += one_seed(seed, args.duration, Path(tmp))
    print(f"Command: python scripts/end_to_end_prediction.py --seeds {args.seeds} --duration {args.duration:g}\n")
    print("| seed | axis | Kp | Kd | predicted p90 [deg] | flown p90 [deg] | predicted / flown | KS |")
    print("|---|---|---|---|---|---|---|---|")
    for seed, axis, kp, kd, pred, flown, ks in rows:
        print(f"| {seed} | {axis} | {kp:.3g} | {kd:.3g} | {pred:.4f} | {flown:.4f} | {pred / flown:.3f} | {ks:.3f} |")
    err = np.array([abs(p / f - 1.0) for *_, p, f, _ in rows])
    print(f"\n|predicted / flown - 1| over {err.size} pairs: mean {100 * err.mean():.1f} %, worst "
          f"{100 * err.max():.1f} % (target: within 15 %); within 15 %: {int((err <= 0.15).sum())}/{err.size}")


if __name__ == "__main__":
    main()
