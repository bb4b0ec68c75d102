"""``heli evaluate``: any agent (PD or LQG JSON, PPO/SAC zip, or a firmware's gains with ``--firmware``) on
held-out gusts, with the sweep's metrics."""

from __future__ import annotations

import json
from pathlib import Path

from .argtypes import number, output_path, per_axis, seed, whole
from .model_gate import add_accept_option, check_model
from .tune import FIRMWARE_CHOICES

DEFAULT_OUT = "evaluation"
DEFAULT_EPISODE_S = 30.0
"""Episode length flown unless told [s]."""
MIN_EPISODE_S = 5.0
"""Shortest episode the default is shortened to for a short flight's traces [s]: below it an episode says little
of the gusts, and the refusal names the longest that fits instead."""


def register(sub):
    p = sub.add_parser(
        "evaluate",
        help="fly a PD or RL agent in held-out gusts; report its errors",
        description="Fly any agent on gust windows of the model's disturbance library (attitude hold, start at "
        "rest) and report per axis the RMS and 50/90/99th percentiles of |attitude error| and |rate error|, "
        "stick RMS and p99, saturation and a histogram, as 'heli sweep' does for PD gain pairs. The held-out "
        "traces are those the agent was trained without (recorded in an RL agent's zip), else the default split "
        "of 'heli train'. Writes DIR/evaluation.json, evaluation.md, episode.png (a representative episode) and "
        "servo.png (the stick's stretch and spectrum per axis: how hard the agent works its servos).",
    )
    p.add_argument("agent", metavar="AGENT",
                   help="PD controller JSON (PDController.save), LQG JSON (heli design --lqg) or PPO/SAC zip; with "
                   "--firmware, the firmware's parameter file (or its log, whose parameters are read)")
    p.add_argument("--firmware", choices=FIRMWARE_CHOICES, default=None,
                   help="AGENT holds this firmware's gains (ArduPilot .param NAME,VALUE lines or a .bin log; "
                   "Rotorflight CLI 'set' lines or a blackbox log): fly the firmware's own attitude loop at its "
                   "loop rate, as 'heli tune' does (the physics sub-stepped to it)")
    p.add_argument("--scale", type=per_axis("one number > 0 or three separated by ',' (roll,pitch,yaw)"),
                   default=None, metavar="S|R,P,Y",
                   help="with --firmware: model stick per firmware output unit (one number, or roll,pitch,yaw; "
                   "'heli tune' prints the one it measured from the log and records it in tune.json); default 1")
    p.add_argument("--model", metavar="DIR", default=None,
                   help="model directory written by 'heli identify' (default: the model shipped with heli-env)")
    add_accept_option(p, "Fly an agent on it")
    p.add_argument("--traces", default="held-out", choices=("held-out", "all", "train"),
                   help="which library traces to fly (default held-out)")
    p.add_argument("--episodes-per-trace", type=whole(1), default=4, help="episodes per trace (default 4)")
    p.add_argument("--episode-seconds", type=number("seconds >= 0.01 (one control period)", 0.01, low_open=False),
                   default=None, help=f"episode length in s (default {DEFAULT_EPISODE_S:g}, or the longest that fits "
                   "every flown trace when a short flight's traces are shorter; said when so)")
    p.add_argument("--seed", type=seed(), default=0, help="seed of the gust windows (default 0)")
    p.add_argument("--split-seed", type=seed(), default=None, metavar="N",
                   help="held-out traces of 'heli train --split-seed N', for an agent that carries no split (a PD "
                   "JSON); an RL agent flies its own training split (default: that, else 0)")
    p.add_argument("--out", default=DEFAULT_OUT, type=output_path, metavar="DIR", help=f"output directory (default ./{DEFAULT_OUT})")
    p.add_argument("--no-plots", action="store_true", help="do not draw episode.png and servo.png")
    p.add_argument("--robustness", action="store_true",
                   help="also fly the agent with 20 ms more servo delay and the control gains 20 %% lower and "
                   "higher (same windows); prints the p90 degradation and writes DIR/robustness.json and "
                   "robustness.md")
    p.set_defaults(func=run, out_kind="dir")


