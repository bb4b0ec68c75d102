"""``heli sweep``: PD gain sweep → predicted error distributions (paper Section 4), optionally checked by flights."""

from __future__ import annotations

from pathlib import Path

from heli_core.control_period import DEFAULT_DT

from .argtypes import number, output_path, per_axis, seed, whole
from .model_gate import add_accept_option, check_model

DEFAULT_OUT = "sweep"
MAX_EXTENSIONS = 4
"""Default of --max-extensions (controllers.sweep_extend.MAX_EXTENSIONS, not imported here: the parser stays light)."""


def backend_from_args(args):
    """The backend of ``--backend``/``--workers`` (a Ray instance is started or joined on first use)."""
    from heli_core.backends import make_backend

    return make_backend(args.backend, workers=args.workers)


_cutoffs = per_axis("one positive cutoff in Hz or three (roll,pitch,yaw)")
"""``--d-filter-hz``: one cutoff for every axis or three."""


def register(sub):
    p = sub.add_parser(
        "sweep",
        help="sweep PD gains in the model's gusts; predict the errors",
        description="Fly every PD gain pair of a Kp x Kd grid on one axis (attitude hold; the other axes held by "
        "nominal PD gains) against windows of the model's disturbance library, replayed through the physics "
        "core (time domain), and predict the same error distribution from the library's Welch spectrum through "
        "the linearised closed loop (frequency domain). Unstable pairs (closed-loop poles) are reported, not "
        "simulated; every pair's gain and phase margins stand beside its errors, and the report names the best "
        "pair and the best one keeping 6 dB and 45 deg. When the best pair lies on an edge of the grid, the grid "
        "grows past that edge (3 gains at a time, its last ratio continued) until the best pair is interior, the "
        "pair beyond is unstable, or --max-extensions rounds ran (--no-extend: the grid as given). By default the "
        "windows tile every library trace, and each time-domain p90 comes with its 90 % interval (its sampling "
        "error over blocks of the library's time). "
        "Writes DIR/sweep.csv, sweep.json, heatmap.png, histograms.png and sweep.md. With --flights N "
        "the prediction is checked against N fresh-wind flights of the truth model per chosen pair "
        "(KS statistics; DIR/flight_tests.json).",
    )
    p.add_argument("--model", metavar="DIR", default=None,
                   help="model directory written by 'heli identify' (default: the model shipped with heli-env)")
    add_accept_option(p, "Sweep gains on it")
    p.add_argument("--kp", required=True, metavar="A:B:N",
                   help="N proportional gains from A to B [stick/rad], e.g. 0.5:8:20 (or a single value)")
    p.add_argument("--kd", required=True, metavar="C:D:M",
                   help="M derivative gains from C to D [stick/(rad/s)], e.g. 0:3:20 (or a single value)")
    p.add_argument("--axis", default="roll", choices=("roll", "pitch", "yaw"), help="axis to sweep (default roll)")
    p.add_argument("--duration", type=number("a finite number > 0", 0.0),
                   default=60.0, help="seconds per gust window (default 60)")
    p.add_argument("--dt", type=number("a finite number > 0", 0.0), default=None,
                   help=f"control period in seconds (default {DEFAULT_DT:g}, the env's, or the shortest whole number "
                   "of the model's gust-trace sample periods above it: 0.02 for a 50 Hz log's model)")
    p.add_argument("--windows", type=whole(1), default=None,
                   help="number of (trace, offset) gust windows drawn at random (default: windows that tile every "
                   "library trace end to end, the whole library flown once; each p90 comes with its 90 %% interval)")
    p.add_argument("--no-sensors", action="store_true",
                   help="the autopilot reads the true state (default: through the model's identified sensors, "
                   "model.json['sensors']: gyro and attitude noise, vibration lines)")
    p.add_argument("--d-filter-hz", type=_cutoffs, default=None, metavar="F[,F,F]",
                   help="fly every pair with the D term low-passed at this cutoff in Hz (one for every axis or "
                   "roll,pitch,yaw), as a 'heli design' controller does; the predictions and margins include it "
                   "(default: no filter)")
    p.add_argument("--no-extend", action="store_true",
                   help="sweep the grid as given, even when its best pair lies on an edge")
    p.add_argument("--max-extensions", type=whole(0), default=MAX_EXTENSIONS, metavar="N",
                   help=f"rounds of growth past an edge at most (default {MAX_EXTENSIONS})")
    p.add_argument("--seed", type=seed(), default=0, help="seed of the window offsets and flights (default 0)")
    p.add_argument("--out", default=DEFAULT_OUT, type=output_path, metavar="DIR", help=f"output directory (default ./{DEFAULT_OUT})")
    p.add_argument("--no-plots", action="store_true", help="do not draw heatmap.png and histograms.png")
    p.add_argument("--flights", type=whole(0), default=0, metavar="N",
                   help="check the prediction with N fresh-wind flights per pair of the truth model (default 0: no)")
    p.add_argument("--flight-pairs", type=whole(0), default=4, metavar="K",
                   help="pairs flown with --flights: the best and K-1 others spread over the stable pairs' p90 "
                   "ranking (0: every stable pair; default 4)")
    p.add_argument("--truth", default="model", choices=("model", "paper"),
                   help="aircraft flown by --flights: the model's own parameters (default) or the paper's values")
    p.add_argument("--flight-gusts", default="spectrum", choices=("spectrum", "corner"),
                   help="fresh gusts of --flights: surrogates with the library's whole spectrum (default) or coloured "
                   "noise at its level and one fitted corner")
    p.add_argument("--backend", default="local", choices=("local", "ray"),
                   help="where the replay runs: 'local' (default) this machine's cores, 'ray' the Ray cluster at "
                   "RAY_ADDRESS or a Ray instance started here (needs the 'cluster' extra); same result either way")
    p.add_argument("--workers", type=whole(1), default=None, metavar="N",
                   help="local worker processes, or CPUs of a Ray instance started here (default: all cores)")
    p.set_defaults(func=run, out_kind="dir")


