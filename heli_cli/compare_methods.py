"""``heli compare-methods``: the paper's Tables 3-5 (integral method, NLR, EKF) on one flight.

``--validate OTHER.csv`` also scores every identified model on a second flight
the methods did not see (held-out errors). Without it only in-sample errors are
reported: no validation flight is made up, not even for a synthetic flight.
"""

from __future__ import annotations

import sys

from .argtypes import output_path
from .identify import print_read_warnings

DEFAULT_OUT = "method-comparison"


def register(sub):
    p = sub.add_parser(
        "compare-methods",
        help="time the integral method against NLR and the EKF",
        description="Identify the decoupled single-axis model (roll: eq. 18 with k1 = k4 = 0) on one flight with "
        "the integral method, nonlinear regression from each of Table 3's start points and the EKF in each of "
        "Table 4's cases and Table 5's sample lengths, all on the same prefiltered data. Prints the tables with "
        "CPU times, forward-simulation errors and the speed ratios of this run, and writes DIR/comparison.json "
        "and DIR/comparison.md. A synthetic flight's truth (<stem>.truth.json beside it) adds parameter errors. "
        "With --validate OTHER.csv every identified model is also scored on that second flight, which no method "
        "sees (held-out errors); the target is then judged both in-sample and held-out.",
    )
    p.add_argument("flight", metavar="FLIGHT.csv", help="canonical CSV flight log")
    p.add_argument("--out", default=DEFAULT_OUT, type=output_path, metavar="DIR",
                   help=f"output directory (default ./{DEFAULT_OUT})")
    p.add_argument("--axis", default="roll", choices=("roll", "pitch", "yaw"),
                   help="axis to compare (default roll, as the paper)")
    p.add_argument("--validate", metavar="OTHER.csv",
                   help="a second flight of the same aircraft at the same sample rate: adds held-out errors of "
                   "each identified model on it (its truth, if synthetic, adds a held-out reference)")
    p.add_argument("--quick", action="store_true",
                   help="cap each NLR run at a few objective evaluations and time fewer repeats (for a fast "
                   "look; the NLR figures are then indicative only)")
    p.set_defaults(func=run, out_kind="dir")


def run(args) -> int:
    from identification.io import read_flight
    from identification.bench.comparison_config import QUICK_NLR_MAX_NFEV
    from identification.bench.method_comparison import compare_methods
    from identification.reports.method_comparison import comparison_markdown
    from identification.workflows.method_comparison import write_comparison

    from .progress import progress_of

    flight = read_flight(args.flight)
    print_read_warnings(args.flight, flight)
    truth = load_truth_if_any(args.flight)
    validation = validation_truth = None
    if args.validate:
        validation = read_flight(args.validate)
        print_read_warnings(args.validate, validation)
        validation_truth = load_truth_if_any(args.validate)
    else:
        print("No --validate flight: in-sample errors only, where NLR, which minimises that very error, is "
              "favoured; pass --validate OTHER.csv for held-out errors.")
    kwargs = {}
    if args.quick:
        kwargs = {"nlr_max_nfev": QUICK_NLR_MAX_NFEV, "repeats": {"integral": 5, "ekf": 1, "nlr": 1}, "quick": True}
        print(f"--quick: NLR limited to {QUICK_NLR_MAX_NFEV} objective evaluations per start, integral timed "
              "5 times, EKF once; run without --quick for the real figures.")
    with progress_of(args) as progress:
        result = compare_methods(flight, axis=args.axis, truth=truth, progress=progress.bars,
                                 validation=validation, validation_truth=validation_truth, stage=progress.items,
                                 **kwargs)
    print(comparison_markdown(result))
    paths = write_comparison(result, args.out)
    for path in paths.values():
        print(f"wrote {path}")
    return 0


def load_truth_if_any(flight_path):
    """The truth parameters saved beside a synthetic flight, or None (with a warning if unreadable)."""
    from identification.bench.synthetic import load_truth, truth_paths

    if not truth_paths(flight_path)["truth"].exists():
        return None
    try:
        return load_truth(flight_path)[0]
    except (OSError, ValueError, KeyError, TypeError) as e:
        print(f"heli compare-methods: warning: ignoring the truth beside {flight_path}: {e}", file=sys.stderr)
        return None
