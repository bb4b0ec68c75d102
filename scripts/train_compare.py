"""Best PD vs PPO vs SAC on the same held-out gusts (issue 5's comparison report).

1. Splits the model's disturbance library into training and held-out traces
   (:func:`controllers.rl.split_traces`).
2. PD: designs per-axis gains with python-control (:func:`controllers.pd.design_gains`),
   then sweeps a Kp x Kd grid from a quarter of them to past the stability
   boundary on each axis, and a finer grid around the best, against windows of
   the *training* traces (:func:`controllers.sweep.sweep_pairs`), and keeps, per
   axis, the stable pair with the smallest p90 |attitude error| ("best swept PD",
   :func:`swept_gains`).
3. Trains PPO and SAC on the training traces, each for a wall-time budget
   (``--minutes``) or a number of timesteps, whichever ends first, and a PPO
   residual on a swept PD (:mod:`controllers.rl.residual_agent`: the agent's action is
   the PD's command plus a learnt correction of at most ``--residual-scale``
   stick; ``--residual-on robust``, the default, takes the best pair that keeps
   6 dB of gain margin and 45° of phase margin), with the same budget. The residual's wall time does not include the sweep that
   found its base.
4. Evaluates the designed PD, the best swept PD, the RL agents and the LQG baseline
   (:func:`controllers.lqg.design_lqg`: the controller a control engineer would try
   first, designed on the identified model and its wind model; saved as ``lqg.json``)
   with one evaluator (:func:`controllers.evaluate.evaluate_agent`) on the same held-out
   windows and initial states; the RL agents compared are the *final* ones (the best
   checkpoints were picked on the held-out traces). A model without the identified
   wind model flies no LQG (a note says why).
5. Writes OUT/comparison.md, comparison.json, episode.png (a representative
   held-out episode, all agents overlaid) and one episode plot per agent, and
   prints the timesteps and wall time of training.

The issue's goal is an RL agent matching or beating the best PD gain pair on
p90 attitude error within 15 minutes of training on 2 cores (``--minutes 15``).

Usage::

    python scripts/train_compare.py --minutes 15 --out compare-out
    python scripts/train_compare.py --minutes 2 --out /tmp/compare      # a quick look
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from controllers.errors import DesignError
from controllers.evaluate import evaluate_agent
from controllers.evaluate_report import plot_episode
from controllers.evaluate_report import comparison_markdown
from controllers.lqg.design import design_lqg
from controllers.pd import PDController, PDGains, design_gains, loop_analysis
from controllers.rl import RESIDUAL_HISTORY, RESIDUAL_SCALE, load_agent, split_traces, train_agent
from controllers.sweep import sweep_pairs
from controllers.trace_split import draw_windows
from heli_cli.train import add_learning_options, learning_settings
from heli_core.files import jsonable, write_text
from heli_env import load_env_model

AXES = ("roll", "pitch", "yaw")


KP_FACTORS = (0.25, 1024.0)
"""Range of the coarse sweep's Kp, as factors of the designed gains (geometric)."""
KD_FACTORS = (0.25, 128.0)
"""Range of the coarse sweep's Kd, as factors of the designed gains (geometric)."""
MIN_GAIN_MARGIN_DB = 6.0
MIN_PHASE_MARGIN_DEG = 45.0
"""Margins of the sampled loop a "robust" PD pair must keep (the usual 6 dB and 45°)."""


def _robust_best(env_model, ax, results, dt):
    """The pair of smallest p90 among the stable pairs of ``results`` whose sampled loop keeps
    :data:`MIN_GAIN_MARGIN_DB` and :data:`MIN_PHASE_MARGIN_DEG`, with its margins; (None, None) if none does."""
    cands = sorted((r.row(j) for r in results for j in range(r.n_pairs)
                    if r.stable[j] and np.isfinite(r.table["att_p90_deg"][j])), key=lambda row: row["att_p90_deg"])
    for row in cands:
        m = loop_analysis(env_model.params, ax, row["kp"], row["kd"], dt).summary()
        # None: the loop never crosses, an infinite margin
        gm, pm = (math.inf if v is None else v for v in (m["gain_margin_db"], m["phase_margin_deg"]))
        if gm >= MIN_GAIN_MARGIN_DB and pm >= MIN_PHASE_MARGIN_DEG:
            return row, m
    return None, None


