"""``heli identify``: flight logs in, ``model.json`` and a report out."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

from .argtypes import (INPUT_HOLD_HELP, fit_rate_option, input_hold, number, output_path, seconds_or, segment_option,
                       servo_lag, whole)


_delay = seconds_or(("detect", "auto", "none"), "delay", 2.0)


def add_flight_backend_options(p):
    """``--backend`` and ``--workers`` of the commands that identify each flight's wind as one task
    (``heli identify``, ``heli refresh``); :func:`flight_backend` makes the backend from them."""
    p.add_argument("--backend", default=None, choices=("local", "ray"),
                   help="identify each flight's wind as one task per flight: 'local' this machine's cores, 'ray' "
                   "the Ray cluster at RAY_ADDRESS or a Ray instance started here (needs the 'cluster' extra); "
                   "default: one after the other in this process. Same results either way")
    p.add_argument("--workers", type=whole(1), default=None, metavar="N",
                   help="local worker processes, or CPUs of a Ray instance started here (default: all cores)")


def flight_backend(args):
    """The backend of :func:`add_flight_backend_options`, or None (in this process) without ``--backend``."""
    from heli_core.backends import make_backend

    return None if args.backend is None else make_backend(args.backend, workers=args.workers)


def register(sub):
    p = sub.add_parser(
        "identify",
        help="identify the attitude model and the wind from CSV flights",
        description="Identify the minimal attitude models (paper eqs. 18, 21) from one or more canonical CSV "
        "flights, by default with the maximum-likelihood filter-error method (a slow and a fast Gauss-Markov gust "
        "state, white gyro noise; unbiased when the pilot fights turbulence), or with the integral method (Fig. 5, "
        "--method integral); then each flight's wind: the smoother's estimate (maximum likelihood) or the "
        "piecewise torque profile of eqs. 41-47 (integral). Writes DIR/model.json, DIR/report.md, figures, and "
        "appends the winds to the disturbance library DIR/disturbances (a new version; earlier versions are kept).",
    )
    p.add_argument("flights", nargs="+", metavar="FLIGHT.csv", help="canonical CSV flight log(s)")
    p.add_argument("--out", required=True, type=output_path, metavar="DIR", help="output directory")
    p.add_argument("--coupled", action="store_true", help="write the coupled model (k1..k12) instead of the decoupled one")
    p.add_argument("--method", choices=("ml", "integral"), default="ml",
                   help="estimator: 'ml' maximum likelihood with a stochastic wind state (default), 'integral' the "
                   "integral method of Fig. 5")
    p.add_argument("--delay", type=_delay, default=None,
                   help="servo delay (eq. 31): 'detect' (ml's default: a delay searched from the undelayed fit, "
                   "profiled and kept only on the axes whose likelihood supports one), 'auto' (the likelihood, or "
                   "the integral fit, profiled over -0.6-0.5 s on every axis), 'none', or seconds (the integral "
                   "method's default: none)")
    p.add_argument("--servo-lag", type=servo_lag, default=None,
                   help="ml: the servos' first-order lag (eq. 31's d1): 'detect' (default: profiled like 'auto' on "
                   "the axes where the delay's search found a servo delay), 'auto' (the likelihood profiled over "
                   "10-200 ms on every axis, kept only where the data support it), 'none', or seconds")
    p.add_argument("--input-hold", type=input_hold, default="auto",
                   help=INPUT_HOLD_HELP + "; integral: 'auto' is 'linear'")
    p.add_argument("--closed-loop", choices=CLOSED_LOOP_CHOICES, default=None,
                   help="ml: the closed-loop check: where the sticks follow the aircraft rather than the gyro (a "
                   "pilot who sees it), fly the identified model again under the pilot fitted to them, fit those "
                   "flights, and remove a gain's or damping's bias where it is significant ('auto', the default, "
                   f"or ${CLOSED_LOOP_ENV} when set), only report it ('report'), or skip the check ('off'); it "
                   "costs about 8 fits of the flight")
    add_controller_loop(p)
    add_fit_rate(p)
    p.add_argument("--wind-model", choices=("auto", "gm2", "gm_so"), default="auto",
                   help="ml: gust model per axis, 'gm2' two first-order Gauss-Markov processes, 'gm_so' a slow "
                   "first-order and a fast second-order one, 'auto' the more likely (default)")
    p.add_argument("--interval", type=number("a positive interval in seconds", 0.0),
                   default=1.0, help="integral method: integration interval T_i - T_(i-1) in s (default 1.0)")
    p.add_argument("--no-filter", action="store_true",
                   help="integral method: skip the 4/8 Hz zero-phase FIR prefilter (Section 3.1)")
    p.add_argument("--segment", type=segment_option, default=None, metavar="auto|all|T0:T1",
                   help="the stretch of each FLIGHT identified, as heli import's: a flight-controller log's airborne "
                   "segment found automatically (its default), the whole log ('all') or T0:T1 on its own clock [s] "
                   "(a CSV flight is whole by default; 'all' its longest stretch where the logging stopped during it)")
    p.add_argument("--validate", nargs="+", default=[], metavar="OTHER.csv",
                   help="after identifying, simulate the model on these flights (not used for the fit) and report "
                   "per axis the fit %% and R² of the simulation (as MATLAB's compare) and the R² of the 0.5 s-ahead "
                   "prediction, in the terminal and in report.md with a figure per flight")
    p.add_argument("--no-plots", action="store_true", help="do not draw PNG figures")
    p.add_argument("--no-disturbances", action="store_true",
                   help="do not identify wind profiles nor write the disturbance library")
    add_flight_backend_options(p)
    p.add_argument("--no-wait", action="store_true",
                   help="refuse at once when another command is writing the model folder (default: wait for it)")
    p.set_defaults(func=run, out_kind="dir")


CLOSED_LOOP_CHOICES = ("auto", "report", "off")
CLOSED_LOOP_ENV = "HELI_CLOSED_LOOP"
"""Environment variable giving ``--closed-loop``'s default (one of :data:`CLOSED_LOOP_CHOICES`; unset: auto)."""


