"""``heli import``: a flight-controller log in, a canonical CSV flight (and its metadata) out.

Nothing is written for a refused log: the log is read and validated completely before
the CSV and its ``.meta.json`` are written (each atomically). What the import tolerated
(a cut last message, padding, a clock restart, no attitude stream, another log of a
flash dump) is printed as one warning line each and kept in the metadata
(``import_warnings``).
"""

from __future__ import annotations

import sys

from .argtypes import number, output_path, segment_or_each, whole


def register(sub):
    p = sub.add_parser(
        "import",
        help="convert a PX4, ArduPilot or blackbox log to a CSV flight",
        description="Read a flight-controller log (format recognised from its content), map body rates, attitude "
        "and the chosen input source to the canonical flight (rad/s, rad, inputs in [-1, 1]; roll right, nose up, "
        "nose right positive), resample it onto a uniform grid, cut the airborne segment, and write OUT (CSV) "
        "plus OUT's metadata beside it (.meta.json: format, input source and mapping, clipped inputs, "
        "resampling, segment detection). Logs import as real loggers write them: a cut last message is dropped, "
        "0xFF/0x00 padding skipped, a restarted clock continued, a missing attitude reconstructed from the rates, "
        "each printed as a one-line warning and kept in the metadata; damage in the middle of a log needs "
        "--allow-damaged. An old ArduPilot text DataFlash log (.log, ArduCopter <= 3.0) is recognised and refused "
        "in one line saying what it holds and what identification would need. A CSV whose clock is not uniform "
        "(rounded stamps, jitter, missing samples) is written on a uniform clock, saying what was done; one where the "
        "logging stopped needs --segment. Nothing is written for a refused log.",
    )
    p.add_argument("log", metavar="LOG", help="PX4 .ulg, ArduPilot .bin, Betaflight/Rotorflight blackbox, or CSV "
                   "(an ArduPilot text .log is described and refused)")
    p.add_argument("--out", metavar="FLIGHT.csv", type=output_path, help="canonical CSV to write (required unless --list)")
    p.add_argument("--list", action="store_true",
                   help="list the logs in the file (a blackbox flash dump holds several) with their length and "
                   "airborne time, and write nothing")
    p.add_argument("--log", dest="log_n", type=whole(1), default=None, metavar="N",
                   help="which log of a file holding several (from 1, as --list numbers them; default: the one "
                   "with the longest airborne segment)")
    p.add_argument("--segment", type=segment_or_each, default=None, metavar="auto|each|all|T0:T1",
                   help="airborne segment found automatically (default for flight-controller logs: the longest "
                   "airborne run), every airborne run as a CSV of its own ('each': OUT's name numbered, "
                   "flight-1.csv, flight-2.csv, ... in time order), the whole log ('all', the longest stretch "
                   "without a logging gap), or T0:T1 on the log's own clock [s]")
    p.add_argument("--inputs", choices=("sticks", "controller", "servos"), default=None,
                   help="input source: pilot sticks, rate-controller outputs, or swash servos through eq. 67 "
                   "(default: the one closest to the bare airframe: controller for multirotors; servos, else "
                   "the stabilised mixer input, for helicopters)")
    p.add_argument("--rate", type=number("a positive rate in Hz", 0.0), default=None, metavar="HZ",
                   help="grid rate (default: the gyro stream's rate, at most 200 Hz)")
    p.add_argument("--calibration", metavar="JSON", default=None,
                   help="servo mixing {\"G\": 4x4, \"U_trim\": 4} of eq. 66 for --inputs servos "
                   "(default: the documented H3-120 mixing)")
    p.add_argument("--allow-damaged", action="store_true",
                   help="import what decodes from a log damaged in the middle (corrupt frames or messages) instead "
                   "of failing; a log whose last message is cut needs no flag")
    p.set_defaults(func=run, out_kind="file")


def meta_path(out):
    """Where ``heli import`` writes the metadata of ``out``: ``flight.csv`` -> ``flight.meta.json``
    (:func:`identification.io.meta_path`, which the readers use to know an imported CSV's log)."""
    from identification.io import meta_path as _meta_path

    return _meta_path(out)


def _print_list(path, allow_damaged, progress, options=()) -> int:
    """The table of the logs in ``path``: one row per log with data, then each reason an empty log was refused
    once, with the logs it applies to (a flash dump can hold dozens of empty logs)."""
    from identification.io import list_logs

    from .option_wording import as_cli_options

    rows = list_logs(path, allow_damaged=allow_damaged, progress=_LogBar(progress, path))
    print(f"{path}: {len(rows)} log{'s' if len(rows) != 1 else ''}")
    shown = [r for r in rows if r["status"] == "ok" or r.get("start_s") is not None or r.get("duration_s")]
    refused = {}
    for r in rows:
        if r not in shown:
            refused.setdefault(as_cli_options(r["status"], "import", options), []).append(r["log"])
    if shown:
        print(f"{'log':>4}  {'start s':>9}  {'length s':>9}  {'airborne s':>10}  attitude  status")
    for r in shown:
        def num(v):
            return "-" if v is None else f"{float(v):.1f}"

        att = "-" if r.get("attitude") is None else ("yes" if r["attitude"] else "no")
        print(f"{r['log']:>4}  {num(r.get('start_s')):>9}  {num(r.get('duration_s')):>9}  "
              f"{num(r.get('airborne_s')):>10}  {att:>8}  {r['status']}")
    for status, logs in refused.items():
        which = f"log {logs[0]}" if len(logs) == 1 else f"{len(logs)} logs ({_ranges(logs)})"
        print(f"{which}: {status}")
    return 0