def swept_gains(env_model, split, design: PDGains, n: int, seconds: float, windows_per_trace: int, seed: int):
    """Per axis, the stable pair with the smallest p90 |attitude error| on windows of the training traces
    ("best"), and the same among pairs whose sampled loop keeps 6 dB of gain margin and 45° of phase margin
    ("robust"); the design where no pair qualifies.

    Two sweeps per axis: a coarse n x n grid over :data:`KP_FACTORS` x :data:`KD_FACTORS` times the design
    gains (geometric), then a 9 x 9 grid one coarse step either side of the coarse best. The coarse grid
    reaches past the sampled loop's stability boundary (the sweep marks those pairs unstable without
    simulating them; on the shipped model no pair is stable beyond about 600 times the design Kp), so the
    best pair is an optimum of the gains and not of the grid. ``at_grid_edge`` flags an axis where it is not.

    Returns (best gains, robust gains, per-axis rows, windows).
    """
    dt = 0.01
    ratio = int(round(dt * env_model.sample_rate))
    needed = int(round(seconds / dt)) * ratio + 1
    wins = draw_windows(env_model, split.train, needed, np.random.default_rng(seed), per_segment=windows_per_trace)
    fp, fd = np.geomspace(*KP_FACTORS, n), np.geomspace(*KD_FACTORS, n)
    kp, kd, rkp, rkd, rows = list(design.kp), list(design.kd), list(design.kp), list(design.kd), {}
    for i, ax in enumerate(AXES):
        KP, KD = np.meshgrid(fp * design.kp[i], fd * design.kd[i], indexing="ij")
        res = [sweep_pairs(env_model, np.column_stack([KP.ravel(), KD.ravel()]), axis=ax, duration=seconds, dt=dt,
                           traces=wins, progress=False)]
        best, margins, edge = res[0].best(), None, False
        if best is not None:
            edge = bool(np.isclose(best["kp"], KP.max()) or np.isclose(best["kd"], KD.max()))
            fine = np.meshgrid(best["kp"] * np.geomspace(1 / (fp[1] / fp[0]), fp[1] / fp[0], 9),
                               best["kd"] * np.geomspace(1 / (fd[1] / fd[0]), fd[1] / fd[0], 9), indexing="ij")
            res.append(sweep_pairs(env_model, np.column_stack([fine[0].ravel(), fine[1].ravel()]), axis=ax,
                                   duration=seconds, dt=dt, traces=wins, progress=False))
            best = min((b for b in (best, res[1].best()) if b is not None), key=lambda b: b["att_p90_deg"])
            kp[i], kd[i] = best["kp"], best["kd"]
            margins = loop_analysis(env_model.params, ax, kp[i], kd[i], dt).summary()
        robust, robust_margins = _robust_best(env_model, ax, res, dt)
        if robust is not None:
            rkp[i], rkd[i] = robust["kp"], robust["kd"]
        rows[ax] = {"best": best, "robust": robust, "pairs": sum(r.n_pairs for r in res),
                    "stable": sum(int(r.stable.sum()) for r in res), "at_grid_edge": edge, "margins": margins,
                    "robust_margins": robust_margins, "seconds": sum(r.settings["seconds"]["total"] for r in res)}
    return PDGains(kp, kd), PDGains(rkp, rkd), rows, wins


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default=None, help="model directory (default: the shipped model)")
    ap.add_argument("--out", default="compare-out")
    ap.add_argument("--minutes", type=float, default=15.0, help="wall-time budget per algorithm (default 15)")
    ap.add_argument("--timesteps", type=int, default=10**9, help="timestep cap per algorithm (default: none)")
    ap.add_argument("--algos", default="ppo,sac,ppo-residual",
                    help="comma-separated algorithms: ppo, sac, and ppo-residual / sac-residual, a residual on the "
                    "best swept PD (default ppo,sac,ppo-residual)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--split-seed", type=int, default=0,
                    help="seed of which traces are held out (default 0; another holds out another trace)")
    ap.add_argument("--n-envs", type=int, default=8)
    ap.add_argument("--episodes-per-trace", type=int, default=6, help="held-out episodes per trace (default 6)")
    ap.add_argument("--grid", type=int, default=13, help="coarse PD sweep grid size per axis (default 13 x 13; "
                    "a 9 x 9 refinement follows)")
    ap.add_argument("--residual-on", choices=("robust", "best", "lqg"), default="robust",
                    help="the controller a residual trains on: a swept PD (default robust: the best pair with 6 dB / "
                    "45 deg margins; best) or the LQG baseline (lqg)")
    ap.add_argument("--residual-scale", type=float, default=RESIDUAL_SCALE,
                    help=f"bound of the residual in stick (default {RESIDUAL_SCALE:g})")
    ap.add_argument("--surrogates", type=int, default=0,
                    help="train on N phase-randomised surrogates of each training segment instead of the recorded "
                    "ones (the evaluation stays on the recorded held-out gusts; default 0)")
    ap.add_argument("--no-reward-normalisation", action="store_true",
                    help="train on the raw rewards (default: PPO's are divided by a running estimate of the return's "
                    "spread, SB3 VecNormalize(norm_obs=False))")
    ap.add_argument("--reward-reference", choices=("base", "best"), default="base",
                    help="the PD whose error on each axis weighs that axis in a residual's reward: the residual's "
                    "base (default) or the best swept pair, so that each axis counts by how far it is from what a "
                    "PD reaches")
    add_learning_options(ap)
    ap.add_argument("--no-progress", action="store_true")
    return ap


