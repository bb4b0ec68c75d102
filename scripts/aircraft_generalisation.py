"""Other aircraft than the bench's: does the default identification hold on helicopters it was not tuned on?

Every bench cell flies the paper's aircraft (eqs. 68-70). This study flies the same cells with other truth
parameters (:data:`AIRCRAFT`: a small agile helicopter, a large sluggish one, one whose roll is much faster
than its pitch, and one whose sticks are mapped the other way round, negative roll and yaw gains and a
positive pitch gain) and log rates, and per flight runs what a user runs with no flags:

* the maximum-likelihood identifier as ``heli identify`` (:class:`MaximumLikelihoodIdentifier` with
  ``CLI_TIMING``: the log's timing detected, the hold estimated; the closed-loop check removing significant
  biases, ``--closed-loop off`` without it): relative error of the gains (k2, k6, k10) and dampings (k3, k7, k11);
* with ``--diagnose``, the likelihood diagnosis as ``heli diagnose`` on the same flight: effect-free, any
  effect it names is wrong; with ``--effect NAME`` (one of
  :data:`identification.bench.flight_config.EFFECTS`, hidden in the truth at its catalogue size), what it names
  beside the hidden effect is wrong, and the hidden effect should be named. A servo lag shows first as a delay
  (the diagnosis tries the lag behind a delay found): with a lag hidden, a servo delay named on an axis whose lag
  is then named too is the lag's first step, not a wrong effect; on an axis without the lag it is wrong.

Prints per aircraft and cell the RMS [worst] relative error of each parameter over the seeds, the hold
fractions, and the wrong diagnoses; then, over every flight, whether the standard errors the model reports hold
its errors (z = error / standard error: RMS about 1 where they do), a true servo delay's too (``--servo-delay``)
where the fit kept one.

Usage::

    python scripts/aircraft_generalisation.py [--seeds 3] [--first-seed 1] [--duration 300] [--workers 2]
        [--diagnose] [--aircraft agile ...] [--cells independent ...] [--rates 100 ...]
        [--set FIELD=VALUE ...] [--servo-delay AXIS=SECONDS ...] [--closed-loop auto|off] [--timing]

With ``--servo-delay`` the truths carry a servo delay (eq. 31) and the fitted delay's range and RMS error are
printed per axis. With ``--timing`` each flight's servo delay and lag kept per axis are printed, and the closed-loop
check's verdict on a timing the search found (:mod:`identification.likelihood.delay_check`).

With ``--at-truth`` the closed-loop check is flown a second time, on each checked axis at the truth's values
instead of the fitted ones (the flight's own pilot, hold, gust model and timing): the bias an exact correction would
remove, and the estimator's own spread where the truth is. Printed per aircraft and cell and per checked
parameter: the RMS error after that exact correction (the best any correction by this bootstrap can do), the
spread of the fits of the truth's world (their standard deviation, the mean over flights), and ``z``, the
flight's fitted value less the mean of those fits, over their spread (mean and RMS: about 0 and 1 where the
check's world flies as the flight's did).
"""

from __future__ import annotations

import argparse
import shlex
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np

from identification.bench.aircraft import AIRCRAFT, aircraft_truth

GAINS = ("k2", "k6", "k10")
DAMPINGS = ("k3", "k7", "k11")
PARAMS = GAINS + DAMPINGS

def config_field(text: str) -> tuple:
    """``FIELD=VALUE`` of a command line: a :class:`~identification.bench.flight_config.FlightConfig` field and a
    Python literal."""
    import ast
    from dataclasses import fields

    from identification.bench.flight_config import FlightConfig

    name, _, value = text.partition("=")
    known = [f.name for f in fields(FlightConfig)]
    if not name or not value:
        raise argparse.ArgumentTypeError(f"expected FIELD=VALUE (a FlightConfig field), got {text!r}")
    if name not in known:
        raise argparse.ArgumentTypeError(f"expected a FlightConfig field ({', '.join(known)}), got {name!r}")
    try:
        return name, ast.literal_eval(value)
    except (ValueError, SyntaxError):
        raise argparse.ArgumentTypeError(f"expected a Python literal after {name}=, got {value!r}") from None


