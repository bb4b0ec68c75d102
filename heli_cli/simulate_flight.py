"""``heli simulate-flight``: write a synthetic hover flight and its truth."""

from __future__ import annotations


CELL_NAMES = ("default", "independent", "broadband-pd-half", "broadband-pd-2x", "broadband-pd-delay0.1",
              "broadband-pd-delay0.25", "dryden-0.2Hz-pid", "dryden-2Hz-pd", "broadband-autopilot",
              "held-sticks-pd", "broadband-pd-noisy-gyro")
"""The names of :data:`identification.bench.cells.BENCH_CELLS`, written here so that ``--help`` imports no numpy
(a test keeps the two equal)."""

EFFECT_NAMES = ("servo_delay", "cross_coupling", "gyroscopic", "nonlinear_damping", "gain_scheduling",
                "collective_torque", "servo_lag")
"""The names of :data:`identification.bench.flight_config.EFFECTS` (a test keeps the two equal)."""

EFFECT_ALIAS_NAMES = ("flybar", "quadratic_damping", "collective_effectiveness")
"""The names of :data:`identification.bench.flight_config.EFFECT_ALIASES` (a test keeps the two equal)."""

from .argtypes import FLIGHT_BYTES_PER_SECOND, affordable, number, output_path, seed, whole

MIN_RATE_HZ, MAX_RATE_HZ = 10.0, 2000.0
"""The log rates ``--rate`` takes [Hz]: from a slow logger's to a flight controller's loop."""
DEFAULT_RATE_HZ = 100.0
"""The log rate of a flight without ``--rate`` (``FlightConfig``'s) [Hz]; ``FLIGHT_BYTES_PER_SECOND`` is measured at it."""


