"""A CSV whose clock is not uniform: what reading it on its clock does to the identified model.

Per bench cell and seed one flight is flown at 2 kHz (the "continuous" truth) and logged at 100 Hz as other
tools write CSV files, each file read by ``identification.io.read_log`` (:mod:`identification.io.csv_timing`)
and fitted as ``heli identify`` fits by default (:class:`MaximumLikelihoodIdentifier` with ``CLI_TIMING``):

* ``clean``: every 20th sample, stamped on time (the reference);
* ``jitter J ms``: samples taken up to J ms off the 100 Hz clock (uniform), stamped when taken (to 1 ms as
  most loggers do: the stamps then are no rounding of the clock); read as ``read_log`` reads them now, each row
  at its slot of the clock, and **interpolated** (the rows interpolated from their stamps onto the clock: what
  the reader did first, kept here as the alternative it was measured against);
* ``drop P %``: a random P % of the clean samples missing, at most three in a row (a longer hole is a stop of
  the logging, refused; before, any missing sample was refused: "sampling gap"); the missing ones interpolated;
* ``400 Hz in ms``: samples every 2.5 ms stamped in whole milliseconds (2 and 3 ms apart), read on the clock
  they were rounded from, and fitted at 400 Hz as they come.

Prints per cell and condition the RMS [worst] relative error in % of the gains (k2, k6, k10) and dampings (k3,
k7, k11) over the seeds, worst parameter first, and the change against ``clean`` on the same flights.

    python scripts/csv_clock_study.py [--seeds 3] [--cells independent dryden-2Hz-pd broadband-pd-2x]
        [--jitter-ms 1 2 2.5] [--drop 2 5] [--gyro-noise 0.002] [--log-rate 100] [--workers 2] [--duration 300]
"""

from __future__ import annotations

import argparse
import shlex
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

GAINS = ("k2", "k6", "k10")
DAMPINGS = ("k3", "k7", "k11")
FINE_HZ = 2000.0
LOG_HZ = 100.0
"""Hz: the log's rate (``--log-rate``)."""


def _rows(flight, index):
    """Rows (time, then the canonical columns in order) of the fine flight at sample indices ``index``."""
    return np.column_stack([flight.time[index], *flight.rates[:, index], *flight.attitude[:, index],
                            *flight.sticks[:, index]])


def _files(sim, seed: int, jitters, drops, folder: Path, log_hz: float = LOG_HZ) -> dict:
    """The conditions' CSV files of one fine flight logged at ``log_hz``: name -> path."""
    from identification.flight import CSV_COLUMNS
    from identification.io.csv_timing import interpolated

    rng = np.random.default_rng(10_000 + seed)
    step = int(FINE_HZ / log_hz)
    on_time = np.arange(0, sim.flight.n, step)
    files = {}

    def write(name, rows):
        path = folder / f"{name.replace(' ', '_')}_{seed}.csv"
        np.savetxt(path, rows, delimiter=",", header=",".join(CSV_COLUMNS), comments="", fmt="%.10g")
        files[name] = path

    write("clean", _rows(sim.flight, on_time))
    for j in jitters:
        shift = np.rint(rng.uniform(-j, j, on_time.size) * 1e-3 * FINE_HZ).astype(int)
        taken = np.clip(on_time + shift, 0, sim.flight.n - 1)
        taken[[0, -1]] = on_time[[0, -1]]
        taken = np.maximum.accumulate(taken)
        keep = np.concatenate(([True], np.diff(taken) > 0))
        rows = _rows(sim.flight, taken[keep])
        rows[:, 0] = np.round(rows[:, 0], 3)
        write(f"jitter {j:g} ms", rows)
        grid = sim.flight.time[on_time]
        stamps = rows[:, 0]
        write(f"jitter {j:g} ms interpolated", np.column_stack([grid, *(
            interpolated(grid, stamps, c, angle=4 <= i < 7) for i, c in enumerate(rows[:, 1:].T, start=1))]))
    for p in drops:
        keep = rng.random(on_time.size) >= p / 100.0
        run = np.zeros(on_time.size, int)
        for i in range(1, on_time.size):  # at most three missing in a row
            run[i] = 0 if keep[i] else run[i - 1] + 1
        keep |= run > 3
        keep[[0, -1]] = True
        write(f"drop {p:g} %", _rows(sim.flight, on_time[keep]))
    quarter = np.arange(0, sim.flight.n, int(FINE_HZ / 400.0))
    rows = _rows(sim.flight, quarter)
    rows[:, 0] = np.floor(rows[:, 0] * 1e3 + 1e-9) / 1e3
    write("400 Hz in ms", rows)
    return files