def _ranges(numbers) -> str:
    """``[2, 3, 5, 6, 7, 9]`` -> ``"2-3, 5-7, 9"``."""
    out, start = [], None
    for i, n in enumerate(numbers):
        if start is None:
            start = n
        if i + 1 == len(numbers) or numbers[i + 1] != n + 1:
            out.append(str(start) if start == n else f"{start}-{n}")
            start = None
    return ", ".join(out)


class _LogBar:
    """``list_logs``' progress: a tqdm bar over the logs on a terminal, a line when decoding starts off one."""

    def __init__(self, progress, path):
        self.progress, self.path, self.bar = progress, path, None

    def __call__(self, done, total):
        if self.progress.quiet:
            return
        if self.bar is None:
            if not self.progress.terminal:
                self.progress.stage(f"decoding {total} log{'s' if total != 1 else ''} of {self.path}")
                self.bar = False
                return
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=f"import: decoding {self.path}", unit="log", leave=False,
                            file=self.progress.stream)
        if self.bar:
            self.bar.update(done - self.bar.n)
            if done >= total:
                self.bar.close()


def run(args) -> int:
    from identification.io import read_log, read_log_runs

    from .progress import progress_of

    if args.list:
        with progress_of(args) as progress:
            return _print_list(args.log, args.allow_damaged, progress, getattr(args, "cli_options", ()))
    if not args.out:
        print("heli import: error: --out FLIGHT.csv is required (or --list to see the logs in the file)",
              file=sys.stderr)
        return 2
    options = {"inputs": args.inputs, "rate": args.rate, "calibration": args.calibration,
               "allow_damaged": args.allow_damaged, "log": args.log_n}
    with progress_of(args) as progress:
        progress.stage(f"reading {args.log}")
        if args.segment == "each":
            flights = read_log_runs(args.log, **options)
        else:
            flights = [read_log(args.log, segment=args.segment, **options)]
    outs = [args.out] if args.segment != "each" else [run_path(args.out, k + 1) for k in range(len(flights))]
    agreements = [_write(flight, out) for flight, out in zip(flights, outs)]  # all read before any is written
    m = flights[0].metadata
    for line in m.get("import_warnings") or ():
        print(f"heli import: warning: {line}", file=sys.stderr)
    log_note = f", log {m['log_index']} of {m['logs_in_file']}" if m.get("logs_in_file", 1) > 1 else ""
    print(f"{m.get('format', 'csv')} log ({m.get('vehicle', 'flight')}{log_note}), inputs: {m.get('input_source')}")
    for flight, out, agreement in zip(flights, outs, agreements):
        _print_flight(flight, out, agreement, args.segment == "each")
    if len(flights) > 1:
        print(f"identify from every run: heli identify {' '.join(str(o) for o in outs)} --out model/")
    return 0


def run_path(out, k: int):
    """The CSV of airborne run ``k`` (from 1) of ``--segment each``: ``flight.csv`` -> ``flight-2.csv``."""
    from pathlib import Path

    out = Path(out)
    return out.with_name(f"{out.stem}-{k}{out.suffix}")


def _write(flight, out) -> dict | None:
    """``flight`` as the CSV ``out`` and its metadata beside it (each written atomically); returns the
    attitude-derivative vs rate correlation per axis (None without a logged attitude)."""
    import json

    from heli_core.files import jsonable, write_text
    from identification.io import write_csv_flight
    from identification.io.raw_log import rate_attitude_agreement

    measured = flight.metadata.get("attitude_source") == "measured"
    agreement = rate_attitude_agreement(flight) if measured else None
    write_csv_flight(flight, out)
    write_text(meta_path(out), json.dumps(jsonable({**dict(flight.metadata), "rate_attitude_correlation": agreement}),
                                          indent=2, sort_keys=True) + "\n")
    return agreement


def _print_flight(flight, out, agreement, numbered: bool) -> None:
    """What was written of ``flight``: its segment, its attitude's check, clipped inputs, damage, its files."""
    m = flight.metadata
    run = f"airborne run {m['airborne_run']['index']} of {m['airborne_run']['of']}: " if numbered else ""
    print(f"{run}segment {flight.time[0]:.3f}..{flight.time[-1]:.3f} s ({flight.duration:.1f} s, "
          f"{m.get('segment_mode', 'given')}), {flight.n} samples at {flight.sample_rate:.1f} Hz")
    if agreement is None:
        print("attitude: reconstructed from the rates (eqs. 25-29); the log has no attitude stream")
    else:
        print("attitude-derivative vs rate correlation: "
              + ", ".join(f"{a} {'n/a' if c is None else f'{c:.3f}'}" for a, c in agreement.items()))
    clipped = {k: v for k, v in (m.get("inputs_clipped") or {}).items() if v}
    if clipped:
        print("inputs clipped to [-1, 1] (samples): " + ", ".join(f"{k} {v}" for k, v in clipped.items()))
    if m.get("damage"):
        print("damaged log, imported what decodes: " + "; ".join(m["damage"]))
    print(f"wrote {out}")
    print(f"wrote {meta_path(out)}")
