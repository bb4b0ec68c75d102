"""``heli tune``: ArduPilot TradHeli or Rotorflight gains tuned in the identified gusts, written as the firmware's file."""

from __future__ import annotations

import sys
from pathlib import Path

from .argtypes import number, output_path, per_axis, seconds_or, segment_option, servo_lag, seed, whole
from .identify import CLOSED_LOOP_CHOICES, CLOSED_LOOP_ENV, closed_loop_mode, ml_settings, print_read_warnings
from .model_gate import add_accept_option, check_model

FIRMWARE_CHOICES = ("ardupilot", "rotorflight")
OWN_FORMATS = {"ardupilot": ("ardupilot-dataflash", "ardupilot-dataflash-text"), "rotorflight": ("blackbox",)}
"""The log formats each firmware writes (``identification.io.detect_format``'s names)."""


def _scale(text):
    """``--scale``: one number > 0 for every axis, or three (roll,pitch,yaw) as a tuple."""
    values = per_axis("one number > 0 or three separated by ',' (roll,pitch,yaw)")(text)
    return values if isinstance(values, float) else tuple(values)


_delay = seconds_or(("detect", "auto", "none"), "delay", 2.0)


def register(sub):
    p = sub.add_parser(
        "tune",
        help="tune ArduPilot TradHeli or Rotorflight gains in the identified gusts; write the firmware's file",
        description="Identify the model from LOG (or use --model), read the gains the aircraft flew (the log's "
        "parameters or --params FILE), and fly the firmware's own attitude loop — ArduPilot's heli loop at "
        "SCHED_LOOP_RATE, or Rotorflight's pid_mode 3 in angle mode at its PID rate, the physics sub-stepped to "
        "it — in the identified gusts. Sweeps the firmware's gains (ArduPilot: ATC_ANG_*_P x ATC_RAT_*_P with FF "
        "from the model; Rotorflight: P x angle_level_strength with F from the model, yaw P x I), keeps the sets "
        "with 6 dB, 45 deg and 25 ms (delay; --delay-margin) margins, flies the best few beside the current and the default "
        "gains, and writes DIR/ardupilot.param or DIR/rotorflight.txt (the proposed gains), the current gains to revert to, "
        "DIR/tune.json (per axis the current, default and proposed gains with their predicted p50/p90/p99 "
        "attitude error and 90 %% intervals, margins, loop rate and command scale), DIR/tune.md and tune.html "
        "with a flight-test card.",
    )
    p.add_argument("log", metavar="LOG|FLIGHT.csv",
                   help="the flight: an ArduPilot .bin log or a Rotorflight blackbox log (its parameters are "
                   "read), or a canonical CSV flight (then --params is needed)")
    p.add_argument("--firmware", required=True, choices=FIRMWARE_CHOICES, help="the firmware to tune")
    p.add_argument("--model", metavar="DIR", default=None,
                   help="a model directory written by 'heli identify' (default: identify LOG into DIR/model)")
    add_accept_option(p, "Tune gains on it")
    p.add_argument("--params", metavar="FILE", default=None,
                   help="the gains the aircraft flew: an ArduPilot parameter file (NAME,VALUE) or a Rotorflight "
                   "CLI file ('set name = value'); default: read from LOG")
    p.add_argument("--out", required=True, type=output_path, metavar="DIR", help="output directory")
    p.add_argument("--segment", type=segment_option, default=None, metavar="auto|all|T0:T1",
                   help="the stretch of LOG identified, as heli import's: the airborne segment found automatically "
                   "(default), the whole log ('all') or T0:T1 on the log's own clock [s]; with --model LOG is read "
                   "whole for its gains")
    p.add_argument("--scale", type=_scale, default=None, metavar="S|R,P,Y",
                   help="model stick per firmware output unit (one number, or roll,pitch,yaw); default: measured "
                   "from LOG (the model's input against the firmware's logged output), else 1")
    p.add_argument("--delay", type=_delay, default=None,
                   help="servo delay when identifying from LOG, as heli identify's: 'detect' (default: searched "
                   "from the undelayed fit and kept on the axes whose likelihood supports one), 'auto' (the "
                   "likelihood profiled on every axis), 'none' or seconds")
    p.add_argument("--servo-lag", type=servo_lag, default=None,
                   help="the servos' first-order lag when identifying from LOG, as heli identify's: 'detect' "
                   "(default: profiled where a servo delay is found), 'auto', 'none' or seconds")
    p.add_argument("--closed-loop", choices=CLOSED_LOOP_CHOICES, default=None,
                   help="the closed-loop check when identifying from LOG, as heli identify's: where a pilot's "
                   f"sticks follow the aircraft, remove the damping's bias they cause ('auto', the default, or "
                   f"${CLOSED_LOOP_ENV} when set), only report it ('report'), or skip it ('off': quicker; the "
                   "check costs 8-24 fits of the flight, each profiling a servo delay the flight's fit found)")
    p.add_argument("--window", type=number("a window length in seconds > 0", 0.0), default=20.0,
                   help="length of the gust windows flown in the time domain (default 20 s; they tile the library)")
    p.add_argument("--candidates", type=whole(1, 10), default=3,
                   help="robust candidate sets per axis flown in the time domain (default 3)")
    p.add_argument("--delay-margin", type=number("seconds in [0, 1]", 0.0, 1.0, low_open=False, high_open=False),
                   default=None, metavar="S",
                   help="delay margin a robust set keeps besides 6 dB and 45 deg, in seconds (default 0.025: the "
                   "loop survives 25 ms more servo delay than identified; 0 drops the criterion)")
    p.add_argument("--seed", type=seed(), default=0, help="seed of the windows and sensor errors (default 0)")
    p.add_argument("--no-sensors", action="store_true",
                   help="the loop reads the true state (default: through the model's identified sensors)")
    p.add_argument("--no-plots", action="store_true", help="do not draw the figures")
    p.set_defaults(func=run, out_kind="dir")


