"""``heli diagnose``: where a model and a flight disagree, which effect is missing, and the model with it added."""

from __future__ import annotations

import sys
from pathlib import Path

from .argtypes import INPUT_HOLD_HELP, input_hold, number, output_path, whole
from .identify import (CLOSED_LOOP_CHOICES, add_controller_loop, add_fit_rate, closed_loop_mode, fit_rate_flights,
                       print_check, print_read_warnings)


def register(sub):
    p = sub.add_parser(
        "diagnose",
        help="find the physical effect a model misses and add it",
        description="Fit the model structure (default: the paper's decoupled model, eqs. 18, 21) by maximum "
        "likelihood with a stochastic wind state, try every effect of the catalogue (servo_delay, cross_coupling, "
        "gyroscopic, collective_torque, nonlinear_damping, gain_scheduling) on every axis, accept those whose "
        "likelihood-ratio statistic clears the threshold, add them and iterate (--method integral: the integral "
        "method with held-out forward simulation instead). Writes DIR/diagnosis.json, DIR/diagnosis.md with "
        "figures and, when an effect is found, a new DIR/model.json version (checked in the flight's closed loop "
        "as heli identify checks its own: --closed-loop) and the flight's wind in DIR/disturbances.",
    )
    p.add_argument("flight", metavar="FLIGHT.csv", help="canonical CSV flight log")
    p.add_argument("--model", metavar="DIR/model.json", default=None,
                   help="model whose structure is diagnosed (default: the paper's decoupled model)")
    p.add_argument("--out", required=True, type=output_path, metavar="DIR", help="output directory")
    p.add_argument("--method", choices=("ml", "integral"), default="ml",
                   help="'ml' likelihood-ratio tests of the wind-state model (default); 'integral' held-out "
                   "forward simulation of integral-method fits")
    p.add_argument("--min-lr", type=number("a number >= 0", 0.0, low_open=False), default=None,
                   help="ml: smallest likelihood-ratio statistic per added term accepted (default 10)")
    p.add_argument("--min-lr-alignment", type=number("a number >= 0", 0.0, low_open=False), default=None,
                   help="ml: smallest likelihood-ratio statistic of a servo delay / input shift (default 20)")
    p.add_argument("--input-hold", type=input_hold, default="auto", help=INPUT_HOLD_HELP)
    p.add_argument("--closed-loop", choices=CLOSED_LOOP_CHOICES, default=None,
                   help="ml: when an effect is found, check the model written in the flight's closed loop as heli "
                   "identify checks its own ('auto', the default, or $HELI_CLOSED_LOOP when set: a bias a pilot "
                   "who sees the aircraft gives the damping is removed; 'report': measured only; 'off': skipped); "
                   "it costs 8-24 fits of the flight, more where a servo delay was found")
    add_controller_loop(p)
    add_fit_rate(p)
    p.add_argument("--folds", type=whole(2, 12), default=5,  # at most Diagnoser.min_windows (12)
                   help="integral: cross-validation blocks, 2 to 12 (default 5)")
    p.add_argument("--window", type=number("a positive number of seconds", 0.0),
                   default=4.0, help="integral: held-out simulation window in s (default 4)")
    p.add_argument("--alpha", type=number("a number in (0, 1)", 0.0, 1.0), default=None,
                   help="family-wise significance per axis (default 0.01 for ml, 0.05 for integral)")
    p.add_argument("--min-gain", type=number("a number in (0, 1)", 0.0, 1.0), default=None,
                   help="integral: smallest held-out improvement accepted, as a fraction (default 0.05)")
    p.add_argument("--no-plots", action="store_true", help="do not draw PNG figures")
    p.add_argument("--no-wait", action="store_true",
                   help="refuse at once when another command is writing the model folder (default: wait for it)")
    p.set_defaults(func=run, out_kind="dir")


def run(args) -> int:
    from identification.io import read_flight
    from identification.workflows.identify import source_entry
    from model_store.model_dir import ModelDir

    from .progress import progress_of

    try:
        closed_loop = closed_loop_mode(args)
    except ValueError as exc:  # $HELI_CLOSED_LOOP misspelt: refused before any work, as heli identify does
        print(f"heli diagnose: error: {exc}", file=sys.stderr)
        return 2
    for option, given in ((f"--closed-loop {args.closed_loop}", args.closed_loop in ("auto", "report")),
                          ("--controller-loop", args.controller_loop is not None),
                          ("--gyro-filter", args.gyro_filter is not None)):
        if args.method != "ml" and given:
            print(f"heli diagnose: error: {option} needs the likelihood diagnosis (--method ml), got --method "
                  "integral", file=sys.stderr)
            return 2
    from identification.validation.fit_warnings import stated_controller

    flight = read_flight(args.flight)
    flight = stated_controller(flight, args.controller_loop, args.gyro_filter)  # stated for a log that cannot
    print_read_warnings(args.flight, flight)
    model = document = None
    if args.model is not None:
        document = ModelDir(_existing_model(args.model)).load(library=False).document
        model = document.params
    with progress_of(args) as progress:
        if (at_rate := fit_rate_flights(args, [flight], "diagnose", progress)) is None:
            return 2
        (flight,), _ = at_rate
        source = source_entry(args.flight, controller_loop_hz=args.controller_loop, gyro_filter_hz=args.gyro_filter)
        if args.method == "ml":
            return _run_ml(args, flight, model, document, source, progress, None if closed_loop == "off" else closed_loop)
        from identification.diagnosis.heldout_diagnoser import ALPHA, MIN_GAIN, Diagnoser
        from identification.workflows.diagnose import DiagnosisConfig, diagnose_and_report

        diagnoser = Diagnoser(folds=args.folds, window=args.window,
                              alpha=ALPHA if args.alpha is None else args.alpha,
                              min_gain=MIN_GAIN if args.min_gain is None else args.min_gain, progress=progress.bars)
        config = DiagnosisConfig(diagnoser=diagnoser, plots=not args.no_plots, draw_figures=False,
                                 wait=not args.no_wait)
        progress.stage(f"diagnosing {args.flight} by held-out forward simulation (every catalogue effect on "
                       "every axis)")
        run_ = diagnose_and_report(flight, args.out, config, model=model, model_document=document,
                                   source=source)
        progress.done()
        _print_run(run_, lambda s: (
            f"held-out MAE {s.gap_before['mae_deg_s']:.3f} -> {s.gap_after['mae_deg_s']:.3f} deg/s, gain "
            f"{100 * s.gain:.1f} %, p {s.p_value:.2g}; "
            + (f"runner-up {s.runner_up} by {100 * s.margin:.1f} %" if s.runner_up else "no runner-up")))
        progress.draw_figures(run_)
    return _write_html(run_)


