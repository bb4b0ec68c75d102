"""``heli train``: train a PPO or SAC attitude agent on the training gusts of a model's library."""

from __future__ import annotations

import argparse
import sys

from .argtypes import json_object, number, output_path, seed, seed_list, weights, whole
from .model_gate import add_accept_option, check_model


def register(sub):
    p = sub.add_parser(
        "train",
        help="train a PPO or SAC agent in the model's gusts ('rl' extra)",
        description="Train a stable-baselines3 PPO or SAC agent on the native vector environment (attitude hold "
        "in replayed gusts). Episodes replay windows of the training traces only; the held-out traces (a "
        "quarter of the library by default, chosen by --split-seed; a single-trace library is split in time) "
        "score the agent during training. At the end the final agent and a PD (heli design's, or --compare-pd) "
        "fly the same held-out gusts and a warning says where the agent holds attitude worse. Writes AGENT.zip "
        "(the final agent), and AGENT_training/ with training.json, report.md/.html (the comparison and "
        "learning_curve.png: returns and held-out p90 against timesteps), comparison.json, best_model.zip, "
        "evaluations.npz and checkpoints/. Ctrl-C saves a checkpoint first. Evaluate further with "
        "'heli evaluate AGENT.zip'.",
    )
    p.add_argument("--algo", required=True, choices=("ppo", "sac"), help="algorithm")
    p.add_argument("--model", metavar="DIR", default=None,
                   help="model directory written by 'heli identify' (default: the model shipped with heli-env)")
    add_accept_option(p, "Train an agent on it")
    p.add_argument("--timesteps", type=whole(1), default=None, metavar="N",
                   help="environment steps to train for (all copies together); with --minutes alone, training "
                   "runs until the time budget is spent")
    p.add_argument("--out", required=True, type=output_path, metavar="AGENT", help="agent path (.zip is added)")
    p.add_argument("--seed", type=seed(), default=0, help="seed of everything (default 0)")
    p.add_argument("--n-envs", type=whole(1), default=8, help="environment copies (default 8)")
    p.add_argument("--minutes", type=number("a finite number > 0", 0.0), default=None,
                   help="wall-time budget; training stops at --timesteps or this, whichever comes first "
                   "(give --timesteps, --minutes or both)")
    p.add_argument("--eval-freq", type=whole(0), default=50_000, metavar="N",
                   help="timesteps between held-out evaluations (0: none; default 50000)")
    p.add_argument("--eval-episodes", type=whole(1), default=4, help="held-out episodes per evaluation (default 4)")
    p.add_argument("--checkpoint-freq", type=whole(0), default=100_000, metavar="N",
                   help="timesteps between checkpoints (0: none; default 100000)")
    p.add_argument("--episode-seconds", type=number("seconds >= 0.01 (one control period)", 0.01, low_open=False), default=30.0,
                   help="episode length in s (default 30)")
    p.add_argument("--held-out-fraction", type=number("a fraction in (0, 1)", 0.0, 1.0), default=0.25,
                   help="fraction of the library's traces held out (default 0.25)")
    p.add_argument("--split-seed", type=seed(), default=0, help="seed of the held-out choice (default 0)")
    p.add_argument("--seeds", type=seed_list, default=None, metavar="S1,S2,...",
                   help="train one agent per seed, each as a task of --backend (one torch thread each); agents "
                   "are written to AGENT_seed<S>.zip and AGENT_seed<S>_training/ (overrides --seed)")
    p.add_argument("--backend", default="local", choices=("local", "ray"),
                   help="where --seeds train: 'local' (default) this machine's cores, 'ray' the Ray cluster at "
                   "RAY_ADDRESS or a Ray instance started here (needs the 'cluster' extra)")
    p.add_argument("--workers", type=whole(1), default=None, metavar="N",
                   help="local worker processes for --seeds, or CPUs of a Ray instance started here "
                   "(default: all cores)")
    p.add_argument("--residual", metavar="PD.json", default=None,
                   help="train a residual on this PD controller (from 'heli design' or a sweep): the env receives "
                   "the PD's command plus --residual-scale times the agent's action; reward and observation scales "
                   "follow the PD's own errors on the training gusts")
    p.add_argument("--surrogates", type=whole(0), default=0, metavar="N",
                   help="train on N phase-randomised surrogates of each training segment (same spectra, new gusts) "
                   "instead of the recorded segments; the evaluation stays on the recorded held-out gusts "
                   "(default 0)")
    p.add_argument("--residual-scale", type=number("a number in (0, 2]", 0.0, 2.0, high_open=False),
                   default=None, metavar="STICK",
                   help="bound of the residual in stick units (default 0.3, controllers.rl.RESIDUAL_SCALE)")
    p.add_argument("--reward-reference", metavar="PD.json", default=None,
                   help="with --residual: weigh each axis of the reward by the error this PD (e.g. the best pair of "
                   "'heli sweep') leaves on the training gusts, instead of the --residual PD's own")
    p.add_argument("--compare-pd", metavar="PD.json", default=None,
                   help="the PD the final agent is compared with on the held-out gusts (default: the --residual "
                   "base, else the PD 'heli design' writes for the model with its defaults)")
    p.add_argument("--no-compare", action="store_true",
                   help="skip the end-of-training comparison with the PD (the learning curve is still drawn)")
    add_learning_options(p)
    p.set_defaults(func=run, out_kind="file")