def _episode_seconds(args, env_model, split) -> tuple[float, str | None]:
    """The episode length flown, and a note when the default was shortened to fit the traces."""
    if args.episode_seconds is not None:
        return args.episode_seconds, None
    from controllers.trace_split import as_segments, longest_episode_s

    longest = longest_episode_s(env_model, as_segments(args.traces, split, "held-out"))
    if longest >= DEFAULT_EPISODE_S or longest < MIN_EPISODE_S:  # fits, or too short: the flight says why
        return DEFAULT_EPISODE_S, None
    return longest, (f"note: episodes of {longest:g} s, the longest that fits every {args.traces} trace (the default "
                     f"{DEFAULT_EPISODE_S:g} s does not); pass --episode-seconds to choose")


def _check_control_period(agent, env_model, args) -> None:
    """Refuse a PD designed for a control period the model's gust traces cannot be stepped at (a 0.01 s design
    on a 50 Hz log's model), naming the design that can be flown (a PD is flown at the period it was designed
    for, :class:`controllers.evaluate.EvaluationConfig`)."""
    import math

    from controllers.errors import AgentError
    from controllers.pd.controller import PDController

    from .control_period import control_period

    if not isinstance(agent, PDController):
        return
    ratio = agent.dt * env_model.sample_rate
    if round(ratio) >= 1 and math.isclose(ratio, round(ratio), abs_tol=1e-6):
        return
    fits = control_period(env_model.sample_rate)[0]
    model = f" --model {args.model}" if args.model else ""
    raise AgentError(f"{args.agent} was designed for a control period of {agent.dt:g} s, which is not a whole number "
                     f"of this model's gust sample period ({1.0 / env_model.sample_rate:g} s, {env_model.sample_rate:g} "
                     f"Hz traces): design the PD on this model (heli design{model}, which picks {fits:g} s) or with "
                     f"heli design --dt {fits:g}")


def _firmware_gains(args):
    """With ``--firmware``: ``(spec, params, scale, notes)`` of the gains in ``args.agent``, else None; every bad
    input (``--scale`` alone, a missing or malformed file, the other firmware's file) refused here, before any
    work."""
    from controllers.errors import AgentError
    from controllers.firmware.firmwares import FIRMWARES
    from controllers.firmware.scale import default_scale, user_scale

    if args.firmware is None:
        if args.scale is not None:
            raise AgentError("--scale is the firmware's command scale: give it with --firmware")
        return None
    spec = FIRMWARES[args.firmware]
    if not Path(args.agent).is_file():
        raise FileNotFoundError(2, "no such parameter file or log", str(args.agent))
    params, notes = spec.gains(args.agent)
    scale = (user_scale(args.scale) if args.scale is not None
             else default_scale("no --scale given (heli tune measures it from the firmware's log)"))
    notes = [f"gains read from {args.agent}: {n}" for n in notes]
    return spec, params, scale, notes + ([f"command scale: {scale.detail}"] if scale.source == "default" else [])


def _agent(args, env_model, firmware):
    """``(agent, label, metadata, evaluate, notes)``: what ``args.agent`` names (``firmware``: what
    :func:`_firmware_gains` read), and the function that flies it."""
    from controllers.agent_description import describe_agent
    from controllers.evaluate import evaluate_agent
    from controllers.rl.agent_file import agent_metadata, load_agent

    if firmware is not None:
        from controllers.firmware.loop_rate_env import evaluate_firmware
        from controllers.firmware.tune import control_signs

        spec, params, scale, notes = firmware
        loop = spec.loop_class(params, scale.scale, control_signs(env_model.params))
        label = f"{Path(args.agent).name} ({args.firmware} loop at {loop.loop_rate_hz:g} Hz)"
        return loop, label, {}, evaluate_firmware, notes
    agent = load_agent(args.agent)
    return (agent, f"{Path(args.agent).name} ({describe_agent(agent)[0]})", agent_metadata(args.agent),
            evaluate_agent, [])