def servo_delay(text: str) -> tuple:
    """``AXIS=SECONDS`` of a command line: a true servo delay (eq. 31) on one axis."""
    axis, _, value = text.partition("=")
    if axis not in ("roll", "pitch", "yaw"):
        raise argparse.ArgumentTypeError(f"expected AXIS=SECONDS with AXIS roll, pitch or yaw, got {text!r}")
    try:
        seconds = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds after {axis}=, got {value!r}") from None
    if not 0.0 <= seconds <= 0.5:
        raise argparse.ArgumentTypeError(f"expected a delay in [0, 0.5] s, got {seconds!r}")
    return axis, seconds


def _one(job):
    """Fly one (aircraft, cell, rate, seed) and identify (and diagnose) it as the CLI does by default."""
    from threadpoolctl import threadpool_limits

    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.fit_rate import at_fit_rate
    from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier
    from heli_core.terms import AXES, TERMS
    from identification.likelihood.input_hold import std_errors_with_hold

    (aircraft, cell, rate, seed, duration, diagnose, effect, closed_loop, settings, delays, at_truth, fit_rate,
     unstated) = job
    with threadpool_limits(limits=1, user_api="blas"):
        config = replace(BENCH_CELLS[cell], duration=duration, sample_rate=float(rate), **dict(settings))
        truth = replace(aircraft_truth(aircraft), **{f"tau_{axis}": tau for axis, tau in delays})
        sim = simulate_flight(duration, seed=seed, config=config, truth=truth, effects=(effect,) if effect else ())
        truth = sim.truth.values()
        out = {"aircraft": aircraft, "cell": cell, "rate": rate, "seed": seed}
        t0 = time.perf_counter()
        logged = sim.flight.with_metadata(gyro_filter_hz=None) if unstated else sim.flight  # a CSV's: no corner
        (flight,), chosen = at_fit_rate([logged], fit_rate)  # as heli identify reads a log (--fit-rate)
        out["fit_every"] = chosen.every
        try:
            ml = MaximumLikelihoodIdentifier(**CLI_TIMING, closed_loop=closed_loop).fit(flight)
        except Exception as exc:  # a refusal is a finding of this study, not its end
            out["error"] = f"{type(exc).__name__}: {exc}"
            return out
        out["ml_time_s"] = time.perf_counter() - t0
        v = ml.params_.values()
        out["ml"] = {k: 100.0 * (v[k] - truth[k]) / truth[k] for k in PARAMS}
        alternative = getattr(ml, "hold_alternative_", None)  # the hold's doubt, where the data leave one
        widened = {axis: std_errors_with_hold(f.params, f.std_errors, alternative, axis)
                   for axis, f in ml.axes_.items()}
        se = {k: widened[AXES[TERMS[k].axis]].get(k, 0.0) for k in PARAMS}
        out["hold_doubt"] = alternative is not None
        out["z"] = {k: (v[k] - truth[k]) / se[k] for k in PARAMS if se[k] > 0}
        out["se"] = {k: 100.0 * se[k] / abs(truth[k]) for k in PARAMS}
        for axis, tau in delays:  # a true servo delay the fit kept, with its standard error
            fit, k = ml.axes_[axis], f"tau_{axis}"
            if fit.delay > 0.0 and widened[axis].get(k, 0.0) > 0.0:
                out["z"][k] = (fit.delay - tau) / widened[axis][k]
                out["se"][k] = 100.0 * widened[axis][k] / tau
        out["hold"] = [f.input_hold for f in ml.axes_.values()]
        out["delays"] = {axis: (tau, ml.axes_[axis].delay) for axis, tau in delays}
        out["timing"] = {axis: (f.delay, f.lag) for axis, f in ml.axes_.items()}
        out["timing_checks"] = [d.line() for d in getattr(ml.closed_loop_, "delays", {}).values()]
        hold = getattr(ml.closed_loop_, "hold", None)
        out["hold_check"] = None if hold is None else hold.describe()
        if at_truth and ml.closed_loop_ is not None:
            out["at_truth"] = _check_at_truth(ml, truth, dict(delays))
        if diagnose:
            from identification.diagnosis.likelihood_diagnoser import LikelihoodDiagnoser

            t0 = time.perf_counter()
            d = LikelihoodDiagnoser().fit(flight)
            out["diagnosis_s"] = time.perf_counter() - t0
            out["named"] = [(s.axis, s.effect, round(float(s.lr), 1)) for s in d.steps_]
            out["effect"] = effect
    return out