def closed_loop_mode(args) -> str:
    """``--closed-loop`` as given, else ``$HELI_CLOSED_LOOP``, else "auto".

    Raises
    ------
    ValueError
        ``HELI_CLOSED_LOOP`` set to something else than the choices.
    """
    if args.closed_loop is not None:
        return args.closed_loop
    text = os.environ.get(CLOSED_LOOP_ENV, "").strip() or "auto"
    if text not in CLOSED_LOOP_CHOICES:
        raise ValueError(f"{CLOSED_LOOP_ENV} must be one of {', '.join(CLOSED_LOOP_CHOICES)}; got {text!r}")
    return text


def ml_settings(args, closed_loop: str) -> dict:
    """The maximum-likelihood identifier's settings of a command line: ``--delay``, ``--servo-lag`` (when not
    given, :data:`~identification.likelihood.estimator.CLI_TIMING`), ``--input-hold``, ``--wind-model`` (when the
    command has none, "auto") and the closed-loop mode (:func:`closed_loop_mode`). ``heli tune`` identifies its
    LOG with these too, so that the same flight gives the same model whichever command identifies it."""
    from identification.likelihood.estimator import CLI_TIMING

    timing = {name: CLI_TIMING[name] if value is None else None if value == "none" else value
              for name, value in (("delay", args.delay), ("servo_lag", args.servo_lag))}
    return {**timing, "input_hold": getattr(args, "input_hold", "auto"),
            "wind_model": getattr(args, "wind_model", "auto"),
            "closed_loop": None if closed_loop == "off" else closed_loop}