def add_learning_options(p) -> None:
    """The options of how an agent learns (TrainConfig's ``axis_balance``, ``paired_baseline``, ``history``,
    ``normalize_obs``, ``lr_schedule``, ``reward_weights``, ``stick_step_weight``, the gust curriculum,
    ``algo_kwargs``, ``delay_spread``), shared with ``scripts/train_compare.py``; :func:`learning_settings` reads them."""
    p.add_argument("--no-axis-balance", action="store_true",
                   help="scale a residual's reward and observations by its PD's worst axis on every axis (default: "
                   "each axis by its own error level, so that every axis counts alike in the reward)")
    p.add_argument("--paired-baseline", action=argparse.BooleanOptionalAction, default=True,
                   help="with --residual: each training copy has a twin flying the PD alone on the same gusts, start "
                   "and sensor noise, and the residual is rewarded for the difference (twice the env copies; the "
                   "default; --no-paired-baseline: each copy's own return)")
    p.add_argument("--history", type=whole(1), default=None, metavar="N",
                   help="with --residual: the policy sees the last N observations side by side (default 4; 1: the "
                   "current one only), so it can tell what the servo delay still holds and what the gust is doing")
    p.add_argument("--normalize-obs", action="store_true",
                   help="standardise observations by running statistics of the training rollouts (SB3's "
                   "VecNormalize, kept inside the policy so the saved agent takes raw observations); default: "
                   "fixed scales")
    p.add_argument("--reward-weights", type=weights(3), default=None, metavar="ATT,RATE,EFFORT",
                   help="weights of the reward's attitude, rate and control-effort terms (default 1,0.01,0.01 with "
                   "--residual, else 1,0.1,0.01); the error figures compared are attitude only")
    p.add_argument("--stick-step-weight", type=number("a weight >= 0", 0.0, low_open=False), default=0.0,
                   metavar="W",
                   help="weight of the squared change of the applied stick from one step to the next in the reward "
                   "(default 0): charges the chatter a servo feels, which the effort weight charges only by its size")
    p.add_argument("--lr-schedule", choices=("constant", "linear"), default="constant",
                   help="learning rate constant (default) or falling linearly to 0 at --timesteps (with a time "
                   "budget, give --timesteps about what the budget allows)")
    p.add_argument("--curriculum", type=whole(0), default=0, metavar="STEPS",
                   help="gust curriculum: training gusts rise linearly from --curriculum-start times their level to "
                   "the full level over the first STEPS timesteps (default 0: full gusts throughout; the held-out "
                   "evaluations always fly full gusts)")
    p.add_argument("--curriculum-start", type=number("a gust multiplier in [0, 1)", 0.0, 1.0, low_open=False),
                   default=0.5, metavar="X", help="gust multiplier of the first training episodes (default 0.5)")
    p.add_argument("--delay-spread", type=number("a delay spread in seconds >= 0", 0.0, low_open=False), default=0.0,
                   metavar="SECONDS",
                   help="domain randomisation of the servo delay: training copies fly the identified delay shifted by "
                   "4 evenly spaced values from -SECONDS to +SECONDS (at most 0.1, "
                   "controllers.rl.config.MAX_DELAY_SPREAD; default 0: as identified); the held-out evaluations fly "
                   "it as identified")
    p.add_argument("--algo-kwargs", type=json_object, default=None, metavar="JSON",
                   help="SB3 hyperparameters over the defaults, e.g. '{\"gamma\": 0.995}' or, for a residual, "
                   "'{\"use_sde\": false}' (white-noise exploration instead of the default gSDE)")


