"""``heli refresh``: new flights in, parameter drift, a refreshed model and a larger disturbance library out."""

from __future__ import annotations

import math

from .argtypes import number, seed, segment_option, whole
from .identify import add_controller_loop, add_flight_backend_options, flight_backend


def register(sub):
    p = sub.add_parser(
        "refresh",
        help="refit a model with new flights; report parameter drift",
        description="Identify NEW_FLIGHTs with the structure and settings of MODEL_DIR/model.json, compare every "
        "parameter with the current model (interval bootstrap; a change is flagged when |new - old| > "
        "z*sqrt(se_old^2 + se_new^2), Bonferroni z at family-wise ALPHA), write the refreshed model (previous and "
        "new flights pooled when the previous flights are at hand and nothing changed, else the new flights "
        "alone; the replaced model.json is kept under history/), append the new flights' wind to the "
        "disturbance library as a new version, and write MODEL_DIR/refresh.md and refresh.json.",
    )
    p.add_argument("model_dir", metavar="MODEL_DIR", help="directory written by 'heli identify'")
    p.add_argument("flights", nargs="+", metavar="NEW_FLIGHT.csv", help="canonical CSV flight log(s) new to the model")
    p.add_argument("--previous-flights", nargs="+", default=[], metavar="FLIGHT.csv",
                   help="the current model's source flights, when not in MODEL_DIR or beside the new flights "
                   "(matched by SHA-256)")
    p.add_argument("--segment", type=segment_option, default=None, metavar="auto|all|T0:T1",
                   help="the stretch of each NEW_FLIGHT read, as heli identify's: a flight-controller log's airborne "
                   "segment found automatically (its default), the whole log ('all') or T0:T1 on its own clock [s]; "
                   "recorded in the model's sources (the previous flights are read as their sources record)")
    p.add_argument("--fit", choices=("auto", "pooled", "new"), default="auto",
                   help="flights of the refreshed model: auto (pooled unless a parameter changed or the previous "
                   "flights are missing), pooled, or new (default auto)")
    p.add_argument("--bootstrap", type=whole(2), default=200, metavar="N",
                   help="bootstrap replicates per data set (default 200)")
    p.add_argument("--block", type=whole(1), default=1, metavar="K",
                   help="consecutive intervals per bootstrap block (default 1)")
    p.add_argument("--seed", type=seed(), default=0, help="bootstrap seed (default 0; same seed, same table)")
    p.add_argument("--alpha", type=number("a probability in (0, 1)", 0.0, 1.0), default=0.05,
                   help="family-wise probability of a false flag over the parameters (default 0.05)")
    p.add_argument("--min-change", type=number("a non-negative fraction (0.05 = 5 %)", 0.0, low_open=False),
                   default=0.0, metavar="FRACTION",
                   help="smallest relative change that may be flagged, e.g. 0.05 (default 0: any significant change)")
    p.add_argument("--no-plots", action="store_true", help="do not draw PNG figures")
    add_controller_loop(p, "the NEW_FLIGHTs' inputs (recorded in their sources; the previous flights are read as "
                           "theirs record)")
    add_flight_backend_options(p)
    p.add_argument("--no-wait", action="store_true",
                   help="refuse at once when another command is writing the model folder (default: wait for it)")
    p.set_defaults(func=run)


def run(args) -> int:
    from identification.workflows.refresh import refresh_model

    from .progress import progress_of

    progress = progress_of(args)
    backend = flight_backend(args)
    progress.stage(f"reading {args.model_dir} and checking the new flights")
    try:  # each step that can take seconds says so as it starts (issue 31: 17 s with nothing moving)
        result = refresh_model(
            args.model_dir, args.flights, previous_flights=args.previous_flights, fit=args.fit,
            n_replicates=args.bootstrap, block=args.block, seed=args.seed, alpha=args.alpha,
            min_relative=args.min_change, plots=not args.no_plots, progress=progress.bars, backend=backend,
            wait=not args.no_wait, stage=progress.stage, segment=args.segment, controller_loop=args.controller_loop,
            gyro_filter=args.gyro_filter,
        )
    finally:
        progress.done()
        if backend is not None:
            backend.close()
    crit = result.criterion
    print(f"parameter drift (new flights vs current model; flag |Δ| > {crit['z']:.2f}·se of the difference):")
    for r in result.drift:
        rel = f"{100 * r.relative:+6.1f} %" if math.isfinite(r.relative) else "     — "
        print(f"  {r.name:5s} {r.old:10.4f} -> {r.new:10.4f}  Δ {r.delta:+.4f} ({rel})  z {r.z:5.2f}"
              + ("  CHANGED" if r.flagged else ""))
    print("changed: " + (", ".join(result.flagged) if result.flagged else "nothing beyond the uncertainty"))
    print(f"refreshed model: {result.reason}")
    for note in result.notes:
        print(f"note: {note}")
    print(f"disturbance library: {result.paths.get('library')} version {result.library_version}")
    for key in ("model", "report", "refresh_md", "refresh_json"):
        if key in result.paths:
            print(f"wrote {result.paths[key]}")
    from .html_report import write_html_report  # as identify: after the figures, it embeds them

    print(f"wrote {write_html_report(result.paths['report'])}")
    return 0