def main(argv=None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)
    out = Path(args.out)
    env_model = load_env_model(args.model)
    split = split_traces(env_model.n_traces, seed=args.split_seed)
    ids = env_model.trace_ids
    print(f"library: {env_model.n_traces} traces; training {[ids[s.trace] for s in split.train]}, held out "
          f"{[ids[s.trace] for s in split.held_out]}" + (" (one trace split in time)" if split.in_time else ""))

    design = design_gains(env_model.params)
    t0 = time.perf_counter()
    swept, robust, sweep_rows, sweep_windows = swept_gains(env_model, split, design, args.grid, 30.0, 4, args.seed)
    print(f"PD sweep ({args.grid} x {args.grid} + 9 x 9 pairs per axis on {len(sweep_windows)} training windows): "
          f"{time.perf_counter() - t0:.1f} s")
    agents = _pd_agents(env_model, out, (design, swept, robust), sweep_rows)
    lqg = _lqg_agent(env_model, out)  # designed before training: a model it cannot take is said at once
    if args.residual_on == "lqg" and lqg is None:
        ap.error("--residual-on lqg: this model has no LQG baseline (see the note above)")
    training = _train(ap, args, env_model, agents, out, lqg)
    agents += [lqg] if lqg else []  # last: the residual's bases keep their places, results[3:] the others

    results = []
    for name, agent in agents:
        r = evaluate_agent(agent, env_model, traces="held-out", split=split,
                           episodes_per_trace=args.episodes_per_trace, seed=args.seed + 1, name=name)
        results.append(r)
    ep = results[1].representative_episode()
    paths = [plot_episode(results, out / "episode.png", ep)]
    for r in results:
        paths.append(plot_episode(r, out / f"episode_{r.name.lower().replace(' ', '_')}.png", ep))

    notes = _training_notes(args, training, agents) + _goal_notes(results) + _sweep_notes(sweep_rows, swept, robust)
    notes += ["", f"Representative episode (median RMS error of the best swept PD): {ep}; `episode.png`."]
    md = comparison_markdown(results, notes=notes)
    paths.append(write_text(out / "comparison.md", md))
    doc = jsonable({"split": split.to_dict(), "training": training, "sweep": sweep_rows,
                    "sweep_windows": sweep_windows, "representative_episode": ep,
                    "results": [r.to_dict() for r in results]})
    paths.append(write_text(out / "comparison.json", json.dumps(doc, indent=1, allow_nan=False) + "\n"))
    print(md)
    for p in paths:
        print(f"wrote {p}")
    return 0


