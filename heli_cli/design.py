"""``heli design``: per-axis PD gains designed with python-control on an identified model.

Writes the controller that ``heli evaluate`` flies (``pd.json``), a Markdown table of
the loop properties of each axis (``design.md``), the closed-loop step responses
(``step.png``), one Bode figure per axis (``bode_<axis>.png``) and the servo activity of
the design flown in the model's gusts beside the same design without its derivative
filter (``servo.png``); ``design.html`` is the report with its figures inside. With ``--lqg``
it designs the LQG of :mod:`controllers.lqg` instead (:mod:`heli_cli.design_lqg`: ``lqg.json`` and
``lqg.md``).
"""

from __future__ import annotations

from pathlib import Path

from .argtypes import number, output_path, per_axis
from .control_period import DEFAULT_DT, control_period
from .model_gate import add_accept_option, check_model

DEFAULT_OUT = "pd"
AXES = ("roll", "pitch", "yaw")


def _bandwidths(text):
    """One bandwidth for every axis or three (roll,pitch,yaw), each a positive number in rad/s."""
    return per_axis("one positive bandwidth in rad/s or three (roll,pitch,yaw)")(text)


def _d_filter(text):
    """``auto`` (the design's rule), ``off``, one cutoff in Hz for every axis or three (roll,pitch,yaw)."""
    word = str(text).strip().lower()
    if word in ("auto", "off"):
        return "auto" if word == "auto" else None
    return per_axis("'auto', 'off', one positive cutoff in Hz or three (roll,pitch,yaw)")(text)


def register(sub):
    p = sub.add_parser(
        "design",
        help="design per-axis PD attitude gains (python-control)",
        description="Design per-axis PD attitude controllers on the linear part of an identified model "
        "(the Padé servo of eq. 31 included when identified), sampled at the control period by zero-order "
        "hold as the environment runs them: each axis reaches the requested closed-loop bandwidth with at "
        "least the requested phase margin (default bandwidth: five times the bare airframe's rate pole, or "
        "half the largest the margin allows). The D term is low-passed (--d-filter-hz; default: a cutoff 20 "
        "times the loop's crossover) and the design includes the filter, so the margins hold for the filtered "
        "PD. Writes DIR/pd.json (the controller), design.md (margins, crossover, bandwidth, closed-loop poles, "
        "servo activity), step.png, bode_<axis>.png and servo.png, and design.html (the report, figures inside).",
    )
    p.add_argument("--model", metavar="DIR", default=None,
                   help="model directory written by 'heli identify' (default: the model shipped with heli-env)")
    add_accept_option(p, "Design a controller on it")
    p.add_argument("--phase-margin", type=number("a phase margin in (0, 180) degrees", 0.0, 180.0), default=45.0,
                   help="least phase margin in deg (default 45)")
    p.add_argument("--bandwidth", type=_bandwidths, default=None, metavar="W[,W,W]",
                   help="closed-loop -3 dB bandwidth in rad/s, one for all axes or roll,pitch,yaw")
    p.add_argument("--d-filter-hz", type=_d_filter, default="auto", metavar="auto|off|F[,F,F]",
                   help="first-order low-pass on the D term: 'auto' (default) a cutoff 20 times each loop's "
                   "crossover (controllers.pd.D_FILTER_RATIO), 'off' none, or a cutoff in Hz for every axis or "
                   "roll,pitch,yaw; the design keeps the phase margin with the filter in the loop")
    p.add_argument("--dt", type=number("a control period in s, 0 < dt < 1", 0.0, 1.0),
                   default=None, help=f"control period in s (default {DEFAULT_DT:g}, the env's, or the shortest "
                   "whole number of the model's gust sample periods above it: 0.02 for a model of a 50 Hz log)")
    p.add_argument("--out", default=DEFAULT_OUT, type=output_path, metavar="DIR", help=f"output directory (default ./{DEFAULT_OUT})")
    p.add_argument("--no-plots", action="store_true",
                   help="do not draw step.png, the Bode figures and servo.png (nor fly the design for the last); "
                   "with --lqg, recovery.png and the Bode figures")
    p.add_argument("--lqg", action="store_true",
                   help="design the LQG instead (controllers.lqg: a Kalman filter on the identified wind model and "
                   "sensors, an LQR, >= 6 dB and --phase-margin at the plant input); writes DIR/lqg.json, which "
                   "heli evaluate flies, lqg.md, recovery.png (from a 2 deg attitude error), bode_<axis>.png (each "
                   "loop at the plant input) and lqg.html")
    p.set_defaults(func=run, out_kind="dir")