def _one(job):
    """Fly one (cell, seed) at 2 kHz, write its conditions' files, fit each; relative errors in %."""
    from threadpoolctl import threadpool_limits

    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.io import read_log
    from identification.likelihood.estimator import CLI_TIMING, MaximumLikelihoodIdentifier

    cell, seed, duration, jitters, drops, gyro, log_hz = job
    with threadpool_limits(limits=1, user_api="blas"), tempfile.TemporaryDirectory() as tmp:
        config = replace(BENCH_CELLS[cell], duration=duration, sample_rate=FINE_HZ)
        if gyro is not None:
            config = replace(config, gyro_noise=gyro)
        sim = simulate_flight(duration, seed=seed, config=config)
        truth = sim.truth.values()
        out = {"cell": cell, "seed": seed, "errors": {}}
        for name, path in _files(sim, seed, jitters, drops, Path(tmp), log_hz).items():
            try:
                flight = read_log(path)
                ml = MaximumLikelihoodIdentifier(**CLI_TIMING, closed_loop="auto").fit(flight)
            except Exception as exc:  # a refusal is a finding here
                out["errors"][name] = f"{type(exc).__name__}: {exc}"
                continue
            v = ml.params_.values()
            out[name] = {k: 100.0 * (v[k] - truth[k]) / truth[k] for k in GAINS + DAMPINGS}
    return out


def rms_line(rows, name: str, keys) -> str:
    """``RMS (worst parameter) [worst flight]`` of the relative errors ``row[name][key]`` [%] over ``rows``
    (those that hold ``name``: the others were refused), or "refused"."""
    got = [r for r in rows if name in r]
    if not got:
        return "refused"
    rms = {k: float(np.sqrt(np.mean([r[name][k] ** 2 for r in got]))) for k in keys}
    worst_key = max(rms, key=rms.get)
    return f"{rms[worst_key]:.1f} ({worst_key}) [{max(abs(r[name][k]) for r in got for k in keys):.1f}]"


def _cell_line(rows, name: str, keys) -> str:
    """:func:`rms_line`, and the RMS change against clean."""
    got = [r for r in rows if name in r and "clean" in r]
    if not got:
        return rms_line(rows, name, keys)
    change = max(float(np.sqrt(np.mean([(r[name][k] - r["clean"][k]) ** 2 for r in got]))) for k in keys)
    return f"{rms_line(rows, name, keys)}; vs clean {change:.2f}"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", nargs="+", default=["independent", "dryden-2Hz-pd", "broadband-pd-2x"])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--jitter-ms", nargs="+", type=float, default=[1.0, 2.0, 2.5])
    ap.add_argument("--drop", nargs="+", type=float, default=[2.0, 5.0], help="missing samples in %%")
    ap.add_argument("--gyro-noise", type=float, default=None, help="the gyro's white noise [rad/s] (default the "
                    "cell's; the flight's samples are 2 kHz, each logged sample one of them)")
    ap.add_argument("--log-rate", type=float, default=LOG_HZ, help="Hz: the files' rate (2000 / a whole number)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    from tqdm import tqdm

    jobs = [(c, s, args.duration, tuple(args.jitter_ms), tuple(args.drop), args.gyro_noise, args.log_rate)
            for c in args.cells for s in range(args.first_seed, args.first_seed + args.seeds)]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(tqdm(pool.map(_one, jobs), total=len(jobs), desc="flights", unit="flight"))
    names = ["clean", *(n for j in args.jitter_ms for n in (f"jitter {j:g} ms", f"jitter {j:g} ms interpolated")),
             *(f"drop {p:g} %" for p in args.drop), "400 Hz in ms"]
    print(f"\n`python scripts/csv_clock_study.py {shlex.join(sys.argv[1:])}`\n")
    print("| cell | file | gains: RMS % (worst) [worst flight]; RMS change vs clean | dampings: the same |")
    print("|---|---|---|---|")
    for cell in args.cells:
        got = [r for r in rows if r["cell"] == cell]
        for name in names:
            print(f"| {cell} | {name} | {_cell_line(got, name, GAINS)} | {_cell_line(got, name, DAMPINGS)} |")
    for r in rows:
        for name, error in r["errors"].items():
            print(f"refused: {r['cell']} seed {r['seed']} {name}: {error}")


if __name__ == "__main__":
    main()