def run(args) -> int:
    from identification.io import read_flight, read_log
    from identification.validation.fit_warnings import stated_controller
    from identification.workflows.identify import identify_and_report, segment_read, source_entry

    from .progress import progress_of

    with progress_of(args) as progress:
        if len(args.flights) > 1:  # one flight reads in a fraction of a second
            progress.stage(f"reading {len(args.flights)} flights")
        flights = [read_log(path, segment=args.segment) for path in args.flights]
        # stated by the user for logs that cannot state it
        flights = [stated_controller(f, args.controller_loop, args.gyro_filter) for f in flights]
        others = [read_flight(path) for path in args.validate]  # a bad one refused before any fit
        for path, flight in zip(args.flights + args.validate, flights + others):
            print_read_warnings(path, flight, progress)
        try:
            closed_loop = closed_loop_mode(args)
        except ValueError as exc:
            progress.done()
            print(f"heli identify: error: {exc}", file=sys.stderr)
            return 2
        if (at_rate := fit_rate_flights(args, flights, "identify", progress)) is None:
            return 2
        flights, fit_rate = at_rate
        others = [thinned_alike(o, fit_rate) for o in others]
        delay = None if args.delay == "none" else args.delay
        lag = None if args.servo_lag == "none" else args.servo_lag
        if args.method == "ml":
            kwargs = ml_settings(args, closed_loop)
        else:
            for option, given in (("--servo-lag", lag is not None), ("--delay detect", delay == "detect"),
                                  (f"--closed-loop {closed_loop}", args.closed_loop == "report"),
                                  ("--controller-loop", args.controller_loop is not None),
                                  ("--gyro-filter", args.gyro_filter is not None)):
                if given:
                    progress.done()
                    print(f"heli identify: error: {option} needs the maximum-likelihood estimator (--method ml), "
                          "got --method integral", file=sys.stderr)
                    return 2
            kwargs = {"interval": args.interval, "delay": delay, "prefilter": not args.no_filter, "remove_folded": True,
                      "input_hold": "linear" if args.input_hold == "auto" else args.input_hold}
        backend = flight_backend(args)
        try:
            run = _identify_or_explain(args, flights, kwargs, progress, lambda: identify_and_report(
                flights, args.out, coupled=args.coupled,
                sources=[source_entry(p, segment=segment_read(args.segment, f),
                                     controller_loop_hz=args.controller_loop, gyro_filter_hz=args.gyro_filter)
                        for p, f in zip(args.flights, flights)],
                identifier_kwargs=kwargs, flight_paths=args.flights, plots=not args.no_plots,
                disturbances=not args.no_disturbances, backend=backend, method=args.method,
                progress=progress.bars and len(flights) > 1, draw_figures=False, stage=progress.stage,
                wait=not args.no_wait, validate_flights=others,
                validate_names=[Path(p).name for p in args.validate],
                validate_paths=[str(Path(p).resolve()) for p in args.validate],
            ))
        finally:
            if backend is not None:
                backend.close()
        progress.done()
        _print_run(run, len(flights), args.method)
        _print_flight_checks(run.flight_checks)
        progress.draw_figures(run)
    from .html_report import write_html_report

    print(f"wrote {write_html_report(run.paths['report'])}")  # after the figures: it embeds them
    return 0


def add_fit_rate(p) -> None:
    """``--fit-rate auto|log|HZ`` (heli identify and diagnose): the rate the log is fitted at."""
    p.add_argument("--fit-rate", type=fit_rate_option, default=None, metavar="auto|log|HZ",
                   help="ml: the rate the log is fitted at: 'auto' (the default, or $HELI_FIT_RATE when set) its own "
                   "unless the damping fitted there "
                   "is inflated against the one fitted at half of it, the mark of a gyro low-passed before it was "
                   "logged (a flight controller's gyro filter), whose noise the likelihood takes for motion: then "
                   "every second sample, again while the same holds; 'log' its own; or HZ, the log's rate over a "
                   "whole number")


def fit_rate_flights(args, flights, command: str, progress=None):
    """``(flights, FitRate)``: ``flights`` at the rate ``--fit-rate`` gives ('auto' for the maximum-likelihood
    estimator only: the integral method's prefilter keeps below 8 Hz whatever the gyro's filter did), or None after
    saying why in one line on stderr (a rate the log's is not a whole multiple of)."""
    from identification.fit_rate import at_fit_rate

    try:
        setting = fit_rate_setting(getattr(args, "fit_rate", None))
    except ValueError as exc:
        if progress is not None:
            progress.done()
        print(f"heli {command}: error: {exc}", file=sys.stderr)
        return None
    if getattr(args, "method", "ml") != "ml":
        setting = "log" if setting == "auto" else setting
    if setting == "auto" and progress is not None:
        progress.stage("choosing the fit rate (the log's fitted at its rate and at half of it)")
    try:
        fitted, chosen = at_fit_rate(flights, setting)
    except ValueError as exc:  # a rate the log's is not a whole multiple of, or logs of two rates
        if progress is not None:
            progress.done()
        print(f"heli {command}: error: {'--fit-rate: ' if isinstance(setting, float) else ''}{exc}", file=sys.stderr)
        return None
    return fitted, chosen


FIT_RATE_ENV = "HELI_FIT_RATE"
"""Sets ``--fit-rate``'s default (auto, log or Hz), as ``$HELI_CLOSED_LOOP`` sets ``--closed-loop``'s: the test
suite identifies short flights some fifty times for other reasons and sets it to 'log'."""


def fit_rate_setting(given):
    """``--fit-rate`` as given, else ``$HELI_FIT_RATE``, else "auto".

    Raises
    ------
    ValueError
        ``HELI_FIT_RATE`` set to something else than 'auto', 'log' or a rate in Hz.
    """
    import argparse

    from .argtypes import fit_rate_option

    if given is not None:
        return given
    text = os.environ.get(FIT_RATE_ENV, "").strip() or "auto"
    try:
        return fit_rate_option(text)
    except argparse.ArgumentTypeError as exc:
        raise ValueError(f"{FIT_RATE_ENV}: {exc}") from None