def learning_settings(args) -> dict:
    """The TrainConfig fields of :func:`add_learning_options`' options."""
    return {"axis_balance": not args.no_axis_balance, "paired_baseline": args.paired_baseline,
            "history": args.history, "normalize_obs": args.normalize_obs, "curriculum_steps": args.curriculum,
            "curriculum_start": args.curriculum_start, "lr_schedule": args.lr_schedule,
            "reward_weights": args.reward_weights, "algo_kwargs": args.algo_kwargs,
            "delay_spread": args.delay_spread, "stick_step_weight": args.stick_step_weight}



def _config(args):
    """The TrainConfig of the command line; a --residual PD file is read here, so a bad one fails before any work."""
    from controllers.rl.config import TrainConfig

    from controllers.errors import AgentError
    from controllers.rl.config import UNLIMITED_TIMESTEPS

    if args.timesteps is None and args.minutes is None:
        raise AgentError("give --timesteps N (environment steps), --minutes M (a time budget) or both")
    if args.timesteps is None and args.lr_schedule == "linear":
        raise AgentError("--lr-schedule linear falls to 0 at --timesteps: give --timesteps with it (about what "
                         "--minutes allows)")
    timesteps = UNLIMITED_TIMESTEPS if args.timesteps is None else args.timesteps
    return TrainConfig(algo=args.algo, timesteps=timesteps, seed=args.seed, n_envs=args.n_envs,
                       eval_freq=args.eval_freq, checkpoint_freq=args.checkpoint_freq,
                       held_out_fraction=args.held_out_fraction, split_seed=args.split_seed,
                       eval_episodes=args.eval_episodes, episode_seconds=args.episode_seconds,
                       residual=args.residual, surrogates=args.surrogates, reward_reference=args.reward_reference,
                       **({} if args.residual_scale is None else {"residual_scale": args.residual_scale}),
                       max_seconds=None if args.minutes is None else 60.0 * args.minutes, **learning_settings(args))


def _run_seeds(args, config, progress) -> int:
    from controllers.rl.seeds import train_seeds
    from heli_core.backends import make_backend

    backend = make_backend(args.backend, workers=args.workers)
    try:
        results = train_seeds(model=args.model, out=args.out, seeds=args.seeds, backend=backend,
                              progress=not args.quiet, config=config)
        where = backend.describe()
    finally:
        backend.close()
    reference = {}  # the PD compared with, made once for every seed
    reports = {s: _report(args, res, progress, reference) for s, res in results.items()}
    print(f"heli train: {args.algo.upper()}, {len(results)} seeds on {where}")
    for k, res in results.items():  # not `seed` (nor `number`): argument types imported above
        last = f"; held-out return {res.evaluations[-1][1]:.2f}" if res.evaluations else ""
        why = " (time budget reached)" if res.stopped_by_time else ""
        print(f"  seed {k}: {res.timesteps} timesteps in {res.seconds:.1f} s{why}{last}; wrote {res.path}")
        _print_report(reports[k], f"  seed {k} ")
    return 0


def _comparison_pd(args, env_model, dt: float):
    """(PD, label) the agent is compared with: --compare-pd, the --residual base, or heli design's defaults."""
    from controllers.rl.residual_agent import as_base
    from controllers.rl.training_report import reference_pd

    if args.compare_pd is not None:
        return as_base(args.compare_pd, "--compare-pd"), str(args.compare_pd)
    if args.residual is not None:
        return as_base(args.residual, "--residual"), f"the residual's base {args.residual}"
    return reference_pd(env_model, dt), "heli design's defaults"


