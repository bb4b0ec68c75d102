"""``heli simulate-flight``: write a synthetic hover flight and its truth."""

from __future__ import annotations


from identification.synthetic import EFFECT_ALIASES, EFFECTS

from .argtypes import number, whole


def register(sub):
    p = sub.add_parser(
        "simulate-flight",
        help="fly the truth model (paper eqs. 18, 21) with a pilot, wind and sensor noise; write a CSV flight",
        description="Write a realistic synthetic hover flight (canonical CSV) plus its truth: "
        "<stem>.truth.json (parameters, seed, settings) and <stem>.wind.csv (the true wind u_d).",
    )
    p.add_argument("--duration", type=number("a finite number > 0", 0.0),
                   default=300.0, help="flight length in seconds (default 300)")
    p.add_argument("--seed", type=whole(0), default=1, help="random seed: same seed, same flight (default 1)")
    p.add_argument("--out", required=True, help="output CSV path, e.g. flight.csv")
    p.add_argument("--effect", action="append", default=[], metavar="NAME",
                   choices=sorted(list(EFFECTS) + list(EFFECT_ALIASES)),
                   help=f"switch on a hidden physical effect (repeatable): {', '.join(EFFECTS)}")
    p.add_argument("--wind", type=number("a finite number >= 0", 0.0, low_open=False), default=None,
                   help="half-width of the 90%% interval of the cyclic wind u_d (default 0.09, the paper's level)")
    p.set_defaults(func=run)


def run(args) -> int:
    from dataclasses import replace

    from identification.synthetic import FlightConfig, simulate_flight

    cfg = FlightConfig(duration=args.duration)
    if args.wind is not None:
        cfg = replace(cfg, wind_level=(args.wind, args.wind, args.wind / 3.0))
    result = simulate_flight(args.duration, seed=args.seed, effects=tuple(args.effect), config=cfg)
    paths = result.save(args.out)
    f = result.flight
    print(f"wrote {paths['flight']} ({f.duration:.1f} s, {f.n} samples at {f.sample_rate:.0f} Hz)")
    print(f"truth: {paths['truth']}  wind: {paths['wind']}")
    if args.effect:
        print(f"hidden effects: {', '.join(args.effect)}")
    return 0
