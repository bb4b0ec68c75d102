"""The real helicopter log: what identification finds on ``trex550_hovertest.csv`` and how well it predicts.

On the T-REX 550 flybarless hover of ``../shared/fixtures/logs`` (79.7 s at 100 Hz, inputs and outputs
low-pass filtered near 2.2 Hz by the source's authors, the collective constant, the RC inputs logged after
the response), prints:

* the band the log carries (:mod:`identification.log_band`) and what the default fit (no alignment) gives;
* the fit with the alignment searched (``delay="auto"``, as ``heli identify LOG --delay auto``): each axis'
  input shift, damping, control gain, the share of the rate its stick explains;
* the prediction R² ``h`` seconds ahead (0.1, 0.2, 0.5 s) on each of ``--folds`` contiguous blocks, each
  predicted by the model fitted on the others (:func:`identification.likelihood.ahead_prediction.heldout_ahead_r2`).

Usage::

    python scripts/real_heli.py [--log PATH] [--folds 3]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

DEFAULT_LOG = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "logs" / "trex550_hovertest.csv"
HORIZONS = (0.1, 0.2, 0.5)


def main(argv=None):
    from identification.likelihood.ahead_prediction import heldout_ahead_r2
    from identification.likelihood.ahead_score import format_r2
    from identification.io import read_log
    from identification.log_band import log_band
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--log", type=Path, default=DEFAULT_LOG)
    ap.add_argument("--folds", type=int, default=3)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    flight = read_log(args.log)
    print(f"{args.log.name}: {flight.duration:.1f} s at {flight.sample_rate:.0f} Hz; {log_band(flight).describe()}")
    plain = MaximumLikelihoodIdentifier().fit(flight)
    print("default fit (no alignment): " + ", ".join(
        f"{a} damping {next(v for k, v in f.params.items() if k in ('k3', 'k7', 'k11')):+.3f}"
        for a, f in plain.axes_.items()))
    t0 = time.perf_counter()
    ident = MaximumLikelihoodIdentifier(delay="auto").fit(flight)
    print(f"\nwith the alignment searched (delay='auto', {time.perf_counter() - t0:.1f} s):\n")
    print("| axis | input shift (s) | damping (1/s) | control gain | sticks explain | hold fraction |")
    print("|---|---|---|---|---|---|")
    for a, f in ident.axes_.items():
        damp = next(k for k in f.params if k in ("k3", "k7", "k11"))
        gain = next(k for k in f.params if k in ("k2", "k6", "k10"))
        print(f"| {a} | {ident.input_shifts_[a]:+.3f} | {damp} = {f.params[damp]:.3f} | {gain} = {f.params[gain]:.3f} "
              f"| {100 * f.r2:.0f} % | {f.input_hold:.2f} |")
    print(f"\nprediction R² h seconds ahead on {args.folds} held-out blocks (fitted on the others):\n")
    print("| axis | " + " | ".join(f"{h:g} s ahead (blocks)" for h in HORIZONS) + " | worst 0.5 s |")
    print("|---|" + "---|" * (len(HORIZONS) + 1))
    table = {h: heldout_ahead_r2(MaximumLikelihoodIdentifier(delay="auto"), flight, args.folds, h) for h in HORIZONS}
    for a in ident.axes_:
        cells = [" / ".join(format_r2(v) for v in table[h][a]) for h in HORIZONS]
        worst = np.nanmin(table[0.5][a]) if not np.all(np.isnan(table[0.5][a])) else float("nan")
        print(f"| {a} | " + " | ".join(cells) + f" | {format_r2(worst)} |")
    aligned = ident.aligned(flight)
    ceiling = linear_ceiling(aligned, 0.5)
    print("\nreference, in the fit's own data: the best linear model of rates, attitudes and all three sticks "
          "(least squares on the aligned flight, no wind state) 0.5 s ahead from the measured state: "
          + ", ".join(f"{a} {v:.3f}" for a, v in ceiling.items()))
    print("the same, each axis from its own rate and stick (the minimal model's structure) / with the attitudes / "
          "with the other axes' rates and sticks:")
    parts = {(att, cross): linear_ceiling(aligned, 0.5, att, cross) for att, cross in
             ((False, False), (True, False), (False, True))}
    for a in ceiling:
        print(f"  {a}: " + " / ".join(f"{parts[k][a]:.3f}" for k in parts))
    print(f"\nCommand: python scripts/real_heli.py --folds {args.folds}")


def linear_ceiling(flight, horizon_s: float, attitudes: bool = True, cross: bool = True) -> dict:
    """R² of the best linear model ``x' = M x + N u + c`` (x: p, q, r, roll, pitch; u: the three cyclic and
    pedal sticks), fitted by least squares on the whole flight, predicting the rates ``horizon_s`` ahead from
    the measured state with the sticks known (Euler steps at the log's rate): what any linear model of these
    sticks can explain without a wind state, in sample (so an optimistic bound). Without ``attitudes`` the rates'
    derivatives take no attitude; without ``cross`` each takes its own rate and stick alone (the minimal model's
    structure, eqs. 18 and 21 without their products): what each part of the model's structure is worth."""
    from heli_core.terms import STICK_ROW

    dt, n = flight.dt, flight.n
    rates = np.asarray(flight.rates, dtype=float)
    att = np.asarray(flight.attitude[:2], dtype=float)
    att = att - att.mean(axis=1, keepdims=True)
    sticks = np.asarray(flight.sticks[list(STICK_ROW)], dtype=float)
    x = np.vstack([rates, att])
    M, N, c = np.zeros((5, 5)), np.zeros((5, 3)), np.zeros(5)
    M[3, 0] = M[4, 1] = 1.0
    for axis in range(3):
        states = ([0, 1, 2] if cross else [axis]) + ([3, 4] if attitudes else [])
        inputs = [0, 1, 2] if cross else [axis]
        rhs = np.vstack([x[states], sticks[inputs], np.ones(n)])
        theta = np.linalg.lstsq(rhs.T, np.gradient(rates[axis], dt), rcond=None)[0]
        M[axis, states] = theta[:len(states)]
        N[axis, inputs] = theta[len(states):-1]
        c[axis] = theta[-1]
    h = int(round(horizon_s / dt))
    starts = np.arange(0, n - h, 10)
    state = x[:, starts].copy()
    for j in range(h):
        state = state + dt * (M @ state + N @ sticks[:, starts + j] + c[:, None])
    target = rates[:, starts + h]
    r2 = 1.0 - np.sum((state[:3] - target) ** 2, axis=1) / np.sum((target - target.mean(axis=1, keepdims=True)) ** 2,
                                                                  axis=1)
    return dict(zip(("roll", "pitch", "yaw"), (float(v) for v in r2)))


if __name__ == "__main__":
    main()