def thinned_alike(flight, fit_rate):
    """``flight`` (a validation flight) thinned as the fitted log was, where it was logged at the log's rate."""
    from identification.fit_rate import thinned

    same = abs(flight.sample_rate - fit_rate.log_hz) <= 1e-6 * fit_rate.log_hz
    return thinned(flight, fit_rate.every) if fit_rate.every > 1 and same else flight


def add_controller_loop(p, which: str = "the inputs") -> None:
    """``--controller-loop HZ`` and ``--gyro-filter HZ`` (heli identify, diagnose and refresh): ``which`` inputs
    stated as a flight controller's commands, and the gyro its loop read as low-passed."""
    p.add_argument("--controller-loop", type=number("a loop rate in Hz above 0", 0.0), default=None, metavar="HZ",
                   help=f"ml: {which} are a flight controller's commands from a loop at HZ (for a CSV, which cannot "
                   "say so; imported logs state it): where HZ is faster than the log, the loop corrects the aircraft "
                   "inside each sample and the dampings read high, so the hold is taken as held where the data do not "
                   "reject it, and the closed-loop check flies the loop at HZ to measure and remove that bias")
    p.add_argument("--gyro-filter", type=number("a filter's corner in Hz above 0", 0.0), default=None, metavar="HZ",
                   help="ml: the gyro passed a 2-pole low-pass at HZ before the flight controller's loop read it and "
                   "the log wrote it (ArduPilot's INS_GYRO_FILTER, which its logs state; PX4's IMU_GYRO_CUTOFF): the "
                   "closed-loop check flies the loop through it. Without it, a loop faster than the log whose gyro "
                   "the fit found filtered is not checked")


def print_read_warnings(path, flight, progress=None) -> None:
    """Print what reading ``flight`` from ``path`` changed or doubted (``metadata["import_warnings"]``: a log
    imported as real loggers write them, a CSV whose clock was resampled), one line each."""
    for warning in flight.metadata.get("import_warnings") or ():
        if progress is not None:
            progress.done()
        print(f"warning: {path}: {warning}")


def print_check(check, title: str) -> None:
    """A closed-loop check (:class:`~identification.likelihood.closed_loop.ClosedLoopCheck`) as the terminal shows
    it: ``title`` with its headline, then a line per axis, delay tested and hold."""
    print(f"{title} ({check.headline()}):")
    for line in check.lines():
        print(f"  {line}")


def _identify_or_explain(args, flights, kwargs: dict, progress, identify):
    """``identify()``; when its model diverges, test whether searching the alignment (``--delay auto``) gives
    a physical, stable model, and say so in the error with the command to run next only if it does."""
    from identification.diagnosis.alignment_check import check_alignment
    from identification.errors import SimulationDivergedError
    from identification.validation.fit_warnings import controller_loop_warning

    try:
        return identify()
    except SimulationDivergedError as e:
        if args.method != "ml" or args.delay == "auto":
            raise
        # a flight controller's commands fitted slower than its loop read as damping: a cause to name beside the
        # refusal, whose warnings are never printed (the ArduCopter fixture: its RATE outputs at 9.9 Hz)
        loop = "".join(f" Note: {line}." for line in controller_loop_warning(flights, advice=False))
        loop += "".join(f" Note: {why}." for why in dict.fromkeys(f.metadata.get("fit_rate") for f in flights) if why)
        progress.stage("the model diverged: fitting again with the alignment searched (--delay auto)")
        finding = check_alignment(flights, kwargs)
        if finding.helps:
            advice = (f"Fitted with the alignment searched ({finding.seconds:.0f} s): {finding.describe()}. "
                      f"Identify with it: {next_command(args.argv, '--delay', 'auto')}")
        else:
            # no command advised: none is known to change the outcome (another input source of the same log
            # ended in the same refusal on the ArduCopter fixture)
            advice = (f"Searching the alignment (--delay auto) does not mend it: {finding.describe()}."
                      + _weak_axes_advice(finding))
        raise SimulationDivergedError(f"{e}{loop} {advice}") from None


def _weak_axes_advice(finding) -> str:
    """What to try when the alignment does not mend a diverging fit: the axes the sticks barely move are the
    ones the data cannot place (the ArduCopter fixture: 8 % and 0 % of roll's and pitch's rate from the sticks),
    and only a flight that moves them can (no command: none known changes the outcome on this flight)."""
    weak = [a for a in finding.explained if a not in finding.excited]
    if not weak:
        return ""
    return (f" What to try: identify from a flight whose sticks move the aircraft on {', '.join(weak)} (stick doublets "
            "or frequency sweeps of a few seconds on each)")


