"""The derivative filter's effect on the designed PD: stick activity and held-out p90, per filter rule.

For each derivative-filter request (none, the rule ``f_c = N x crossover`` for several N, and the
unfiltered design's gains with a fixed filter added but not redesigned, margins falling) the PD is designed with
:func:`controllers.pd.design_gains` (default bandwidth and 45 deg phase margin) and flown by the one
evaluator (:func:`controllers.evaluate.evaluate_agent`, attitude hold from rest, the model's sensors) on
the same gust windows. Printed per axis: the stick's RMS, its RMS increment per control period, its
variance above 10 Hz, the p90 |attitude error| and its change against the unfiltered design, the loop's
phase and gain margins and the filter's cutoff. The figures in docs/controllers.md ("The derivative
filter") come from::

    .venv/bin/python scripts/d_filter_study.py --traces all --episodes-per-trace 4

(about a minute on one core).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from controllers.evaluate import EvaluationConfig, evaluate_agent  # noqa: E402
from controllers.pd import PDController, PDGains, design_gains, loop_analysis  # noqa: E402
from heli_core.terms import AXES  # noqa: E402
from heli_env.env_model import load_env_model  # noqa: E402


def cases(params, ratios, plain_filter_hz=None):
    """(label, PDGains) of every filter request flown."""
    plain = design_gains(params)
    out = [("no filter", plain)]
    out += [(f"{n:g} x crossover", design_gains(params, d_filter_hz="auto", d_filter_ratio=n)) for n in ratios]
    if plain_filter_hz:
        out.append((f"unfiltered gains + {plain_filter_hz:g} Hz (not redesigned)",
                    PDGains(plain.kp, plain.kd, plain_filter_hz)))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--model", default=None, help="model directory (default: the shipped model)")
    p.add_argument("--traces", default="held-out", choices=("held-out", "all"))
    p.add_argument("--episodes-per-trace", type=int, default=4)
    p.add_argument("--episode-seconds", type=float, default=30.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--ratios", default="5,10,15,20,30", help="multiples N of the crossover (comma separated)")
    p.add_argument("--plain-filter-hz", type=float, default=5.0,
                   help="also fly the unfiltered design's gains with this filter added, not redesigned (0: not)")
    args = p.parse_args(argv)
    env_model = load_env_model(args.model)
    params = env_model.params
    config = EvaluationConfig(traces=args.traces, episodes_per_trace=args.episodes_per_trace,
                              episode_seconds=args.episode_seconds, seed=args.seed)
    base = None
    print("| filter | axis | cutoff [Hz] | kp | kd | PM [deg] | GM [dB] | stick RMS | RMS stick step | "
          "variance > 10 Hz | p90 att [deg] | p90 vs no filter |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for label, gains in cases(params, [float(v) for v in args.ratios.split(",")], args.plain_filter_hz):
        res = evaluate_agent(PDController.from_model(params, gains), env_model, config, name=label)
        base = base or res
        for i, ax in enumerate(AXES):
            an = loop_analysis(params, ax, gains.kp[i], gains.kd[i], d_filter_hz=gains.d_filter_hz[i])
            act, m = res.activity[ax], res.metrics[ax]
            change = m["att_p90_deg"] / base.metrics[ax]["att_p90_deg"] - 1.0
            cut = gains.d_filter_hz[i]
            print(f"| {label} | {ax} | {'—' if cut is None else f'{cut:.3g}'} | {gains.kp[i]:.4g} | "
                  f"{gains.kd[i]:.4g} | {an.phase_margin:.1f} | {an.gain_margin_db:.1f} | {act['stick_rms']:.3f} | "
                  f"{act['stick_step_rms']:.3f} | {100 * act['stick_hf_fraction']:.0f} % | "
                  f"{m['att_p90_deg']:.4f} | {100 * change:+.1f} % |")
    st = base.settings
    print(f"\n{len(base.episodes)} episodes of {st['episode_seconds']:g} s on {st['traces_label']} traces "
          f"{', '.join(st['trace_ids_used'])}, seed {st['seed']}, dt {st['dt']:g} s; model {st['model']}")
    return 0 if all(math.isfinite(base.metrics[a]["att_p90_deg"]) for a in AXES) else 1


if __name__ == "__main__":
    raise SystemExit(main())