def _pd_agents(env_model, out: Path, gains: tuple, sweep_rows: dict) -> list:
    """The designed, best swept and robust swept PD controllers of ``gains`` as (name, controller), each
    saved in ``out``."""
    design, swept, robust = gains
    agents = [("PD designed", PDController.from_model(env_model.params, design)),
              ("PD best swept", PDController.from_model(env_model.params, swept)),
              ("PD robust swept", PDController.from_model(env_model.params, robust))]
    agents[0][1].save(out / "pd_designed.json", {"model": str(env_model.path), "how": "design_gains"})
    agents[1][1].save(out / "pd_swept.json", {"model": str(env_model.path), "how": "per-axis sweep on training "
                                              "windows", "sweep": sweep_rows})
    agents[2][1].save(out / "pd_robust.json", {"model": str(env_model.path), "how": "per-axis sweep on training "
                                               f"windows, gain margin >= {MIN_GAIN_MARGIN_DB} dB and phase margin "
                                               f">= {MIN_PHASE_MARGIN_DEG} deg", "sweep": sweep_rows})
    return agents


def _lqg_agent(env_model, out: Path):
    """("LQG", controller) of :func:`controllers.lqg.design_lqg` (its defaults), saved as ``out/lqg.json``; None,
    with a note, for a model it cannot design on (no identified wind model, margins out of reach)."""
    try:
        design = design_lqg(env_model)
    except DesignError as e:
        print(f"note: no LQG baseline: {e}")
        return None
    lqg = design.controller()
    lqg.save(out / "lqg.json", {"model": str(env_model.path), "how": "design_lqg", "design": design.summary()})
    return ("LQG", lqg)


def _train(ap, args, env_model, agents: list, out: Path, lqg=None) -> dict:
    """Train each algorithm of ``--algos`` within the budget; append the trained agents to ``agents``.
    Returns the training record per algorithm."""
    training = {}
    for algo in [a.strip() for a in args.algos.split(",") if a.strip()]:
        base, _, residual = algo.partition("-")
        if base not in ("ppo", "sac") or residual not in ("", "residual"):
            ap.error(f"--algos: unknown algorithm {algo!r}")
        print(f"training {algo.upper()} for at most {args.minutes:g} min ...", flush=True)
        res = train_agent(base, env_model, args.timesteps, out / algo, seed=args.seed, split_seed=args.split_seed,
                          n_envs=args.n_envs, eval_freq=200_000 if base == "ppo" else 50_000, checkpoint_freq=500_000,
                          progress=not args.no_progress, max_seconds=60.0 * args.minutes,
                          residual=_residual_base(args, agents, lqg) if residual else None,
                          residual_scale=args.residual_scale, surrogates=args.surrogates,
                          normalize_reward=False if args.no_reward_normalisation else None,
                          reward_reference=agents[1][1] if residual and args.reward_reference == "best" else None,
                          **learning_settings(args))
        training[algo] = {"timesteps": res.timesteps, "seconds": res.seconds,
                          "steps_per_second": res.steps_per_second, "stopped_by_time": res.stopped_by_time,
                          "evaluations": res.evaluations, "agent": str(res.path)}
        print(f"  {algo.upper()}: {res.timesteps} timesteps in {res.seconds:.1f} s "
              f"({res.steps_per_second:.0f} steps/s)")
        agents.append((algo.upper(), load_agent(res.path)))
    return training


def _residual_base(args, agents: list, lqg):
    """The controller a residual trains on: the robust or best swept PD of ``agents``, or the LQG."""
    if args.residual_on == "lqg":
        return lqg[1]
    return agents[2 if args.residual_on == "robust" else 1][1]