def next_command(argv, option: str, value: str) -> str:
    """The ``heli`` command line ``argv`` with ``option`` set to ``value`` (replaced or added), quoted."""
    import shlex

    argv = list(argv)
    for i, word in enumerate(argv):
        if word == option and i + 1 < len(argv):
            argv[i + 1] = value
            break
        if word.startswith(option + "="):
            argv[i] = f"{option}={value}"
            break
    else:
        argv += [option, value]
    return shlex.join(["heli"] + argv)


def print_verdict(verdict) -> None:
    """The model's verdict (:mod:`model_store.verdict`): its level, then one line per reason."""
    print(f"model verdict: {verdict.level}" + (":" if verdict.reasons else ""))
    for line in verdict.lines():
        print(f"  - {line}")


def _print_flight_checks(checks) -> None:
    """The model on the ``--validate`` flights: one line per flight and axis (fit %, R², 0.5 s-ahead R², CIFER's
    frequency-response cost J)."""
    if not checks:
        return
    from identification.likelihood.ahead_score import format_r2

    width = max(6, *(len(c.name) for c in checks))
    print(f"validation on {len(checks)} flight(s) not used for the fit ({checks[0].model} model simulated from "
          "their sticks, as MATLAB's compare):")
    print(f"  {'flight':{width}s}  axis    fit %      R²  R² 0.5 s ahead  freq. cost J")
    for c in checks:
        for axis in c.axes:
            fit = "diverged" if c.diverged else f"{c.fit_pct[axis]:.1f}"
            r2 = "diverged" if c.diverged else format_r2(c.r2[axis])
            ahead = "—" if c.ahead_r2 is None else format_r2(c.ahead_r2.get(axis))
            cost = c.cost.get(axis) if c.cost else None
            cost = "—" if cost is None or not math.isfinite(cost) else f"{cost:.1f}"
            print(f"  {c.name:{width}s}  {axis:5s} {fit:>8s} {r2:>7s} {ahead:>15s} {cost:>13s}")
        if c.diverged:
            print(f"  {c.name}: {c.diverged}")


def _print_run(run, n_flights: int, method: str) -> None:
    """The model's verdict, the identified parameters, the validation errors, warnings and the files written so
    far."""
    from identification.diagnosis.alignment_check import MIN_EXPLAINED

    if run.verdict is not None:
        print_verdict(run.verdict)
    params = run.params.values()
    print(f"identified {run.chosen} model from {n_flights} flight(s) by "
          f"{'maximum likelihood' if method == 'ml' else 'the integral method'}:")
    for axis, fit in run.identifiers[run.chosen].axes_.items():
        vals = ", ".join(f"{k}={params[k]:.4f}" for k in fit.params)
        delay = f", delay {fit.delay:.3f} s" if fit.delay else ""
        if getattr(fit, "input_shift", 0.0) < 0.0:
            delay += f", stick logged {-fit.input_shift:.3f} s late (advanced)"
            if fit.r2 < MIN_EXPLAINED:  # as the alignment check says it: the value is the likelihood's, weakly placed
                delay += (f", weakly placed: the stick explains {100 * max(fit.r2, 0.0):.0f} % of the rate, "
                          "too little to time it")
        if getattr(fit, "lag_lr", None) is not None:
            delay += (f", servo lag {fit.lag:.3f} s (LR {fit.lag_lr:.1f})" if fit.lag
                      else f", no servo lag supported (LR {fit.lag_lr:.1f})")
        print(f"  {axis:5s}: {vals}  (R² {fit.r2:.3f}{delay})")
    check = getattr(run.identifiers[run.chosen], "closed_loop_", None)
    if check is not None:
        print_check(check, "closed-loop check")
    stats = run.validation.rate_stats[run.chosen]
    print("forward-simulation MAE (deg/s): " + ", ".join(f"{a} {stats[a]['mae_deg_s']:.3f}" for a in stats))
    for profile in run.disturbances:
        mae = profile.simulation.rate_stats if profile.simulation is not None else None
        if mae:
            label = list(mae)[-1]
            print(f"with its identified wind ({profile.source.get('name', 'flight')}): MAE (deg/s) "
                  + ", ".join(f"{a} {mae[label][a]['mae_deg_s']:.3f}" for a in mae[label]))
    for warning in run.warnings:
        print(f"warning: {warning}")
    if run.library_version is not None:
        print(f"disturbance library: {run.paths['library']} version {run.library_version}")
    for key, path in run.paths.items():
        if key != "library":
            print(f"wrote {path}")