def _check_at_truth(ml, truth: dict, delays: dict) -> dict:
    """The closed-loop check of ``ml`` (fitted and checked) flown again with each checked axis at the ``truth``'s
    values (``delays``: axis -> the true servo delay; none elsewhere), in mode "report": per checked parameter, the
    error [%] of the fitted value corrected by the bias measured there, the fits' spread there [%] and the flight's
    ``z`` (module docstring)."""
    from identification.likelihood.closed_loop import check_closed_loop, set_axis_values

    first = ml.closed_loop_
    checked = {axis: c for axis, c in first.axes.items() if c.checked}
    for axis, c in checked.items():
        set_axis_values(ml, axis, {k: delays.get(axis, 0.0) if k.startswith("tau_") else truth[k] for k in c.fitted})
    again = check_closed_loop(ml, ml.closed_loop_flights, seed=1, mode="report", workers=1)
    out = {}
    for axis, c in checked.items():
        a = again.axes[axis]
        if not a.checked:
            continue
        for k, fitted in c.fitted.items():
            if k not in a.bias:  # a delay fitted where the truth has none: its world flies no servo
                continue
            true, spread = a.fitted[k], a.bias_se[k] * np.sqrt(again.n_flights)
            out[k] = {"exact": 100.0 * (fitted / (1.0 + a.bias[k]) - true) / true, "spread": 100.0 * spread,
                      "z": (fitted / true - 1.0 - a.bias[k]) / max(spread, 1e-12)}
    return out


def _truth_table(rows) -> None:
    """The ``--at-truth`` rows (module docstring)."""
    keys = sorted({(r["aircraft"], r["cell"], r["rate"]) for r in rows if r.get("at_truth")}, key=str)
    if not keys:
        return
    print("\nThe check flown at the truth: error after the exact correction, RMS [worst] %; the fits' spread there, "
          "% (mean); z of the flight's fit, mean / RMS")
    print("| aircraft | cell | log rate | parameter | exact correction | spread at the truth | z | flights |")
    print("|---|---|---|---|---|---|---|---|")
    for key in keys:
        rs = [r["at_truth"] for r in rows if (r["aircraft"], r["cell"], r["rate"]) == key and r.get("at_truth")]
        for k in sorted({k for r in rs for k in r}, key=lambda k: (k.startswith("tau"), k[:1], len(k), k)):
            v = [r[k] for r in rs if k in r]
            exact = np.array([x["exact"] for x in v])
            z = np.array([x["z"] for x in v])
            print(f"| {key[0]} | {key[1]} | {key[2]:g} Hz | {k} | {np.sqrt(np.mean(exact ** 2)):.1f} "
                  f"[{np.abs(exact).max():.1f}] | {np.mean([x['spread'] for x in v]):.1f} | {z.mean():+.2f} / "
                  f"{np.sqrt(np.mean(z ** 2)):.2f} | {len(v)} |")


def _wrong(named: list, effect: str | None) -> list:
    """The ``(axis, effect, lr)`` of ``named`` that are not the hidden ``effect`` (a servo delay on an axis whose
    hidden lag is named too is the lag's first step: module docstring)."""
    lagged = {a for a, e, _ in named if e == "servo_lag"} if effect == "servo_lag" else set()
    return [(a, e, lr) for a, e, lr in named if e != effect and not (e == "servo_delay" and a in lagged)]