def run(args) -> int:
    from controllers.errors import SweepError
    from controllers.sweep import sweep_gains
    from controllers.sweep_inputs import parse_range
    from controllers.sweep_report import default_pairs, flight_test_markdown, markdown, pair_summary, plot_heatmap, \
        plot_histograms

    check_model(args, "sweep gains on it")  # an unusable model is refused before any work
    kp = parse_range(args.kp, "--kp")
    kd = parse_range(args.kd, "--kd")
    if args.model is not None and not Path(args.model).is_dir():
        raise SweepError(f"model directory {args.model!r} does not exist (write one with 'heli identify')")
    from .progress import progress_of

    from controllers.sweep_inputs import load_model

    from .control_period import control_period

    progress = progress_of(args)
    model = load_model(args.model)
    if args.dt is None:
        args.dt, note = control_period(model.sample_rate)
        if note:
            print(note)
    backend = backend_from_args(args)
    progress.stage(f"sweeping {len(kp)} x {len(kd)} gain pairs on {args.axis} in the model's gusts")
    try:
        result = sweep_gains(model, kp, kd, axis=args.axis, duration=args.duration, dt=args.dt,
                             seed=args.seed, windows=args.windows, progress=not args.quiet, backend=backend,
                             extend=not args.no_extend, max_extensions=args.max_extensions,
                             sensors=not args.no_sensors, d_filter_hz=args.d_filter_hz)
    finally:
        backend.close()
    out = Path(args.out)
    paths = {"csv": result.to_csv(out / "sweep.csv"), "json": result.to_json(out / "sweep.json")}
    if not args.no_plots:
        progress.stage("drawing the heatmap and the histograms")
        paths["heatmap"] = plot_heatmap(result, out / "heatmap.png")
        paths["histograms"] = plot_histograms(result, out / "histograms.png")
    report = markdown(result)
    flights = None
    if args.flights:
        from controllers.flight_test import validate_against_flights

        if args.flight_pairs == 0:
            idx = [i for i in range(result.n_pairs) if result.table["status"][i] == "stable"]
            pairs = [(float(result.table["kp"][i]), float(result.table["kd"][i])) for i in idx]
        else:
            pairs = default_pairs(result, args.flight_pairs)
        if pairs:
            progress.stage(f"flying {args.flights} flight test(s) per pair at {len(pairs)} gain pair(s)")
            flights = validate_against_flights(model, pairs, axis=args.axis, n_flights=args.flights,
                                               duration=args.duration, seed=args.seed, truth=args.truth, dt=args.dt,
                                               gusts=args.flight_gusts, progress=not args.quiet,
                                               d_filter_hz=args.d_filter_hz)
            paths["flights"] = flights.to_json(out / "flight_tests.json")
            report += "\n" + flight_test_markdown(flights)
    from heli_core.files import write_text

    paths["report"] = write_text(out / "sweep.md", report)
    progress.done()

    st = result.table["status"]
    n_unstable = int((st == "unstable").sum())
    best = result.best()
    print(f"heli sweep: {result.n_pairs} gain pairs on {result.axis} x {result.settings['n_windows']} gust windows "
          f"of {result.settings['duration']:g} s in {result.settings['seconds']['total']:.1f} s on "
          f"{result.settings['backend']} ({result.settings['tasks']} task{'s' if result.settings['tasks'] != 1 else ''})")
    print(f"unstable (closed-loop poles, not simulated): {n_unstable}; diverged: {int((st == 'diverged').sum())}; "
          f"time/frequency domain disagree: {int(result.table['disagree'].sum())}")
    _print_extension(result)
    from controllers.sweep_report import interval_sentence

    sentence = interval_sentence(result.settings)
    if sentence:
        print(sentence[0].upper() + sentence[1:])
    if best:
        print(f"best by p90 |attitude error|: {pair_summary(best, ' deg')}")
        robust = result.best_robust()
        print("best with gain margin >= 6 dB and phase margin >= 45 deg: "
              + ("none" if robust is None else pair_summary(robust, ' deg')))
    else:
        print("no stable gain pair in the grid")
    if flights is not None:
        _print_flights(flights, args, len(pairs))
    for path in paths.values():
        print(f"wrote {path}")
    from .html_report import write_html_report  # sweep.md links no figure: the two are appended

    figures = [paths[k] for k in ("heatmap", "histograms") if k in paths]
    print(f"wrote {write_html_report(paths['report'], figures=figures)}")
    return 0


