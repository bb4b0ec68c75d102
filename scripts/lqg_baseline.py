"""The LQG baseline beside the PDs: p90 |attitude error| per axis on the held-out gusts, and its robustness.

The baseline a control engineer would try first (issue 33, point 2): a per-axis LQG designed with
python-control on the identified model, its Gauss-Markov wind model and its sensors
(:func:`controllers.lqg.design_lqg`: Bryson's weights, the smallest loop-transfer-recovery weight that keeps
6 dB and 45° at the plant input), flown by the one evaluator (:func:`controllers.evaluate.evaluate_agent`)
beside

* **PD designed** — ``heli design``'s PD (45° phase margin, default bandwidth, derivative filter at 20 x
  the crossover: :func:`controllers.pd.design_gains` with ``d_filter_hz="auto"``);
* **PD robust swept** and **PD best swept** — the per-axis gain sweep of ``scripts/train_compare.py``
  (:func:`controllers.sweep.sweep_pairs` on windows of the training traces, a coarse grid and a fine one
  round its best): the best pair that keeps 6 dB and 45°, and the best pair of any margin, the reference of
  the RL targets (``scripts/rl_targets.py``);
* **LQG, lines as white noise** — the same design with the gyros' vibration lines left to the filter as
  white noise of their variance, to show what modelling them is worth.

All fly the same held-out windows and sensor noise as ``train_compare.py --seed 0`` does (evaluation seed 1,
6 episodes of 30 s per held-out trace, attitude hold from rest). Printed: the LQG's design (recovery weight,
margins, crossover, predicted p90), the table of p90s with each one's ratio to the best swept PD, and the
robustness check (:func:`controllers.robustness.robustness_check`: 20 ms more servo delay, control gains
-20 % and +20 %) as each case's p90 over the nominal one. ``--scan`` also prints, per axis, the margins and
predicted p90 over the weight scale ρ (``R`` times ρ, at no recovery) and over the recovery weight ``q``:
why the design searches ``q`` and not ρ.

Usage::

    .venv/bin/python scripts/lqg_baseline.py [--model DIR] [--out DIR] [--scan] [--no-robustness]

(about 2 minutes on a busy 2-core machine, most of it the PD sweep). ``--out`` writes ``lqg.json``, which
``heli evaluate`` flies, and ``lqg_baseline.json`` with every figure.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from controllers.evaluate import evaluate_agent  # noqa: E402
from controllers.lqg import LQGWeights, WindModel, axis_model, design_axis, design_lqg  # noqa: E402
from controllers.pd import PDController, design_gains  # noqa: E402
from controllers.robustness import CASES, robustness_check  # noqa: E402
from controllers.trace_split import split_traces  # noqa: E402
from heli_core.files import jsonable, write_text  # noqa: E402
from heli_core.terms import AXES  # noqa: E402
from heli_env.env_model import load_env_model  # noqa: E402

BEST = "PD best swept"
SCAN_RHO = tuple(10.0 ** np.arange(-3, 3.1, 1.0))
SCAN_Q = (0.0, 1e-4, 1e-3, 1e-2, 3e-2, 1e-1, 1.0)


def agents(env_model, split, grid: int, seed: int) -> tuple[list, dict]:
    """(name, policy) of every agent flown, and what their designs report."""
    from train_compare import swept_gains  # the sweep that defines the RL targets' best PD

    params = env_model.params
    t0 = time.perf_counter()
    lqg = design_lqg(env_model)
    white = design_lqg(env_model, lines=False)
    t_lqg = time.perf_counter() - t0
    designed = design_gains(params, d_filter_hz="auto")
    t0 = time.perf_counter()
    best, robust, rows, windows = swept_gains(env_model, split, design_gains(params), grid, 30.0, 4, seed)
    t_sweep = time.perf_counter() - t0
    out = [("PD designed", PDController.from_model(params, designed)),
           ("PD robust swept", PDController.from_model(params, robust)),
           (BEST, PDController.from_model(params, best)),
           ("LQG", lqg.controller()),
           ("LQG, lines as white noise", white.controller())]
    info = {"lqg": lqg, "lqg_white": white, "sweep_rows": rows, "sweep_windows": len(windows),
            "seconds": {"lqg_designs": t_lqg, "pd_sweep": t_sweep}}
    return out, info


def p90_table(results) -> str:
    """Markdown: p90 |attitude error| per axis, as a multiple of the best swept PD's, and the stick's RMS and
    RMS increment per control period (:func:`controllers.servo_activity.stick_activity`)."""
    ref = next(r for r in results if r.name == BEST)
    lines = ["| agent | roll p90 [deg] | pitch p90 [deg] | yaw p90 [deg] | ÷ best swept PD (roll / pitch / yaw) "
             "| stick RMS (roll / pitch / yaw) | stick RMS step per period |", "|---|---|---|---|---|---|---|"]
    for r in results:
        p90 = [r.metrics[a]["att_p90_deg"] for a in AXES]
        ratio = " / ".join(f"{v / ref.metrics[a]['att_p90_deg']:.2f}" for v, a in zip(p90, AXES))
        stick = " / ".join(f"{r.metrics[a]['stick_rms']:.3f}" for a in AXES)
        step = " / ".join(f"{r.activity[a]['stick_step_rms']:.3f}" for a in AXES)
        lines.append(f"| {r.name} | " + " | ".join(f"{v:.4f}" for v in p90) + f" | {ratio} | {stick} | {step} |")
    return "\n".join(lines)


def robustness_table(checks: dict) -> str:
    """Markdown: per agent and perturbed case, p90 over the nominal p90 per axis, and early ends."""
    cases = [c for c in CASES if c != "nominal"]
    lines = ["| agent | " + " | ".join(f"{c} (roll / pitch / yaw)" for c in cases) + " | worst | ended early |",
             "|---|" + "---|" * (len(cases) + 2)]
    for name, check in checks.items():
        cells = [" / ".join(f"{check[c]['ratio'][a]:.2f}" for a in AXES) for c in cases]
        worst = max(check[c]["ratio"][a] for c in cases for a in AXES)
        ended = sum(check[c]["ended_early"] for c in check)
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {worst:.2f} | {ended} |")
    return "\n".join(lines)


def scans(env_model) -> str:
    """Per axis: margins and predicted p90 over the weight scale ρ (no recovery), and over the recovery q."""
    lines = ["| axis | scan | value | gain margin [dB] | phase margin [deg] | predicted p90 [deg] | kept |",
             "|---|---|---|---|---|---|---|"]
    base = LQGWeights()
    for axis in AXES:
        model = axis_model(env_model.params, env_model.sensors, WindModel.from_document(env_model.document, axis),
                           axis, 0.01, float(np.mean(env_model.collective)))
        for label, values, make in (
                ("ρ (q = 0)", SCAN_RHO, lambda v: (LQGWeights(base.attitude_deg, base.rate_deg_s,
                                                              base.stick / math.sqrt(v)), 0.0)),
                ("q", SCAN_Q, lambda v: (base, v))):
            for v in values:
                weights, q = make(v)
                row = design_axis(model, weights, q).search[0]
                kept = row["stable"] and row["gain_margin_db"] >= 6 and row["phase_margin_deg"] >= 45
                lines.append(f"| {axis} | {label} | {v:.3g} | {row['gain_margin_db']:.1f} | "
                             f"{row['phase_margin_deg']:.1f} | {row['predicted_att_p90_deg']:.3f} | "
                             f"{'yes' if kept else 'no'} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--model", default=None, help="model directory (default: the shipped model)")
    p.add_argument("--seed", type=int, default=0, help="seed of the PD sweep's windows; the evaluation flies "
                   "seed + 1, as scripts/train_compare.py (default 0)")
    p.add_argument("--split-seed", type=int, default=0, help="which traces are held out (default 0)")
    p.add_argument("--episodes-per-trace", type=int, default=6)
    p.add_argument("--grid", type=int, default=13, help="coarse PD sweep grid per axis (default 13 x 13)")
    p.add_argument("--out", default=None, help="write lqg.json (the LQG agent) and lqg_baseline.json here")
    p.add_argument("--scan", action="store_true", help="also print the ρ and q scans of the LQG design")
    p.add_argument("--no-robustness", action="store_true", help="skip the robustness check")
    args = p.parse_args(argv)

    env_model = load_env_model(args.model)
    split = split_traces(env_model.n_traces, seed=args.split_seed)
    flown, info = agents(env_model, split, args.grid, args.seed)
    lqg = info["lqg"]
    print(f"LQG design ({lqg.weights}; recovery searched for >= 6 dB and >= 45 deg at the plant input):\n")
    print(lqg.markdown())
    print("\nLQG, gyro lines as white noise:\n")
    print(info["lqg_white"].markdown())
    settings = dict(traces="held-out", split=split, episodes_per_trace=args.episodes_per_trace, seed=args.seed + 1)
    results = [evaluate_agent(agent, env_model, name=name, **settings) for name, agent in flown]
    st = results[0].settings
    print(f"\nHeld-out traces {st['trace_ids_used']}, {len(results[0].episodes)} episodes of "
          f"{st['episode_seconds']:g} s, seed {st['seed']} (PD sweep: {info['sweep_windows']} training windows, "
          f"{info['seconds']['pd_sweep']:.0f} s; LQG designs {info['seconds']['lqg_designs']:.1f} s):\n")
    print(p90_table(results))
    checks = {}
    if not args.no_robustness:
        names = ("PD robust swept", BEST, "LQG")
        checks = {name: robustness_check(agent, env_model, **settings) for name, agent in flown if name in names}
        print("\nRobustness: p90 |attitude error| of each case over the nominal one (same windows):\n")
        print(robustness_table(checks))
    if args.scan:
        print("\nThe LQG's scans (predicted p90 under the design model's noises):\n")
        print(scans(env_model))
    if args.out:
        out = Path(args.out)
        path = lqg.controller().save(out / "lqg.json", {"model": str(env_model.path), "how": "design_lqg",
                                                          "design": lqg.summary()})
        doc = {"settings": st, "design": lqg.summary(), "design_lines_as_white_noise": info["lqg_white"].summary(),
               "results": [r.summary() for r in results], "robustness": checks, "sweep": info["sweep_rows"],
               "seconds": info["seconds"]}
        report = write_text(out / "lqg_baseline.json", json.dumps(jsonable(doc), indent=1, allow_nan=False) + "\n")
        print(f"\nwrote {path}\nwrote {report}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
