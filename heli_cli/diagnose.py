"""``heli diagnose``: where a model and a flight disagree, which effect is missing, and the model with it added."""

from __future__ import annotations

from .argtypes import number, whole


def register(sub):
    p = sub.add_parser(
        "diagnose",
        help="locate where a model and a flight disagree, name the missing physical effect, add it and "
        "show the held-out gap shrink",
        description="Fit the model structure (default: the paper's decoupled model, eqs. 18, 21) with the integral "
        "method, locate the disagreement (residual tests, frequency band, time windows), try every effect of the "
        "catalogue (servo_delay, cross_coupling, gyroscopic, collective_torque, nonlinear_damping, "
        "gain_scheduling) on held-out data, add the significant ones and iterate. Writes DIR/diagnosis.json, "
        "DIR/diagnosis.md with figures and, when an effect is found, a new DIR/model.json version and the "
        "flight's wind in DIR/disturbances.",
    )
    p.add_argument("flight", metavar="FLIGHT.csv", help="canonical CSV flight log")
    p.add_argument("--model", metavar="DIR/model.json", default=None,
                   help="model whose structure is diagnosed (default: the paper's decoupled model)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--folds", type=whole(2), default=5, help="cross-validation blocks (default 5)")
    p.add_argument("--window", type=number("a positive number of seconds", 0.0),
                   default=4.0, help="held-out simulation window in s (default 4)")
    p.add_argument("--alpha", type=number("a number in (0, 1)", 0.0, 1.0), default=None,
                   help="family-wise significance per axis (default 0.05)")
    p.add_argument("--min-gain", type=number("a number in (0, 1)", 0.0, 1.0), default=None,
                   help="smallest held-out improvement accepted, as a fraction (default 0.05)")
    p.add_argument("--no-plots", action="store_true", help="do not draw PNG figures")
    p.set_defaults(func=run)


def run(args) -> int:
    from identification.diagnose import ALPHA, MIN_GAIN, Diagnoser
    from identification.diagnose_report import diagnose_and_report
    from identification.io import read_flight
    from identification.model_file import load_model
    from identification.report import source_entry

    flight = read_flight(args.flight)
    model = document = None
    if args.model is not None:
        model, document = load_model(args.model)
    diagnoser = Diagnoser(folds=args.folds, window=args.window,
                          alpha=ALPHA if args.alpha is None else args.alpha,
                          min_gain=MIN_GAIN if args.min_gain is None else args.min_gain, progress=True)
    run_ = diagnose_and_report(flight, args.out, model=model, model_document=document,
                               source=source_entry(args.flight), plots=not args.no_plots, diagnoser=diagnoser)
    d = run_.diagnoser
    print(f"verdict: {d.verdict_}")
    if d.verdict_ == "undecided":
        print(f"  {d.evidence_.get('reason', '')}")
    for s in d.steps_:
        params = ", ".join(f"{k}={v:.4g}" for k, v in s.parameters.items())
        runner = f"runner-up {s.runner_up} by {100 * s.margin:.1f} %" if s.runner_up else "no runner-up"
        print(f"  round {s.round}: {s.axis:5s} {s.effect} ({params}); held-out MAE {s.gap_before['mae_deg_s']:.3f} "
              f"-> {s.gap_after['mae_deg_s']:.3f} deg/s, gain {100 * s.gain:.1f} %, p {s.p_value:.2g}; {runner}")
    for key, path in run_.paths.items():
        print(f"wrote {path}")
    return 0