def _report(args, res, progress, reference=None) -> dict:
    """Compare the run's final agent with the PD (unless --no-compare), draw the learning curve, write
    report.md/.html and comparison.json in the run folder; what was written and the comparison.
    ``reference`` (a dict) keeps the model and the PD for the next run of a --seeds command."""
    import json

    from controllers.rl.agent_file import load_agent
    from controllers.rl.training_report import compare_with_pd, plot_learning_curve, training_markdown
    from controllers.trace_split import TraceSegment
    from heli_core.files import write_text
    from heli_env.env_model import load_env_model

    from .html_report import write_html_report

    meta, comparison, paths = res.metadata, None, []
    if not args.no_compare:
        progress.stage(f"flying {res.path.name} and the controller it is compared with on the same held-out gusts")
        reference = {} if reference is None else reference
        if not reference:
            env_model = load_env_model(args.model)
            reference.update(env_model=env_model, pd=_comparison_pd(args, env_model, meta["dt"]))
        env_model, (pd, label) = reference["env_model"], reference["pd"]
        task = meta["task"] if isinstance(meta["task"], str) else meta["task"]["task"]
        comparison = compare_with_pd(load_agent(res.path), pd, env_model,
                                     [TraceSegment(**d) for d in meta["eval_segments"]], meta["seed"],
                                     meta["episode_seconds"], task, label)
        paths.append(write_text(res.run_dir / "comparison.json",
                                json.dumps(comparison.to_dict(), indent=1, allow_nan=False) + "\n"))
    progress.stage("drawing the learning curve")
    paths.append(plot_learning_curve(res.learning_curve, res.run_dir / "learning_curve.png", comparison,
                                     res.timesteps, f"{res.algo.upper()} seed {meta['seed']}: learning curve"))
    report = write_text(res.run_dir / "report.md", training_markdown(res, comparison))
    paths += [report, write_html_report(report)]
    progress.done()
    return {"comparison": comparison, "paths": paths}


def _print_report(report: dict, indent: str = "") -> None:
    """The comparison's table (agent vs PD p90 per axis), the warning on stderr, and what was written."""
    comparison = report["comparison"]
    if comparison is not None:
        kind = comparison.base_kind
        print(f"{indent}p90 |attitude error| on the held-out gusts, agent vs {kind} ({comparison.pd_label}):")
        for ax, a, p, r in zip(("roll", "pitch", "yaw"), comparison.p90("agent"), comparison.p90("pd"),
                               comparison.ratios):
            print(f"{indent}  {ax:5s}: agent {a:.4g} deg, {kind} {p:.4g} deg (x{r:.3g})")
        if comparison.warning():
            print(f"heli train: {comparison.warning()}", file=sys.stderr)
    for path in report["paths"]:
        print(f"{indent}wrote {path}")


def run(args) -> int:
    from .progress import progress_of

    check_model(args, "train an agent on it")  # an unusable model is refused before any work
    if args.compare_pd is not None and not args.no_compare:  # a bad PD file is named before training, not after
        from controllers.rl.residual_agent import as_base

        as_base(args.compare_pd, "--compare-pd")
    progress = progress_of(args)
    progress.stage("loading stable-baselines3, torch and the model; training shows its own bar on a terminal")
    from controllers.errors import TrainingInterrupted
    from controllers.rl.train import train_agent

    if args.seeds is not None:
        progress.done()
        return _run_seeds(args, _config(args), progress)
    try:
        progress.done()
        res = train_agent(model=args.model, out=args.out, config=_config(args), progress=not args.quiet)
    except TrainingInterrupted as e:
        print(f"heli train: interrupted after {e.timesteps} timesteps; checkpoint saved to {e.checkpoint}",
              file=sys.stderr)
        return 130
    report = _report(args, res, progress)
    why = " (time budget reached)" if res.stopped_by_time else ""
    print(f"heli train: {res.algo.upper()} trained for {res.timesteps} timesteps in {res.seconds:.1f} s "
          f"({res.steps_per_second:.0f} steps/s){why}")
    if res.evaluations:
        t, mean, std = res.evaluations[-1]
        best = max(res.evaluations, key=lambda e: e[1])
        print(f"held-out return: last {mean:.2f} ± {std:.2f} at {t} steps; best {best[1]:.2f} at {best[0]} steps")
    print(f"wrote {res.path}")
    print(f"wrote {res.run_dir / 'training.json'}")
    if res.best_model is not None:
        print(f"wrote {res.best_model}")
    else:  # say why the files the help names are absent, instead of leaving them silently out
        print(f"no held-out evaluation ran (--eval-freq {args.eval_freq} against {res.timesteps} timesteps): "
              "no best_model.zip or evaluations.npz")
    if res.checkpoints:
        print(f"wrote {len(res.checkpoints)} checkpoints in {res.run_dir / 'checkpoints'}")
    else:
        print(f"no checkpoint (--checkpoint-freq {args.checkpoint_freq} against {res.timesteps} timesteps)")
    _print_report(report)
    return 0