def _table(rows, diagnose: bool, effect: str | None) -> None:
    keys = sorted({(r["aircraft"], r["cell"], r["rate"]) for r in rows}, key=str)
    print("\n| aircraft | cell | log rate | " + " | ".join(PARAMS) + " | hold fractions | fitted at |"
          + (" wrong diagnoses |" if diagnose else "") + (" hidden effect named |" if effect else ""))
    print("|---|---|---|" + "---|" * (len(PARAMS) + 2) + ("---|" if diagnose else "") + ("---|" if effect else ""))
    worst = {"gains": 0.0, "dampings": 0.0}
    for key in keys:
        rs = [r for r in rows if (r["aircraft"], r["cell"], r["rate"]) == key]
        ok = [r for r in rs if "ml" in r]
        failed = [r["error"] for r in rs if "error" in r]
        if ok:
            e = np.array([[r["ml"][k] for k in PARAMS] for r in ok])
            rms, top = np.sqrt(np.mean(e ** 2, axis=0)), np.abs(e).max(axis=0)
            worst["gains"] = max(worst["gains"], float(rms[:3].max()))
            worst["dampings"] = max(worst["dampings"], float(rms[3:].max()))
            cells = [f"{a:.1f} [{b:.1f}]" for a, b in zip(rms, top)]
            holds = np.array([r["hold"] for r in ok])
            hold = f"{holds.min():.2f}-{holds.max():.2f}"
        else:
            cells, hold = ["-"] * len(PARAMS), "-"
        rates = [key[2] / r.get("fit_every", 1) for r in rs]  # identification.fit_rate: a filtered gyro's log thinned
        fitted = ", ".join(f"{hz:g} Hz ({rates.count(hz)}/{len(rs)})" for hz in sorted(set(rates), reverse=True))
        text = f"| {key[0]} | {key[1]} | {key[2]:g} Hz | " + " | ".join(cells) + f" | {hold} | {fitted} |"
        if failed:
            text += f" refused {len(failed)}/{len(rs)}: {failed[0][:80]}"
        if diagnose:
            wrong = [r for r in ok if _wrong(r["named"], r["effect"])]
            what = "; ".join(f"{a} {e} {lr}" for r in wrong for a, e, lr in _wrong(r["named"], r["effect"]))
            text += f" {len(wrong)}/{len(ok)} {what} |"
            if any(r["effect"] for r in ok):
                hit = [r for r in ok if any(e == r["effect"] for _, e, _ in r["named"])]
                text += f" {len(hit)}/{len(ok)} |"
        print(text)
    print(f"\nWorst cell: gains {worst['gains']:.2f} % RMS, dampings {worst['dampings']:.2f} % RMS")
    for axis in sorted({axis for r in rows for axis in r.get("delays", {})}):
        pairs = np.array([r["delays"][axis] for r in rows if "ml" in r])
        err = 1000.0 * (pairs[:, 1] - pairs[:, 0])
        print(f"{axis} servo delay {1000 * pairs[0, 0]:g} ms: fitted {1000 * pairs[:, 1].min():.1f}-"
              f"{1000 * pairs[:, 1].max():.1f} ms, error RMS {np.sqrt(np.mean(err ** 2)):.1f} ms "
              f"over {len(pairs)} flights")
    _standard_error_line(rows)
    checked = [r["hold_check"] for r in rows if r.get("hold_check")]
    if checked:
        moved = [f"{c['decided']} -> {c['chosen']}" for c in checked if c["switched"]]
        print(f"Hold decided again in the closed loop's world on {len(checked)} of {len(rows)} flights; changed on "
              f"{len(moved)}" + (f" ({', '.join(sorted(set(moved)))})" if moved else ""))


def _timing_lines(rows) -> None:
    """``--timing``: per flight, the servo delay and lag each axis kept [ms] and what the check made of a timing
    the search found (:mod:`identification.likelihood.delay_check`)."""
    print("\nServo timing kept per flight (delay / lag, ms), and the check's verdict on a timing found:")
    for r in sorted((r for r in rows if "timing" in r), key=lambda r: (r["aircraft"], r["cell"], r["rate"], r["seed"])):
        kept = ", ".join(f"{a} {1000 * d:.1f} / {1000 * g:.1f}" for a, (d, g) in r["timing"].items())
        print(f"- {r['aircraft']} {r['cell']} {r['rate']:g} Hz seed {r['seed']}: {kept}"
              + "".join(f"\n  {line}" for line in r["timing_checks"]))