def _training_notes(args, training: dict, agents: list) -> list[str]:
    """comparison.md's lines on the training budget and runs, and the PD gains compared."""
    notes = [f"Training on {os.cpu_count()} cores, one torch thread, {args.n_envs} environment copies, seed "
             f"{args.seed}" + (f", split seed {args.split_seed}" if args.split_seed else "")
             + f"; budget {args.minutes:g} min per algorithm; residual bound {args.residual_scale:g} stick"
             + (f" on the {args.residual_on} {'PD' if args.residual_on != 'lqg' else 'baseline'}"
                if "residual" in args.algos else "")
             + (f"; {args.surrogates} surrogates per training segment" if args.surrogates else "")
             + ("; raw rewards" if args.no_reward_normalisation else "")
             + ("; every axis scaled by the worst one" if args.no_axis_balance else "")
             + ("" if args.paired_baseline else "; no paired PD baseline")
             + (f"; a residual sees its last {args.history or RESIDUAL_HISTORY} observations"
                if "residual" in args.algos else "")
             + (f"; servo delay spread ±{1e3 * args.delay_spread:g} ms in training" if args.delay_spread else "")
             + ("; running observation statistics" if args.normalize_obs else "")
             + (f"; learning rate to 0 at {args.timesteps} steps" if args.lr_schedule == "linear" else "")
             + (f"; reward weights {args.reward_weights}" if args.reward_weights else "")
             + (f"; stick step weight {args.stick_step_weight:g}" if args.stick_step_weight else "")
             + ("; axes weighed by the best swept pair's errors" if args.reward_reference == "best" else "")
             + (f"; gusts from {args.curriculum_start:g}x to full over {args.curriculum} steps"
                if args.curriculum else "")
             + (f"; hyperparameters {json.dumps(args.algo_kwargs)}" if args.algo_kwargs else "") + ":", ""]
    for algo, t in training.items():
        notes.append(f"- {algo.upper()}: {t['timesteps']} timesteps in {t['seconds']:.0f} s "
                     f"({t['steps_per_second']:.0f} steps/s){' (time budget reached)' if t['stopped_by_time'] else ''}")
    return notes + ["", f"PD designed: {agents[0][1]!r}", f"PD best swept (per axis, on training windows): "
                    f"{agents[1][1]!r}", f"PD robust swept (the same, among pairs with gain margin >= "
                    f"{MIN_GAIN_MARGIN_DB:g} dB and phase margin >= {MIN_PHASE_MARGIN_DEG:g} deg): {agents[2][1]!r}",
                    ""]


def _goal_notes(results: list) -> list[str]:
    """Whether each RL agent meets issue 5's goal against each swept PD (p90 |attitude error| per axis)."""
    notes = ["Goal (issue 5): an RL agent with p90 |attitude error| at or below the swept PD's on every axis "
             "(the LQG baseline, not RL, for reference):", ""]
    for r in results[3:]:
        for pd_res in results[1:3]:
            met = all(r.metrics[a]["att_p90_deg"] <= pd_res.metrics[a]["att_p90_deg"] for a in AXES)
            ratio = " / ".join(f"{r.metrics[a]['att_p90_deg'] / pd_res.metrics[a]['att_p90_deg']:.2f}" for a in AXES)
            notes.append(f"- {r.name} vs {pd_res.name}: {'met' if met else 'NOT met'} (p90 ratio, roll/pitch/yaw: "
                         f"{ratio})")
    return notes


def _sweep_notes(sweep_rows: dict, swept: PDGains, robust: PDGains) -> list[str]:
    """The swept pairs per axis with the margins of their sampled loops."""
    notes = ["", "Swept pairs (sweep on training windows; margins of the sampled loop):", ""]
    for i, (ax, row) in enumerate(sweep_rows.items()):
        for label, gains, key in (("best", swept, "margins"), ("robust", robust, "robust_margins")):
            m = row[key] or {}
            gm, pm = m.get("gain_margin_db"), m.get("phase_margin_deg")
            notes.append(f"- {ax}, {label}: kp = {gains.kp[i]:.4g}, kd = {gains.kd[i]:.4g}, gain margin "
                         f"{gm if gm is None else round(gm, 1)} dB, phase margin {pm if pm is None else round(pm, 1)}"
                         " deg" + (f" ({row['stable']} of {row['pairs']} pairs stable)" if label == "best" else "")
                         + (" — AT THE GRID'S EDGE: higher gains would score better still"
                            if label == "best" and row["at_grid_edge"] else ""))
    return notes


if __name__ == "__main__":
    sys.exit(main())
