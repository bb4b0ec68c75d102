"""End to end: does the sweep's prediction on an identified model hold for flights of the truth in its own gusts?

Per bench cell and seed: a 300 s flight of the cell (:data:`identification.bench.cells.BENCH_CELLS`; the paper's
aircraft with a 40/40/25 ms servo delay); ``heli identify`` (maximum likelihood, ``--delay auto``, the
sensors and the library's winds) into a scratch folder; then per axis three PD pairs — the design of
``heli design`` (45°) scaled by 0.5, 1 and 2 — predicted by ``heli sweep``'s defaults on the identified
model (its library tiled by 60 s windows, its sensors; each p90 with its 90 % interval,
:mod:`controllers.sweep_interval`) twice: replaying the library as ``heli identify`` writes it (a draw from
the smoother's posterior, :mod:`identification.disturbance.wind_posterior`) and replaying the smoother's mean in its
place (what it wrote before issue #30). The truth is then flown (RK4, the flight generator's sensors, PD
autopilot at 100 Hz with the identified trim) in **fresh gusts of the cell's own generator**
(:func:`identification.bench.synthetic.gust_trace` at the cell's level and spectrum, new seeds): weather the
identification never saw, from another generator than its Gauss-Markov gust model, ``--flights`` flights of
``--flight-duration`` s per pair.

Prints per pair the predicted p90 |attitude error| (mean and draw), the draw's 90 % interval, the flown
p90 with its own 90 % interval (the same method over 10 s blocks of the flights), and per cell and over
all: mean and worst |predicted / flown - 1| (target: within 15 %), the share of pairs whose predicted
interval contains the flown p90 (target: >= 85 %) and the share whose two intervals overlap.

Usage::

    python scripts/end_to_end_prediction.py [--seeds 3] [--cells independent ...] [--flights 20] [--workers 2]
"""

from __future__ import annotations

import argparse
import os
import tempfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

FACTORS = (0.5, 1.0, 2.0)
DEFAULT_CELLS = ("independent", "broadband-pd-2x", "dryden-2Hz-pd", "held-sticks-pd")
_DEG = 180.0 / np.pi


def cell_gusts(cfg, truth, env_model, n_flights: int, steps: int, dt: float, seed: int):
    """What ``n_flights`` flights of the truth hold over each period: gusts of the cell's generator at its level
    (torque ``k·u_d`` with the truth's gains), the cell's wandering collective and sensors; the trim the
    autopilot adds is the identified model's (:class:`controllers.replay.LoopInputs`)."""
    from controllers.replay import LoopInputs
    from heli_core.physics import trim_sticks
    from identification.bench.synthetic import coloured_noise, gust_trace, sensor_errors

    rng = np.random.default_rng([seed, 0xF17])
    level = np.broadcast_to(np.asarray(cfg.wind_level, dtype=float), (3,))
    gust, col = np.empty((3, steps, n_flights)), np.empty((steps, n_flights))
    gyro, attn = np.zeros((3, steps, n_flights)), np.zeros((3, steps, n_flights))
    t = np.arange(steps) * dt
    for f in range(n_flights):
        for i in range(3):
            gust[i, :, f] = gust_trace(rng, steps, 1.0 / dt, cfg, level[i] / 1.6449)
        col[:, f] = np.clip(cfg.collective_trim + coloured_noise(rng, steps, 1.0 / dt, 0.05, cfg.collective_wander),
                            -1.0, 1.0)
        terms, attn[:, :, f] = sensor_errors(rng, cfg, t)
        gyro[:, :, f] = sum(terms[1:], terms[0])
    trim = np.array(trim_sticks(env_model.params, col))
    return LoopInputs(trim, col, truth.control_gains[:, None, None] * gust, att_noise=attn, rate_noise=gyro)


def fly_truth(truth, inputs, axis: int, pairs, nominal, signs, dt: float):
    """|attitude error| [deg] of the truth under each pair, shape (pairs, steps, flights)."""
    from controllers.replay import Autopilot, fly, rk4_step
    from identification.bench.flight_config import FlightConfig

    kp, kd = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    autopilot = Autopilot(axis, kp, kd, nominal, signs)
    out = np.empty((len(pairs), inputs.steps, inputs.windows), dtype=np.float32)
    for sl, rec in fly(rk4_step(truth, dt, FlightConfig().substeps), inputs, autopilot, 4096, False, "flights"):
        out[sl] = np.abs(rec.att) * _DEG
    return out


def flown_p90(errors: np.ndarray, dt: float) -> tuple:
    """The pooled p90 of one pair's flights (steps, flights) and its 90 % interval over 10 s blocks of each."""
    from controllers.sweep_interval import BLOCK_SECONDS, quantiles_at, trace_blocks, woodruff_levels

    steps, F = errors.shape
    blocks, adjacent = trace_blocks([(f, 0) for f in range(F)], steps, 1, 1.0 / dt, BLOCK_SECONDS)
    values = np.ascontiguousarray(errors).reshape(1, -1)  # sample k * F + f, as the sweep's layout
    p90 = float(np.quantile(values, 0.9))
    lo, hi = quantiles_at(values.copy(), woodruff_levels(values, blocks.ravel(), adjacent))[0]
    return p90, float(lo), float(hi)


def one_job(job) -> list:
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _one_job(*job)