def _standard_error_line(rows) -> None:
    """Whether the standard errors the model reports hold the errors: z = (fitted - truth) / standard error over
    every flight (RMS about 1 and |z| > 2 on about 5 % where they do; a bias shows as a mean away from 0)."""
    fitted = [r for r in rows if r.get("z")]
    if not fitted:
        return
    cols = []
    for k in PARAMS + tuple(sorted({k for r in fitted for k in r["z"] if k.startswith("tau_")})):
        z = np.array([r["z"][k] for r in fitted if k in r["z"]])
        se = np.median([r["se"][k] for r in fitted if k in r["se"]])
        cols.append(f"{k} {np.sqrt(np.mean(z ** 2)):.2f} ({np.mean(z):+.2f}, SE {se:.1f} %)")
    every = np.array([z for r in fitted for z in r["z"].values()])
    doubt = sum(bool(r.get("hold_doubt")) for r in fitted)
    print(f"Errors over the model's standard errors (the hold's doubt in them where the data leave one: {doubt} "
          f"flights), z RMS (mean, median standard error) over {len(fitted)} flights: "
          + ", ".join(cols) + f"; |z| > 2 on {100 * np.mean(np.abs(every) > 2):.1f} % of {every.size}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--aircraft", nargs="+", default=list(AIRCRAFT), choices=["paper", *AIRCRAFT])
    ap.add_argument("--cells", nargs="+", default=["independent", "held-sticks-pd"])
    ap.add_argument("--rates", nargs="+", type=float, default=[100.0], help="log rates [Hz]")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--diagnose", action="store_true", help="also run the likelihood diagnosis (about 10 s a flight)")
    ap.add_argument("--effect", default=None, help="hide this effect of the catalogue in every truth")
    ap.add_argument("--set", type=config_field, nargs="*", default=[], metavar="FIELD=VALUE",
                    help="FlightConfig fields changed in every cell, e.g. held_sticks=True command_noise=0.01")
    ap.add_argument("--timing", action="store_true",
                    help="print the servo delay and lag each flight's axes kept, and the check's verdict on them")
    ap.add_argument("--servo-delay", type=servo_delay, nargs="*", default=[], metavar="AXIS=SECONDS",
                    help="a true servo delay in every truth, e.g. pitch=0.01")
    ap.add_argument("--closed-loop", choices=("auto", "off"), default="auto",
                    help="the closed-loop check as heli identify runs it ('auto', default) or none ('off')")
    ap.add_argument("--fit-rate", choices=("auto", "log"), default="auto",
                    help="the rate each log is fitted at, as heli identify's --fit-rate: chosen by the data ('auto', "
                    "default) or the log's own ('log')")
    ap.add_argument("--at-truth", action="store_true",
                    help="also fly the check at the truth's values (the exact correction and the spread there)")
    ap.add_argument("--unstated-filter", action="store_true",
                    help="the logs do not state their gyro filter's corner (a CSV without --gyro-filter; an "
                    "ArduPilot log states INS_GYRO_FILTER)")
    args = ap.parse_args(argv)
    from identification.bench.cells import BENCH_CELLS
    from identification.bench.flight_config import EFFECTS

    unknown = [c for c in args.cells if c not in BENCH_CELLS]
    if unknown:
        raise SystemExit(f"unknown cells {unknown}; known: {', '.join(BENCH_CELLS)}")
    if args.effect is not None and args.effect not in EFFECTS:
        raise SystemExit(f"unknown effect {args.effect!r}; known: {', '.join(EFFECTS)}")
    check = None if args.closed_loop == "off" else args.closed_loop
    settings, delays = tuple(args.set), tuple(args.servo_delay)
    for cell in args.cells:  # a study of a setting the flight does not read would report the cell's own figures
        inert = replace(BENCH_CELLS[cell], **dict(settings)).inert(dict(settings))
        if inert:
            raise SystemExit(f"--set {', '.join(inert)}: cell {cell!r} does not read it "
                             f"({'; '.join(inert.values())})")
    if args.at_truth and check is None:
        raise SystemExit("--at-truth flies the closed-loop check again: it needs --closed-loop auto")
    jobs = [(a, c, r, s, args.duration, args.diagnose, args.effect, check, settings, delays, args.at_truth,
             args.fit_rate, args.unstated_filter)
            for a in args.aircraft for c in args.cells for r in args.rates
            for s in range(args.first_seed, args.first_seed + args.seeds)]
    from tqdm import tqdm

    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as pool:
            rows = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight"))
    else:
        rows = [_one(j) for j in tqdm(jobs, desc="flights", unit="flight")]
    print(f"\nRelative error (%) against the truth, RMS over {args.seeds} seeds [worst |error|], "
          f"{args.duration:g} s flights, defaults of heli identify. Command: python scripts/aircraft_generalisation.py "
          f"--seeds {args.seeds} --first-seed {args.first_seed} --duration {args.duration:g} "
          f"--aircraft {' '.join(args.aircraft)} "
          f"--cells {' '.join(args.cells)} --rates {' '.join(f'{r:g}' for r in args.rates)}"
          + (" --diagnose" if args.diagnose else "") + (f" --effect {args.effect}" if args.effect else "")
          + (" --set " + " ".join(shlex.quote(f"{k}={v!r}") for k, v in settings) if settings else "")
          + (" --servo-delay " + " ".join(f"{a}={t:g}" for a, t in delays) if delays else "")
          + ("" if check else " --closed-loop off") + (" --at-truth" if args.at_truth else "")
          + (" --fit-rate log" if args.fit_rate == "log" else "")
          + (" --unstated-filter" if args.unstated_filter else "") + (" --timing" if args.timing else ""))
    _table(rows, args.diagnose, args.effect)
    _truth_table(rows)
    if args.timing:
        _timing_lines(rows)


if __name__ == "__main__":
    main()