def design_markdown(model_path, analyses, phase_margin, bandwidth, plots: bool = True, activity=None) -> str:
    """The design report: one row per axis of :meth:`controllers.pd.LoopAnalysis.summary`, and the servo
    activity table (``activity``, Markdown) when the design was flown."""
    asked = "default (5 x rate pole)" if bandwidth is None else f"{bandwidth} rad/s"
    lines = [
        "# PD attitude controller", "",
        f"Model: `{model_path}`. Requested phase margin {phase_margin:g} deg, bandwidth {asked}; "
        "loop analysed in discrete time (zero-order hold at the control period), the derivative filter included.",
        "",
        "| axis | kp [stick/rad] | kd [stick/(rad/s)] | D filter [Hz] | phase margin [deg] | gain margin [dB] "
        "| crossover [rad/s] | bandwidth [rad/s] | largest pole radius | stable |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for an in analyses:
        s = an.summary()

        def f(v, spec=".3g"):
            return "—" if v is None else format(v, spec)
        lines.append(f"| {an.axis} | {an.kp:.4g} | {an.kd:.4g} | {f(an.d_filter_hz, '.3g') if an.d_filter_hz else 'none'} | "
                     f"{f(s['phase_margin_deg'], '.1f')} | "
                     f"{f(s['gain_margin_db'], '.1f')} | {f(s['gain_crossover_rad_s'])} | "
                     f"{f(s['bandwidth_rad_s'])} | {f(s['max_pole_radius'], '.4f')} | {'yes' if an.stable else 'NO'} |")
    lines += ["", "Control law per axis: `a = clip(sign(k)·(kp·e_angle + kd·y), −1, 1)` on the environment's "
              "observation, `y` the rate error through the D filter (`y = a·y_prev + (1 − a)·e_rate`, "
              "`a = exp(−2π·f_c·dt)`; `y = e_rate` without one).", ""]
    if activity:
        lines += ["## Servo activity", "", activity, ""]
    if plots:
        lines += ["![step responses](step.png)", ""] + [f"![Bode {an.axis}](bode_{an.axis}.png)" for an in analyses]
        if activity and not activity.startswith("Not flown"):
            lines += ["", "![servo activity](servo.png)"]
    return "\n".join(lines) + "\n"


ACTIVITY_EPISODES = {"traces": "held-out", "episodes_per_trace": 2, "episode_seconds": 10.0}
"""The gusts a design is flown on for its servo activity (a few seconds of work); a short flight's held-out
trace (a 27 s Betaflight log leaves 6.8 s) is flown in the longest episode that fits it instead."""


def _activity_episodes(env_model) -> dict:
    """:data:`ACTIVITY_EPISODES`, the episode shortened to the longest that fits every held-out trace."""
    from controllers.trace_split import as_segments, longest_episode_s, split_traces

    longest = longest_episode_s(env_model, as_segments("held-out", split_traces(env_model.n_traces)))
    return {**ACTIVITY_EPISODES, "episode_seconds": min(ACTIVITY_EPISODES["episode_seconds"], longest)
            if longest > 0 else ACTIVITY_EPISODES["episode_seconds"]}  # none fits: the evaluator says why


def _servo_activity(env_model, params, gains, dt, out, design_kwargs):
    """Fly the design (and, when it has a derivative filter, the same request without one) on held-out gusts;
    the activity table's Markdown and the path of servo.png."""
    from controllers.evaluate import evaluate_agent
    from controllers.pd.controller import PDController
    from controllers.pd.design import design_gains
    from controllers.servo_activity import activity_table

    flown = [("this design", gains)]
    if gains.filtered:
        flown.append(("same request, no D filter", design_gains(params, **{**design_kwargs, "d_filter_hz": None})))
    episodes = _activity_episodes(env_model)
    results = [evaluate_agent(PDController.from_model(params, g, dt), env_model, name=name, **episodes)
               for name, g in flown]
    st = results[0].settings
    where = (f"Flown in the model's gusts ({len(results[0].episodes)} episodes of {st['episode_seconds']:g} s on "
             f"held-out traces {', '.join(st['trace_ids_used'])}, attitude hold, the model's sensors): the stick's "
             "increment per control period is the chatter the servos see.")
    p90 = "; ".join(f"{r.name}: p90 |attitude error| " + ", ".join(
        f"{a} {r.metrics[a]['att_p90_deg']:.3g}°" for a in AXES) for r in results)
    text = where + "\n\n" + activity_table(results) + "\n\n" + p90 + "."
    return text, results[0].plot_servo_activity(out / "servo.png", others=results[1:])


def _filter_notes(analyses, dt: float) -> list[str]:
    """A note per axis whose D-filter cutoff lies above the loop's Nyquist frequency ``0.5 / dt``: sampled at
    ``dt`` its pole ``exp(-2 pi f dt)`` is all but zero, so it filters nothing (the auto rule, 20 times the
    crossover, gives 226 Hz at a 100 Hz loop on the Betaflight quad's fast model)."""
    nyquist = 0.5 / dt
    high = [an for an in analyses if an.d_filter_hz is not None and an.d_filter_hz > nyquist]
    if not high:
        return []
    cuts = ", ".join(f"{an.axis} {an.d_filter_hz:.4g} Hz" for an in high)
    return [f"note: D filter above the loop's Nyquist frequency ({nyquist:g} Hz at --dt {dt:g} s): {cuts}; it "
            "filters nothing there (pass --d-filter-hz below it, or off)"]


def run(args) -> int:
    from controllers.errors import AgentError, DesignError
    from controllers.pd.analysis import loop_analysis
    from controllers.pd.controller import PDController
    from controllers.pd.design import design_gains
    from controllers.pd.figures import plot_bode, plot_step_responses
    from heli_env.env_model import load_env_model
    from heli_core.files import write_text

    from .progress import progress_of

    check_model(args, "design a controller on it")  # an unusable model is refused before any work
    if args.lqg:
        from .design_lqg import run_lqg

        return run_lqg(args)
    with progress_of(args) as progress:
        progress.stage("designing the PD gains and analysing each axis' loop")
        env_model = load_env_model(args.model)
        params = env_model.params
        if args.dt is None:
            args.dt, note = control_period(env_model.sample_rate)
            if note:
                progress.done()
                print(note)
        request = {"bandwidth": args.bandwidth, "phase_margin": args.phase_margin, "dt": args.dt,
                   "d_filter_hz": args.d_filter_hz}
        try:
            gains = design_gains(params, **request)
        except ValueError as e:  # an infeasible request: the message says what is achievable
            raise DesignError(str(e)) from e
        analyses = [loop_analysis(params, ax, gains.kp[i], gains.kd[i], args.dt, d_filter_hz=gains.d_filter_hz[i])
                    for i, ax in enumerate(AXES)]
        out = Path(args.out)
        activity = servo = None
        if not args.no_plots:
            progress.stage("flying the design in the model's gusts for its servo activity")
            try:
                activity, servo = _servo_activity(env_model, params, gains, args.dt, out, request)
            except AgentError as e:  # a side figure: the design stands without it, and the report says why
                activity = f"Not flown in the model's gusts: {e}."
                progress.done()
                print(f"note: the servo activity was not flown: {e}")
        pd = PDController.from_model(params, gains, args.dt)
        paths = [pd.save(out / "pd.json", {"model": str(env_model.path), "how": "heli design",
                                           "phase_margin_deg": args.phase_margin, "bandwidth_rad_s": args.bandwidth,
                                           "d_filter_request": args.d_filter_hz,
                                           "dt": args.dt, "analysis": [an.summary() for an in analyses]}),
                 write_text(out / "design.md", design_markdown(env_model.path, analyses, args.phase_margin,
                                                               args.bandwidth, plots=not args.no_plots,
                                                               activity=activity))]
        progress.done()
        for an in analyses:
            s = an.summary()
            cut = "no D filter" if an.d_filter_hz is None else f"D filter {an.d_filter_hz:.3g} Hz"
            print(f"  {an.axis:5s}: kp {an.kp:.4g} stick/rad, kd {an.kd:.4g} stick/(rad/s), {cut}; phase margin "
                  f"{an.phase_margin:.1f} deg, gain margin {an.gain_margin_db:.1f} dB, crossover "
                  f"{an.gain_crossover:.3g} rad/s, bandwidth {an.bandwidth:.3g} rad/s, "
                  f"{'stable' if s['stable'] else 'UNSTABLE'}")
        for line in _filter_notes(analyses, args.dt):
            print(line)
        for path in paths:
            print(f"wrote {path}")
        if not args.no_plots:
            progress.stage("drawing the step responses and Bode figures")
            figures = [plot_step_responses(params, gains, out / "step.png", dt=args.dt)]
            figures += [plot_bode(params, an.axis, an.kp, an.kd, out / f"bode_{an.axis}.png", dt=args.dt,
                                  d_filter_hz=an.d_filter_hz) for an in analyses]
            progress.done()
            for path in [*figures, *([servo] if servo else [])]:
                print(f"wrote {path}")
    from .html_report import write_html_report  # after the figures: it embeds them

    print(f"wrote {write_html_report(out / 'design.md')}")
    return 0