def _flown_gains(args, spec):
    """``(current parameters, notes, source)``; every bad input is refused here, before any work."""
    from controllers.firmware.errors import FirmwareParamError
    from identification.io import detect_format

    if args.params is not None:
        path = Path(args.params)
        if not path.is_file():
            raise FileNotFoundError(2, "no such parameter file", str(path))
        params, notes = spec.gains(path)
        return params, notes, str(path)
    fmt = detect_format(args.log)
    if fmt not in OWN_FORMATS[spec.name]:
        kind = "a CSV flight holds no parameters" if fmt == "csv" else f"{args.log} is a {fmt} log, not {spec.name}'s"
        raise FirmwareParamError(f"{kind}: give the gains the aircraft flew with --params FILE "
                                 f"({'NAME,VALUE lines' if spec.name == 'ardupilot' else 'CLI set lines'})")
    params, notes = spec.gains(args.log)
    return params, notes, str(args.log)


def _own_log(args, spec) -> str | None:
    """None when LOG is the tuned firmware's own log or a CSV flight, else why its controller output and desired
    attitude are not the firmware's (a log of another firmware given with ``--params``: its flight is used, its
    output units and attitude target are not)."""
    from controllers.firmware.errors import FirmwareParamError
    from identification.io import detect_format

    fmt = detect_format(args.log)
    if fmt == "csv":
        return None
    why = f"{args.log} is a {fmt} log, not {spec.name}'s"
    if fmt not in OWN_FORMATS[spec.name]:
        return why
    if fmt == "blackbox":
        try:
            spec.read(args.log)  # a Betaflight blackbox is refused here as not Rotorflight's
        except FirmwareParamError:
            return why
    return None


def _check_mapping(spec, current, sample_rate: float, params=None) -> None:
    """Refuse, before any work, a loop rate the gusts' period cannot hold and axes the model cannot control."""
    from controllers.firmware.tune import control_signs

    signs = control_signs(params) if params is not None else (1.0, 1.0, 1.0)
    spec.loop_class(current, 1.0, signs).substeps(1.0 / sample_rate)


def _checked_log(args, spec, progress):
    """The flight in LOG, read and checked before any work, with ``--model`` too: ``(Flight or None, input source)``.

    LOG gives the gains (without ``--params``), the command scale (without ``--scale``) and what the log flew
    against its desired attitude; with ``--model`` it is still read whole by the one loader
    (:func:`identification.io.read_log`, its whole length: a flight that never left the ground still gives its
    parameters), so a truncated, damaged or foreign file is refused in one line instead of tuning on and
    falling back to defaults in silence. An ArduPilot text log holds no flight by design (no body rates); its
    ``PARM`` messages are what is read of it.
    """
    from identification.io import detect_format, read_log

    fmt = detect_format(args.log)
    if fmt == "ardupilot-dataflash-text":
        if spec.name == "ardupilot":
            spec.read(args.log)  # refuses a text log without PARM messages
        return None, None
    progress.stage(f"reading {args.log}")
    flight = read_log(args.log, segment="all" if args.model is not None else args.segment)
    print_read_warnings(args.log, flight, progress)
    return flight, flight.metadata.get("input_source")


