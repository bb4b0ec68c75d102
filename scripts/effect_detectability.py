"""How much torque each hidden effect puts on each axis, against the gust's torque: what a diagnosis can see.

A missing term can only be named where the torque it makes is a measurable share of what the
model already calls wind. For every effect of :data:`identification.bench.flight_config.EFFECTS` made of
terms (the servo delay and lag are not), on default flights (the closed-loop pilot's gentle one-stick
sweeps) and on manoeuvre flights (large sweeps on all sticks at once), the script flies the truth
with the effect and prints, per axis, the standard deviation of the effect's torque
(``sign * value * feature`` of :data:`heli_core.terms.TERMS`, on the true rates and the sticks)
over the standard deviation of the wind torque, in %, mean over the seeds (smallest in brackets).

Usage::

    python scripts/effect_detectability.py [--seeds 5] [--duration 180] [--cell NAME]
"""

from __future__ import annotations

import argparse

import numpy as np


SCALES = {"nonlinear_damping": (1.0, 5.0)}
"""Effect sizes beside the catalogue's (the diagnosis study's quadratic damping is 5x on gentle flights)."""


def torque_shares(sim, effect: str) -> list:
    """Per axis, std of ``effect``'s torque over std of the wind torque in the flight ``sim`` (NaN where it
    has no term)."""
    from heli_core.terms import AXES, FEATURES, STICK_ROW, TERMS
    from identification.bench.flight_config import EFFECTS

    rates = sim.true_rates
    sticks = sim.flight.sticks
    cmd, col = sticks[list(STICK_ROW)], sticks[2]
    torque = np.zeros_like(rates)
    has = np.zeros(len(AXES), bool)
    for name in EFFECTS[effect]:
        term = TERMS[name]
        torque[term.axis] += term.sign * sim.truth.get(name) * FEATURES[term.feature](rates, cmd, col)
        has[term.axis] = True
    wind = sim.wind_torque.std(axis=1)
    return [100.0 * torque[a].std() / wind[a] if has[a] else float("nan") for a in range(len(AXES))]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=180.0)
    ap.add_argument("--cell", default=None, help="a bench cell (identification.bench.cells) instead of the default flight")
    args = ap.parse_args(argv)
    from dataclasses import replace

    from heli_core.terms import TERMS
    from identification.bench.cells import BENCH_CELLS
    from identification.bench.flight_config import EFFECTS, MANOEUVRE_CONFIG, FlightConfig
    from identification.bench.synthetic import simulate_flight

    base = BENCH_CELLS[args.cell] if args.cell else FlightConfig()
    kinds = {"gentle": base, "manoeuvre": replace(base, sweep_amplitude=MANOEUVRE_CONFIG.sweep_amplitude,
                                                  sweep_mode=MANOEUVRE_CONFIG.sweep_mode)}
    print(f"Command: python scripts/effect_detectability.py --seeds {args.seeds} --duration {args.duration:g}"
          + (f" --cell {args.cell}" if args.cell else ""))
    print("\nstd of the effect's torque / std of the wind torque, % (mean over seeds, smallest in brackets)\n")
    print("| effect | flights | roll | pitch | yaw |")
    print("|---|---|---|---|---|")
    for effect in EFFECTS:
        if not all(name in TERMS for name in EFFECTS[effect]):  # a servo delay or lag: not a torque term
            continue
        for scale in SCALES.get(effect, (1.0,)):
            label = effect if scale == 1.0 else f"{effect} ({scale:g}x)"
            for kind, cfg in kinds.items():
                shares = np.array([torque_shares(simulate_flight(args.duration, seed=s, effects=(effect,), config=cfg,
                                                                 effect_scale=scale), effect)
                                   for s in range(1, args.seeds + 1)])
                cells = ["—" if np.isnan(c).all() else f"{np.mean(c):.1f} [{np.min(c):.1f}]" for c in shares.T]
                print(f"| {label} | {kind} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