def _print_flights(flights, args, n_pairs: int) -> None:
    """The flight tests' verdict, and each pair that misses the KS target with its likely reason."""
    from controllers.flight_test_result import KS_TARGET
    from controllers.sweep_report import miss_reason

    print(f"flight tests ({args.flights} x {args.duration:g} s per pair, {n_pairs} pairs, truth "
          f"{args.truth}): largest KS {flights.max_ks:.3f} (target <= {KS_TARGET:g}: "
          f"{'met' if flights.target_met else 'NOT met'})")
    for r in flights.rows():
        if r["status"] == "flown" and r["ks_att"] > KS_TARGET:
            print(f"  Kp {r['kp']:.4g}, Kd {r['kd']:.4g} misses it (KS {r['ks_att']:.3f}): "
                  f"{miss_reason(r, flights.settings)}")


def _print_extension(result) -> None:
    """How the grid grew and why it stopped, in one or two lines."""
    ext = result.extension
    rounds = ext["rounds"]
    if rounds:
        b = rounds[0]["best_before"]
        print(f"grid grown {len(rounds)} time{'s' * (len(rounds) != 1)} from {len(ext['kp_asked'])} x "
              f"{len(ext['kd_asked'])} to {result.kp_values.size} x {result.kd_values.size} "
              f"({sum(r['pairs_added'] for r in rounds)} pairs added; the grid asked for had its best at "
              f"Kp = {b['kp']:.4g}, Kd = {b['kd']:.4g}, p90 {b['att_p90_deg']:.3g} deg)")
    print(f"extension stopped: {ext['stop']}: {ext['stop_detail']}")