def _model(args, spec, current, progress, settings):
    """``(EnvModel, model folder, the input source of LOG's flight or None, segment or None)``; without
    ``--model`` identified from LOG with the identifier's ``settings`` (``heli identify``'s:
    :func:`heli_cli.identify.ml_settings`)."""
    from heli_env.env_model import load_env_model

    if args.model is not None:
        if not Path(args.model).is_dir():
            raise FileNotFoundError(2, "no such model directory (write one with 'heli identify')", str(args.model))
        check_model(args, "tune firmware gains on it")
        env_model = load_env_model(args.model)
        _check_mapping(spec, current, env_model.sample_rate, env_model.params)
        _, source = _checked_log(args, spec, progress)
        return env_model, Path(args.model), source, None
    from identification.workflows.identify import identify_and_report, segment_read, source_entry

    flight, _ = _checked_log(args, spec, progress)
    if flight is None:
        from identification.io import read_flight

        read_flight(args.log)  # an ArduPilot text log: refused here, saying what it holds and lacks
    _check_mapping(spec, current, flight.sample_rate)
    from identification.fit_rate import at_fit_rate

    from .identify import fit_rate_setting

    setting = fit_rate_setting(None)  # heli identify's default ($HELI_FIT_RATE, else auto)
    if setting == "auto":
        progress.stage("choosing the fit rate (the log's fitted at its rate and at half of it)")
    (flight,), fit_rate = at_fit_rate([flight], setting)  # a firmware's gyro is low-passed before it is logged
    if fit_rate.every > 1:
        _check_mapping(spec, current, flight.sample_rate)  # the gusts' period the model is written with
    folder = Path(args.out) / "model"
    # the decoupled model alone: the firmware loops fly it, and the coupled one cost a third of this step
    source = source_entry(args.log, segment=segment_read(args.segment, flight))
    identify_and_report([flight], folder, sources=[source],
                        flight_paths=[args.log], plots=False,
                        identifier_kwargs=settings, stage=progress.stage, progress=False,
                        compare_structures=False)
    args.model = str(folder)
    check_model(args, "tune firmware gains on it")
    return (load_env_model(folder), folder, flight.metadata.get("input_source"),
            flight.metadata.get("segment"))


def run(args) -> int:
    from controllers.firmware.firmwares import FIRMWARES
    from controllers.firmware.flown import FlownErrors, flown_errors
    from controllers.firmware.scale import default_scale, measure_scale, user_scale
    from controllers.firmware.tune import TuneConfig, tune_gains
    from controllers.firmware.tune_output import write_outputs

    from .progress import progress_of

    spec = FIRMWARES[args.firmware]
    settings = None
    if args.model is None:
        try:
            settings = ml_settings(args, closed_loop_mode(args))
        except ValueError as exc:  # $HELI_CLOSED_LOOP misspelt: refused before any work, as heli identify does
            print(f"heli tune: error: {exc}", file=sys.stderr)
            return 2
    if not Path(args.log).is_file():
        raise FileNotFoundError(2, "no such flight log", str(args.log))
    current, read_notes, source = _flown_gains(args, spec)  # refused before any work or file
    progress = progress_of(args)
    env_model, folder, input_source, segment = _model(args, spec, current, progress, settings)
    progress.stage("measuring the command scale" if args.scale is None else "using the given command scale")
    foreign = _own_log(args, spec)
    if args.scale is not None:
        scale = user_scale(args.scale)
    elif foreign:
        scale = default_scale(f"{foreign}: its controller output is in another firmware's units")
    else:
        scale = measure_scale(args.log, input_source)
    margin = {} if args.delay_margin is None else {"delay_margin_s": args.delay_margin}
    cfg = TuneConfig(window_s=args.window, candidates=args.candidates, seed=args.seed, sensors=not args.no_sensors,
                     progress=progress.bars, **margin)
    result = tune_gains(env_model, spec, current, scale, cfg, stage=progress.stage)
    result.notes[:0] = [f"gains read from {source}: {n}" for n in read_notes]
    flown = (FlownErrors(False, f"{foreign}: what it flew is another firmware's loop") if foreign
             else flown_errors(args.log, segment))
    progress.stage("writing the parameter files, tune.json and the report")
    context = [f"Model: `{folder}`; flight: `{args.log}`; gains flown: `{source}`."]
    paths = write_outputs(result, args.out, flown, context, plots=not args.no_plots,
                          command=" ".join(["heli"] + list(getattr(args, "argv", []))))
    progress.done()
    from .html_report import write_html_report

    paths["html"] = write_html_report(paths["report"])
    _print_summary(result, scale)
    for key in ("proposed", "current", "json", "report", "html"):
        print(f"wrote {paths[key]}")
    for fig in paths.get("figures", []):
        print(f"wrote {fig}")
    return 0


def _print_summary(result, scale) -> None:
    print(f"heli tune: {result.firmware} at {result.loop_rate_hz:g} Hz, command scale "
          f"{', '.join(f'{v:.4g}' for v in scale.scale)} ({scale.source}), "
          f"{result.settings['seconds']:.1f} s")
    for axis, row in result.axes.items():
        def p90(s):
            return "diverged" if s.get("diverged", True) else f"{s['p90_deg']:.3g}"

        tail = " (defaults already near best)" if row["defaults_near_best"] else ""
        kept = " (kept: no robust set)" if row["kept_current"] else ""
        prop = row["proposed"]
        print(f"  {axis:5s}: p90 |attitude error| current {p90(row['current'])}, default {p90(row['default'])}, "
              f"proposed {p90(prop)} deg; proposed margins {prop['gain_margin_db']:.3g} dB / "
              f"{prop['phase_margin_deg']:.3g} deg / {prop['delay_margin_s'] * 1000:.3g} ms{kept}{tail}")
    for note in result.notes:
        print(f"note: {note}")