def register(sub):
    p = sub.add_parser(
        "simulate-flight",
        help="write a synthetic test flight (CSV) and its true parameters",
        description="Write a realistic synthetic hover flight (canonical CSV) plus its truth: "
        "<stem>.truth.json (parameters, seed, settings) and <stem>.wind.csv (the true wind u_d).",
    )
    p.add_argument("--duration", type=affordable("a flight length in seconds > 0", FLIGHT_BYTES_PER_SECOND, "s"),
                   default=300.0, help="flight length in seconds (default 300)")
    p.add_argument("--seed", type=seed(), default=1, help="random seed: same seed, same flight (default 1)")
    p.add_argument("--out", required=True, type=output_path, help="output CSV path, e.g. flight.csv")
    p.add_argument("--effect", action="append", default=[], metavar="NAME",
                   choices=sorted(EFFECT_NAMES + EFFECT_ALIAS_NAMES),
                   help=f"switch on a hidden physical effect (repeatable): {', '.join(EFFECT_NAMES)}")
    p.add_argument("--effect-scale", type=number("a number > 0", 0.0), default=1.0, metavar="X",
                   help="multiply the sizes of the --effect parameters (default 1; the diagnosis study's quadratic "
                   "damping is 5)")
    p.add_argument("--manoeuvre", action="store_true",
                   help="an aggressive pilot: large sweeps on all three sticks at once (rates to ~60 deg/s in roll, "
                   "~150 deg/s in yaw), where gyroscopic and quadratic-damping effects show")
    p.add_argument("--wind", type=number("a finite number >= 0", 0.0, low_open=False), default=None,
                   help="half-width of the 90%% interval of the cyclic wind u_d (default 0.09, the paper's level)")
    p.add_argument("--cell", default=None, choices=sorted(CELL_NAMES), metavar="NAME",
                   help="start from a test-bench condition (identification/bench/cells.py): "
                   + ", ".join(CELL_NAMES) + "; the options below change it further")
    p.add_argument("--wind-scale", type=number("a number > 0", 0.0), default=None,
                   help="multiply the wind level (0.5 to 2 spans calm to twice the paper's)")
    p.add_argument("--wind-model", choices=("lowpass", "gauss_markov", "dryden"), default=None,
                   help="gust spectrum: 'lowpass' (2nd-order, default), 'gauss_markov' (1st-order, broadband), "
                   "'dryden' (lateral Dryden form)")
    p.add_argument("--wind-corner", type=number("a frequency in Hz from 0.001 to below 50 (Nyquist of a 100 Hz flight)", 0.001, 50.0, low_open=False), default=None,
                   help="corner of the lowpass/Dryden gusts in Hz (0.2 to 2 typical; default 0.5)")
    p.add_argument("--slow-gusts", type=number("a fraction in [0, 1)", 0.0, 1.0, low_open=False), default=None,
                   help="share of the wind's variance in slow gusts (first-order, 4 s)")
    p.add_argument("--pilot", choices=("pid", "pd", "autopilot"), default=None,
                   help="'pid' the default human pilot, 'pd' a pilot fighting gusts with a PD on attitude and rate, "
                   "'autopilot' a flight controller holding its commands between samples")
    p.add_argument("--reaction-delay", type=number("seconds from 0 to 5", 0.0, 5.0, low_open=False, high_open=False), default=None,
                   help="the pilot's reaction delay in s (0.1-0.25 typical; default 0.2)")
    p.add_argument("--gyro-noise", type=number("rad/s >= 0", 0.0, low_open=False), default=None,
                   help="gyro white-noise standard deviation in rad/s (default 0.01)")
    p.add_argument("--gyro-filter", type=number("a corner in Hz above 0", 0.0), default=None, metavar="HZ",
                   help="log the gyro through a flight controller's 2-pole low-pass at HZ, run at the world's rate "
                   "(ArduPilot's INS_GYRO_FILTER is 20 Hz; default: the gyro as sampled); the autopilot flies on it")
    p.add_argument("--vibration-line", action="append", default=[], type=_line, metavar="HZ:AMP",
                   help="an extra vibration line on every gyro axis, e.g. 27:0.03 (Hz : rad/s; repeatable)")
    p.add_argument("--input-shift", type=number("seconds", None), default=None,
                   help="shift the logged sticks in s: > 0 the log's inputs lag the response, < 0 they lead")
    p.add_argument("--rate", type=number(f"a log rate in Hz from {MIN_RATE_HZ:g} to {MAX_RATE_HZ:g}", MIN_RATE_HZ,
                                         MAX_RATE_HZ, low_open=False, high_open=False),
                   default=None, metavar="HZ",
                   help="the log's sample rate in Hz (default 100); the world steps at it unless --log-every says "
                   "otherwise")
    p.add_argument("--log-every", type=whole(1, 16), default=None, metavar="N",
                   help="fly the world (pilot, radio link, gusts, sensors) N times faster than the log and log "
                   "every N-th step, as a logger samples a flight that does not wait for it (default 1: the world "
                   "steps at the log's rate)")
    p.set_defaults(func=run, out_kind="file")


def _line(text):
    import argparse
    import math

    try:
        hz, amp = (float(v) for v in text.split(":"))
    except ValueError:
        hz = amp = math.nan
    if not (0 < hz < math.inf and 0 <= amp < math.inf):
        raise argparse.ArgumentTypeError(f"expected HZ:AMP with HZ > 0 and AMP >= 0 (rad/s), e.g. 27:0.03; got {text!r}")
    return (hz, amp)