def _one_job(cell: str, seed: int, duration: float, n_flights: int, flight_duration: float) -> list:
    from controllers.pd import design_gains
    from controllers.sweep import sweep_pairs
    from heli_env.env_model import load_env_model
    from identification.bench.cells import BENCH_CELLS
    from identification.workflows.identify import identify_and_report
    from identification.bench.synthetic import simulate_flight

    cfg = BENCH_CELLS[cell]
    sim = simulate_flight(duration, seed=seed, config=cfg, effects=("servo_delay",), effect_scale=0.5)
    with tempfile.TemporaryDirectory() as tmp:
        run = identify_and_report([sim.flight], Path(tmp) / "model", identifier_kwargs={"delay": "auto"},
                                  plots=False)
        model = load_env_model(Path(tmp) / "model")
    profile = run.disturbances[0]
    assert np.allclose(model.ud, profile.trace), "the library holds the profile's trace"
    models = {"draw": model, "mean": replace(model, ud=np.array(profile.trace_mean))}
    gains = design_gains(model.params)
    dt = 0.01
    steps = int(round(flight_duration / dt))
    inputs = cell_gusts(cfg, sim.truth, model, n_flights, steps, dt, seed)
    rows = []
    for a, axis in enumerate(("roll", "pitch", "yaw")):
        pairs = [(f * gains.kp[a], f * gains.kd[a]) for f in FACTORS]
        pred = {k: sweep_pairs(m, pairs, axis=axis, progress=False, seed=seed) for k, m in models.items()}
        nominal = np.asarray(pred["draw"].settings["nominal_gains"])
        flown = fly_truth(sim.truth, inputs, a, pairs, nominal, np.sign(model.params.control_gains), dt)
        for j, (kp, kd) in enumerate(pairs):
            r, m = pred["draw"].row(j), pred["mean"].row(j)
            if r["status"] != "stable" or np.max(flown[j]) > 60.0:
                continue
            rows.append({"cell": cell, "seed": seed, "axis": axis, "factor": FACTORS[j], "kp": kp, "kd": kd,
                         "pred_mean": m["att_p90_deg"], "pred": r["att_p90_deg"], "lo": r["att_p90_lo_deg"],
                         "hi": r["att_p90_hi_deg"], "flown": flown_p90(flown[j], dt)})
    return rows


def summary(rows: list, label: str) -> str:
    """One line per cell: mean and worst error of both predictions, containment and overlap of the draw's."""
    err_d = np.array([r["pred"] / r["flown"][0] - 1.0 for r in rows])
    err_m = np.array([r["pred_mean"] / r["flown"][0] - 1.0 for r in rows])
    inside = np.mean([r["lo"] <= r["flown"][0] <= r["hi"] for r in rows])
    overlap = np.mean([r["lo"] <= r["flown"][2] and r["flown"][1] <= r["hi"] for r in rows])
    return (f"| {label} | {len(rows)} | {100 * err_m.mean():+.1f} % / {100 * np.abs(err_m).mean():.1f} % / "
            f"{100 * err_m[np.argmax(np.abs(err_m))]:+.1f} % | {100 * err_d.mean():+.1f} % / "
            f"{100 * np.abs(err_d).mean():.1f} % / {100 * err_d[np.argmax(np.abs(err_d))]:+.1f} % | "
            f"{100 * inside:.0f} % | {100 * overlap:.0f} % |")


def main(argv=None):
    from identification.bench.cells import BENCH_CELLS

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--duration", type=float, default=300.0, help="identification flight [s]")
    ap.add_argument("--cells", nargs="+", default=list(DEFAULT_CELLS), choices=list(BENCH_CELLS), metavar="CELL")
    ap.add_argument("--flights", type=int, default=20, help="flights of the truth per pair")
    ap.add_argument("--flight-duration", type=float, default=60.0, help="seconds per flight")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args(argv)
    jobs = [(c, s, args.duration, args.flights, args.flight_duration) for c in args.cells
            for s in range(1, args.seeds + 1)]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = [r for rs in pool.map(one_job, jobs) for r in rs]
    print(f"Command: python scripts/end_to_end_prediction.py --seeds {args.seeds} --duration {args.duration:g} "
          f"--cells {' '.join(args.cells)} --flights {args.flights} --flight-duration {args.flight_duration:g}\n")
    print("| cell | seed | axis | × design | predicted p90, mean [deg] | predicted p90, draw [90 % interval] | "
          "flown p90 [90 % interval] | draw / flown |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        f, flo, fhi = r["flown"]
        print(f"| {r['cell']} | {r['seed']} | {r['axis']} | {r['factor']:g} | {r['pred_mean']:.4f} | {r['pred']:.4f} "
              f"[{r['lo']:.4f}, {r['hi']:.4f}] | {f:.4f} [{flo:.4f}, {fhi:.4f}] | {r['pred'] / f:.3f} |")
    print("\npredicted / flown - 1: mean / mean |.| / worst (target: within 15 %); the draw's 90 % interval holding "
          "the flown p90 (target: >= 85 %), and overlapping the flown p90's own interval\n")
    print("| cell | pairs | smoother mean | posterior draw | flown p90 inside | intervals overlap |")
    print("|---|---|---|---|---|---|")
    for c in args.cells:
        print(summary([r for r in rows if r["cell"] == c], c))
    print(summary(rows, "all"))


if __name__ == "__main__":
    main()