def _existing_model(path):
    """``--model``'s path, refused when no file is there with the way on: the README's ``heli identify`` before
    ``heli diagnose --model model/model.json`` may have refused the flight, and writing one with ``heli identify``
    would send the user back to that refusal; without ``--model`` the diagnosis fits the paper's model itself."""
    from model_store.errors import ModelFileError

    if not Path(path).exists():
        raise ModelFileError(f"model file {str(path)!r} does not exist: write one with 'heli identify', or leave "
                             "out --model and heli diagnose fits the paper's decoupled model to the flight itself")
    return path


def _write_html(run_) -> int:
    """``diagnosis.html`` beside ``diagnosis.md``, once its figures are drawn (they are embedded)."""
    from .html_report import write_html_report

    print(f"wrote {write_html_report(run_.paths['markdown'])}")
    return 0


def _print_run(run_, evidence) -> int:
    """The verdict, one line per step (its parameters and ``evidence(step)``), and the files written."""
    d = run_.diagnoser
    if run_.document.get("model_verdict"):  # the written model's, as heli identify shows it
        from model_store.verdict import ModelVerdict

        from .identify import print_verdict

        print_verdict(ModelVerdict.from_dict(run_.document["model_verdict"]))
    print(f"verdict: {d.verdict_}")
    if d.verdict_ == "undecided":
        print(f"  {d.evidence_.get('reason', '')}")
    for s in d.steps_:
        params = ", ".join(f"{k}={v:.4g}" for k, v in s.parameters.items())
        print(f"  round {s.round}: {s.axis:5s} {s.effect} ({params}); {evidence(s)}")
    if hasattr(d, "closed_loop_"):
        print("stick share closed by the pilot/controller: "
              + ", ".join(f"{a} {100 * v:.0f} %" for a, v in d.closed_loop_.items()))
        from identification.reports.likelihood_diagnosis import flight_controller_note

        if flight_controller_note(d):
            print(flight_controller_note(d))
    from identification.reports.likelihood_diagnosis import timing_note

    if d.steps_ and (note := timing_note(d)):  # the model written carries it
        print(note)
    from identification.reports.likelihood_diagnosis import written_model_check

    if (check := written_model_check(d)) is not None:
        print_check(check, "closed-loop check of the model written")
    for key, path in run_.paths.items():
        print(f"wrote {path}")
    return 0


def _run_ml(args, flight, model, document, source, progress, closed_loop: str | None) -> int:
    """The likelihood diagnosis, the model it writes checked in mode ``closed_loop`` (None: not checked)."""
    from identification.diagnosis.likelihood_diagnoser import (
        ALPHA,
        MIN_LR_ALIGNMENT,
        MIN_LR_PER_PARAMETER,
        LikelihoodDiagnoser,
    )
    from identification.workflows.diagnose import diagnose_by_likelihood

    progress.stage(f"diagnosing {args.flight} by likelihood (every catalogue effect on every axis"
                   + (", then the figures)" if not args.no_plots else ")"))
    diagnoser = LikelihoodDiagnoser(alpha=ALPHA if args.alpha is None else args.alpha,
                                    min_lr_per_parameter=MIN_LR_PER_PARAMETER if args.min_lr is None else args.min_lr,
                                    input_hold=args.input_hold, min_lr_alignment=MIN_LR_ALIGNMENT
                                    if args.min_lr_alignment is None else args.min_lr_alignment,
                                    progress=lambda step: progress.stage(  # each step's line replaces the last
                                        step + (", then the report and its figures" if step.startswith("fitting the "
                                                "final") and not args.no_plots else "")))
    run_ = diagnose_by_likelihood(flight, args.out, model=model, model_document=document, source=source,
                                  plots=not args.no_plots, diagnoser=diagnoser, wait=not args.no_wait,
                                  closed_loop=closed_loop)
    progress.done()
    from identification.likelihood.ahead_score import format_r2
    from identification.reports.likelihood_diagnosis import heldout_change

    _print_run(run_, lambda s: (
        f"LR {s.lr:.1f} > {s.threshold:.1f}; 0.5 s-ahead R² {format_r2(s.r2_before['ahead_0.5s'])} -> "
        f"{format_r2(s.r2_after['ahead_0.5s'])} (held out {heldout_change(s.r2_before, s.r2_after)}); "
        + (f"runner-up {s.runner_up} (LR {s.runner_up_lr:.1f})" if s.runner_up else "no runner-up")))
    return _write_html(run_)