def run(args) -> int:
    from controllers.errors import AgentError
    from controllers.evaluate import EvaluationConfig
    from controllers.evaluate_report import evaluation_markdown, plot_episode
    from controllers.trace_split import TraceSplit, split_traces
    from heli_env.env_model import load_env_model
    from heli_core.files import write_text

    from .progress import progress_of

    check_model(args, "fly an agent on it")  # an unusable model is refused before any work
    firmware = _firmware_gains(args)
    progress = progress_of(args)
    progress.stage(f"loading {args.agent} and the model")
    env_model = load_env_model(args.model)
    agent, label, meta, evaluate, notes = _agent(args, env_model, firmware)
    for line in notes:
        progress.done()
        print(f"note: {line}")
    if meta and meta.get("split") and meta["split"].get("n_traces") == env_model.n_traces:
        split, origin = TraceSplit.from_dict(meta["split"]), "the agent's training split"
        if args.split_seed is not None and args.split_seed != split.seed:
            raise AgentError(f"{args.agent} was trained with split seed {split.seed}; --split-seed "
                             f"{args.split_seed} would fly traces it trained on (leave the option out)")
    else:
        split = split_traces(env_model.n_traces, seed=args.split_seed or 0)
        origin = "default split" if not args.split_seed else f"split seed {args.split_seed}"
    _check_control_period(agent, env_model, args)
    episode_seconds, note = _episode_seconds(args, env_model, split)
    if note:
        print(note)
    progress.stage(f"flying {args.traces} traces' episodes")
    episodes = EvaluationConfig(traces=args.traces, episodes_per_trace=args.episodes_per_trace,
                                episode_seconds=episode_seconds, seed=args.seed, split=split)
    res = evaluate(agent, env_model, episodes, name=label)
    out = Path(args.out)
    progress.stage("writing the report" + ("" if args.no_plots else " and drawing an episode and the sticks"))
    paths = [res.to_json(out / "evaluation.json"), write_text(out / "evaluation.md", evaluation_markdown(res))]
    if not args.no_plots:
        paths.append(plot_episode(res, out / "episode.png"))
        paths.append(res.plot_servo_activity(out / "servo.png"))
    progress.done()
    st = res.settings
    print(f"heli evaluate: {res.name} on {len(res.episodes)} episodes of {st['episode_seconds']:g} s, "
          f"{args.traces} traces {', '.join(st['trace_ids_used'])} ({origin})")
    for ax in ("roll", "pitch", "yaw"):
        m = res.metrics[ax]
        print(f"  {ax:5s}: |attitude error| RMS {m['att_rms_deg']:.3f}, p50 {m['att_p50_deg']:.3f}, p90 "
              f"{m['att_p90_deg']:.3f}, p99 {m['att_p99_deg']:.3f} deg; |rate error| p90 {m['rate_p90_dps']:.3f} "
              f"deg/s; stick RMS {m['stick_rms']:.3f}, RMS step {res.activity[ax]['stick_step_rms']:.3f} per "
              f"period, saturated {100 * m['saturation']:.1f} %")
    print(f"  mean return {res.mean_return:.2f}; episodes ended early: {res.n_terminated}")
    if args.robustness:
        from controllers.robustness import robustness_check

        check = robustness_check(agent, env_model, evaluate=evaluate, config=episodes)  # the same windows, split
        lines = [f"{case:18s}: p90 " + ", ".join(f"{a} {r['p90_deg'][a]:.3f} deg (x{r['ratio'][a]:.2f})"
                                                 for a in r["p90_deg"]) + f"; ended early {r['ended_early']}"
                 for case, r in check.items()]
        print("\n".join("  " + line for line in lines))
        paths.append(write_text(out / "robustness.json", json.dumps({"agent": res.name, "cases": check},
                                                                    indent=1, allow_nan=False) + "\n"))
        paths.append(write_text(out / "robustness.md", f"# Robustness of {res.name}\n\n"
                                "p90 |attitude error| with the aircraft off the model, on the same windows "
                                "(ratio to nominal in brackets):\n\n" + "\n".join(f"- {line}" for line in lines)
                                + "\n"))
    for path in paths:
        print(f"wrote {path}")
    from .html_report import write_html_report  # evaluation.md links no figure: the PNGs are appended

    print(f"wrote {write_html_report(paths[1], figures=[p for p in paths[2:] if p.suffix == '.png'])}")
    return 0

