"""How close surrogate gusts come to the recorded ones: a PD's per-window errors on each, compared by KS.

For a model (default the shipped one) the PD designed by ``heli design`` (45° phase margin) flies
``--windows`` windows of ``--seconds`` s drawn from the recorded library and as many from a library of
phase-randomised surrogates of the same traces (:func:`heli_env.surrogates.surrogate_model`, ``--copies``
per trace), through the model's sensors. Per axis and per window it takes the p90 |attitude error|, and
reports the two-sample KS distance between the two sets of per-window values (and the pooled p90 of
each), over ``--seeds`` surrogate seeds: the worst seed beside the mean.

Usage::

    python scripts/surrogate_gusts.py [--model DIR] [--windows 40] [--seconds 20] [--copies 4] [--seeds 3]
"""

from __future__ import annotations

import argparse

import numpy as np


def per_window_p90(result) -> np.ndarray:
    """(episodes, 3) p90 |attitude error| [deg] of each recorded episode of an evaluation."""
    err = np.abs(result.samples["att_err_deg"])  # (steps, episodes, 3)
    steps = result.samples["steps"]
    return np.array([[np.percentile(err[: steps[e], e, a], 90) for a in range(3)] for e in range(err.shape[1])])


def main(argv=None):
    from scipy.stats import ks_2samp

    from controllers.evaluate import evaluate_agent
    from controllers.pd import PDController, design_gains
    from heli_env.env_model import load_env_model
    from heli_env.surrogates import surrogate_model

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default=None)
    ap.add_argument("--windows", type=int, default=40)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--copies", type=int, default=4)
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args(argv)
    model = load_env_model(args.model)
    pd = PDController.from_model(model.params, design_gains(model.params))
    per = max(1, args.windows // model.n_traces)
    recorded = per_window_p90(evaluate_agent(pd, model, traces="all", episodes_per_trace=per,
                                             episode_seconds=args.seconds, seed=0))
    rows = []
    for seed in range(args.seeds):
        sur = surrogate_model(model, copies=args.copies, seed=seed)
        per_s = max(1, args.windows // sur.n_traces)
        surrogate = per_window_p90(evaluate_agent(pd, sur, traces="all", episodes_per_trace=per_s,
                                                  episode_seconds=args.seconds, seed=1))
        rows.append([ks_2samp(recorded[:, a], surrogate[:, a]).statistic for a in range(3)]
                    + [np.median(surrogate[:, a]) for a in range(3)])
    rows = np.array(rows)
    print(f"Command: python scripts/surrogate_gusts.py --windows {args.windows} --seconds {args.seconds:g} "
          f"--copies {args.copies} --seeds {args.seeds}" + (f" --model {args.model}" if args.model else ""))
    print(f"\nPD of heli design on {model.path.name}: per-window p90 |attitude error|, "
          f"{recorded.shape[0]} recorded windows against each surrogate seed's windows, {args.seconds:g} s each\n")
    print("| axis | median per-window p90, recorded [deg] | surrogates (mean over seeds) | KS mean | KS worst seed |")
    print("|---|---|---|---|---|")
    for a, axis in enumerate(("roll", "pitch", "yaw")):
        print(f"| {axis} | {np.median(recorded[:, a]):.4f} | {rows[:, 3 + a].mean():.4f} | {rows[:, a].mean():.3f} "
              f"| {rows[:, a].max():.3f} |")


if __name__ == "__main__":
    main()