def run(args) -> int:
    from identification.bench.synthetic import simulate_flight
    from identification.validation.fit_warnings import loop_ticks

    from .progress import progress_of

    try:
        cfg = _config(args)
    except ValueError as e:  # a combination the single options cannot check (e.g. a shift longer than the flight)
        import sys

        print(f"heli simulate-flight: error: {e}", file=sys.stderr)
        return 2
    with progress_of(args) as progress:
        progress.stage(f"flying a {args.duration:g} s flight (pilot, wind and sensors of the truth model)")
        result = simulate_flight(args.duration, seed=args.seed, effects=tuple(args.effect), config=cfg,
                                 effect_scale=args.effect_scale)
        paths = result.save(args.out)
    f = result.flight
    print(f"wrote {paths['flight']} ({f.duration:.1f} s, {f.n} samples at {f.sample_rate:.0f} Hz)")
    print(f"truth: {paths['truth']}  wind: {paths['wind']}")
    if args.effect:
        scale = f" (x{args.effect_scale:g})" if args.effect_scale != 1.0 else ""
        print(f"hidden effects: {', '.join(args.effect)}{scale}")
    if f.metadata.get("input_hold") == "zoh":  # a CSV does not carry it: the estimators find it
        print("the sticks reach the aircraft held over each sample (a CSV does not say so: heli identify and "
              "diagnose estimate the hold from the data)")
    if loop_ticks(f) > 1:  # a CSV cannot say so either: the user states it
        loop = f.metadata["loop_rate_hz"]
        corner = f.metadata.get("gyro_filter_hz")
        through = f" --gyro-filter {corner:g}" if corner else ""
        print(f"the inputs are a flight controller's commands from a {loop:g} Hz loop, faster than the log (a CSV "
              f"does not say so: heli identify {paths['flight']} --controller-loop {loop:g}{through} flies that loop "
              f"{'through its gyro filter ' if corner else ''}in its closed-loop check)")
    return 0


def _config(args):
    """The flight's settings from a bench cell (or the default) and the options that change it."""
    from dataclasses import replace

    from identification.bench.cells import BENCH_CELLS
    from identification.bench.flight_config import MANOEUVRE_CONFIG, FlightConfig

    cfg = replace(BENCH_CELLS[args.cell], duration=args.duration) if args.cell else FlightConfig(duration=args.duration)
    if args.manoeuvre:
        cfg = replace(cfg, sweep_amplitude=MANOEUVRE_CONFIG.sweep_amplitude, sweep_mode=MANOEUVRE_CONFIG.sweep_mode)
    if args.wind is not None:
        cfg = replace(cfg, wind_level=(args.wind, args.wind, args.wind / 3.0))
    changes = {"wind_model": args.wind_model, "wind_corner_hz": args.wind_corner, "pilot": args.pilot,
               "wind_slow_fraction": args.slow_gusts, "reaction_delay": args.reaction_delay,
               "gyro_noise": args.gyro_noise, "input_shift": args.input_shift, "log_every": args.log_every,
               "sample_rate": args.rate, "gyro_filter_hz": args.gyro_filter}
    cfg = replace(cfg, **{k: v for k, v in changes.items() if v is not None})
    if args.wind_corner is not None and cfg.inert(["wind_corner_hz"]):
        raise ValueError(f"--wind-corner shapes the lowpass and Dryden gusts; this flight's are gauss_markov"
                         f"{' (from --cell ' + args.cell + ')' if args.cell else ''}: add --wind-model lowpass or "
                         "dryden, or leave --wind-corner out")
    if args.wind_scale is not None:
        cfg = replace(cfg, wind_level=tuple(args.wind_scale * w for w in cfg.wind_level))
    if args.vibration_line:
        cfg = replace(cfg, vibration_lines=tuple(cfg.vibration_lines) + tuple(args.vibration_line))
    if cfg.wind_corner_hz >= cfg.sample_rate / 2 and not cfg.inert(["wind_corner_hz"]):
        raise ValueError(f"--wind-corner {cfg.wind_corner_hz:g} Hz is not below the Nyquist frequency of a "
                         f"{cfg.sample_rate:g} Hz log ({cfg.sample_rate / 2:g} Hz): lower it or raise --rate")
    steps = cfg.log_every * cfg.sample_rate / DEFAULT_RATE_HZ  # the world is flown whole before it is sampled
    if steps > 1:
        from .argtypes import memory_shortfall

        short = memory_shortfall(args.duration * steps * FLIGHT_BYTES_PER_SECOND)
        if short:
            world = cfg.sample_rate * cfg.log_every
            raise ValueError(f"--duration {args.duration:g} with --rate {cfg.sample_rate:g}"
                             + (f" and --log-every {cfg.log_every}" if cfg.log_every > 1 else "")
                             + f" flies a {world:g} Hz world for {args.duration:g} s: {short}; shorten the flight, "
                             "or lower --rate or --log-every")
    return cfg
