"""Kill real ``heli refresh`` and ``heli identify`` commands at random moments; run many writers at once.

The long version of ``tests/test_model_store.py`` (issue 15's targets: 0 stuck or inconsistent folders over
>= 200 random kills and 20 concurrent writers, every replaced model in ``history/``)::

    python scripts/fault_injection.py                      # 200 kills, 20 concurrent writers
    python scripts/fault_injection.py --kills 40 --writers 20 --jobs 2

Each kill runs a real command in a subprocess on a model folder (identified by the integral method from
30 s synthetic flights, so that a command lasts seconds) and stops it with SIGKILL: half of the kills after a
random delay over the command's whole run, half at a random file event of its write (``HELI_FAULT_AFTER``, which
SIGKILLs the process there: the moments a delay rarely hits). Then, with nobody writing:

* the folder must read as the state before or after the command (model and library as one; the env loads it);
* the command run again must succeed (after a kill before its commit), or be refused as a duplicate flight
  (after its commit: the refresh is done); ``heli check`` must then find nothing to repair.

A folder is *inconsistent* when it reads as neither state, *stuck* when the rerun fails otherwise or a problem
remains. Concurrent writers: ``--writers`` refreshes with distinct new flights on one folder at once, then as
many identifies into one folder: all must exit 0, every refresh must be in the chain of ``refresh`` records and
its trace in the library, every replaced model in ``history/``. Prints the tables; exit status 1 when a target
is missed.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DURATION = 30.0


def heli(*args, env=None) -> list:
    exe = shutil.which("heli")
    return ([exe] if exe else [sys.executable, "-m", "heli_cli.main"]) + [str(a) for a in args]


def run_env(**extra) -> dict:
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    env.pop("HELI_FAULT_AFTER", None)
    env.update({k: str(v) for k, v in extra.items()})
    return env


def make_flights(folder: Path, n: int) -> list[Path]:
    """``n`` synthetic flights that ``heli identify --method integral`` identifies (a 30 s flight can be too
    short: its model may diverge, a failure of the input that this script is not about)."""
    from identification.errors import IdentifiabilityError
    from identification.io import read_flight
    from identification.workflows.identify import identify_and_report
    from identification.bench.synthetic import simulate_flight

    paths, seed = [], 1000
    while len(paths) < n:
        path = folder / f"f{seed:04d}.csv"
        simulate_flight(duration=DURATION, seed=seed).save(path)
        seed += 1
        try:
            identify_and_report([read_flight(path)], folder / "screen", method="integral", plots=False,
                                progress=False)
        except IdentifiabilityError:
            path.unlink()
            continue
        paths.append(path)
    shutil.rmtree(folder / "screen", ignore_errors=True)
    return paths


def identify_cmd(flight: Path, out: Path) -> list:
    return heli("identify", flight, "--out", out, "--method", "integral", "--no-plots", "-q")


def refresh_cmd(out: Path, flight: Path) -> list:
    return heli("refresh", out, flight, "--bootstrap", 4, "--no-plots", "-q")


def snapshot(out: Path):
    """(model SHA-256, library version, trace sources) as a reader sees them, or the error it gets."""
    from heli_env import load_env_model
    from model_store import ModelDir

    state = ModelDir(out, notify=lambda m: None).load()
    env = load_env_model(out)
    if env.library_version != state.library_version:
        raise RuntimeError(f"env reads library version {env.library_version}, ModelDir {state.library_version}")
    return state.model_sha256, state.library_version, [(e.get("source") or {}).get("name") for e in state.entries]


def kill_once(command: str, out: Path, flight: Path, rng: random.Random, duration: float) -> dict:
    """One killed command on ``out``; returns the row of the table."""
    from model_store import ModelDir

    before = snapshot(out)
    cmd = refresh_cmd(out, flight) if command == "refresh" else identify_cmd(flight, out)
    by_event = rng.random() < 0.5
    env = run_env(**({"HELI_FAULT_AFTER": rng.randint(1, 16)} if by_event else {}))
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    if not by_event:
        try:
            proc.wait(timeout=rng.uniform(0.2, 1.05) * duration)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc.stderr.close()
    killed = proc.returncode == -signal.SIGKILL
    row = {"command": command, "killed": killed, "how": "event" if by_event else "delay"}
    try:
        after = snapshot(out)
    except Exception as e:  # noqa: BLE001 - the folder does not read: counted
        row.update(state="unreadable", error=f"{type(e).__name__}: {e}")
        return row
    name = flight.name
    if after == before:
        row["state"] = "old"
    elif after[1] == before[1] + 1 and after[2][-1] == name and after[2][:-1] == before[2]:
        row["state"] = "new"
    elif command == "identify" and after[1] == before[1] and name in before[2]:
        row["state"] = "new"  # the same flight identified again: a new model, its trace already there
    else:
        row.update(state="inconsistent", error=f"before {before[1:]}, after {after[1:]}")
        return row
    rerun = subprocess.run(cmd, env=run_env(), capture_output=True, text=True)
    duplicate = "DuplicateFlightError" in rerun.stderr
    row["rerun"] = "ok" if rerun.returncode == 0 else ("duplicate" if duplicate else "failed")
    if row["rerun"] == "failed" or (row["rerun"] == "duplicate" and row["state"] != "new"):
        row["error"] = rerun.stderr.strip().splitlines()[-1:] if rerun.stderr else rerun.returncode
        row["stuck"] = True
    problems = ModelDir(out, notify=lambda m: None).verify()
    if problems:
        row["stuck"], row["error"] = True, problems
    return row


def kill_series(worker: int, kills: int, base: Path, flights: list[Path], work: Path, seed: int,
                durations: dict) -> list[dict]:
    rng = random.Random(seed + worker)
    rows, out, unused = [], None, []
    for k in range(kills):
        if out is None or not unused:
            out = work / f"w{worker}-lineage{k}"
            shutil.copytree(base, out)
            unused = list(flights)
            rng.shuffle(unused)
        command = "refresh" if rng.random() < 0.6 else "identify"
        flight = unused[-1]
        row = kill_once(command, out, flight, rng, durations[command])
        if row.get("state") == "new" or row.get("rerun") == "ok":
            unused.pop()  # the flight is now part of this folder
        rows.append(row)
        if row.get("state") in ("inconsistent", "unreadable") or row.get("stuck"):
            print(f"  {out}: {row}", flush=True)
            out = None  # a fresh folder for what follows
    return rows


def _all_at_once(base: Path, out: Path, commands: list) -> tuple[list, list]:
    """A copy of ``base`` at ``out`` and ``commands`` run on it all at once: their exit codes and the tail
    of each failed one's error output."""
    shutil.copytree(base, out)
    procs = [subprocess.Popen(cmd, env=run_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
             for cmd in commands]
    codes = [p.wait() for p in procs]
    errors = [p.stderr.read().strip()[-300:] for p, c in zip(procs, codes) if c != 0]
    for p in procs:
        p.stderr.close()
    return codes, errors


def concurrent_refreshes(base: Path, flights: list[Path], work: Path) -> dict:
    from model_store import ModelDir, load_model

    out = work / "concurrent-refresh"
    codes, errors = _all_at_once(base, out, [refresh_cmd(out, f) for f in flights])
    state = ModelDir(out, notify=lambda m: None).load()
    traced = {(e.get("source") or {}).get("name") for e in state.entries}
    # walk the chain of refresh records back through history/
    recorded, doc, seen_models = [], state.document, 0
    while doc.refresh:
        recorded += [s["file"] for s in doc.refresh["new_sources"]]
        kept = out / doc.refresh["previous_model"]["kept_as"]
        if not kept.is_file():
            break
        seen_models += 1
        doc = load_model(kept)[1]  # a model kept in history/: one file, not a folder
    names = [f.name for f in flights]
    return {"writers": len(flights), "exit 0": codes.count(0), "errors": errors,
            "traces in library": sum(n in traced for n in names),
            "refreshes recorded": sum(n in recorded for n in names),
            "replaced models in history": seen_models,
            "lost": len(names) - sum(n in recorded and n in traced for n in names),
            "problems": ModelDir(out, notify=lambda m: None).verify()}


def concurrent_identifies(base: Path, flights: list[Path], work: Path) -> dict:
    from model_store import ModelDir, load_model

    out = work / "concurrent-identify"
    codes, _ = _all_at_once(base, out, [identify_cmd(f, out) for f in flights])
    state = ModelDir(out, notify=lambda m: None).load()
    # each identify's model names its flight; every one but the current must be in history/
    models = {}
    for path in (out / "history").glob("model-*.json"):
        models[load_model(path)[1].sources[0].file] = path
    current = state.document.sources[0].file
    names = [f.name for f in flights]
    return {"writers": len(flights), "exit 0": codes.count(0),
            "models kept": sum(n in models or n == current for n in names),
            "replaced models missing from history": sum(n not in models for n in names if n != current),
            "library version": state.library_version, "traces": len(state.traces),
            "problems": ModelDir(out, notify=lambda m: None).verify()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kills", type=int, default=200, help="killed commands in all (default 200)")
    ap.add_argument("--writers", type=int, default=20, help="concurrent writers (default 20)")
    ap.add_argument("--jobs", type=int, default=2, help="kill series run side by side (default 2)")
    ap.add_argument("--flights", type=int, default=12, help="flights per lineage of a kill series (default 12)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", action="store_true", help="keep the work folder")
    args = ap.parse_args(argv)

    work = Path(tempfile.mkdtemp(prefix="heli-faults-"))
    t0 = time.monotonic()
    try:
        flights = make_flights(work, max(args.flights, args.writers) + 1)
        base = work / "base"
        subprocess.run(identify_cmd(flights[0], base), env=run_env(), check=True)
        pool = flights[1:]
        durations = {}
        for command in ("refresh", "identify"):  # how long one lasts, for the random delays
            probe = work / f"probe-{command}"
            shutil.copytree(base, probe)
            start = time.monotonic()
            cmd = refresh_cmd(probe, pool[0]) if command == "refresh" else identify_cmd(pool[0], probe)
            subprocess.run(cmd, env=run_env(), check=True, capture_output=True)
            durations[command] = time.monotonic() - start
        print(f"one command lasts: refresh {durations['refresh']:.1f} s, identify {durations['identify']:.1f} s")

        per = [args.kills // args.jobs + (1 if j < args.kills % args.jobs else 0) for j in range(args.jobs)]
        with ThreadPoolExecutor(args.jobs) as ex:
            series = list(ex.map(lambda j: kill_series(j, per[j], base, pool[:args.flights], work, args.seed,
                                                       durations), range(args.jobs)))
        rows = [r for s in series for r in s]
        print()
        print("| command | how | runs | killed | read as old | read as new | inconsistent | stuck |")
        print("|---|---|---|---|---|---|---|---|")
        bad = 0
        for command in ("refresh", "identify"):
            for how in ("delay", "event"):
                sel = [r for r in rows if r["command"] == command and r["how"] == how]
                inconsistent = sum(r["state"] in ("inconsistent", "unreadable") for r in sel)
                stuck = sum(bool(r.get("stuck")) for r in sel)
                bad += inconsistent + stuck
                print(f"| {command} | {how} | {len(sel)} | {sum(r['killed'] for r in sel)} "
                      f"| {sum(r['state'] == 'old' for r in sel)} | {sum(r['state'] == 'new' for r in sel)} "
                      f"| {inconsistent} | {stuck} |")
        killed = sum(r["killed"] for r in rows)
        print(f"\n{killed} SIGKILLs over {len(rows)} runs; stuck or inconsistent folders: {bad} (target 0)")

        writers = pool[:args.writers]
        ref = concurrent_refreshes(base, writers, work)
        ide = concurrent_identifies(base, writers, work)
        print("\nconcurrent refreshes:", json.dumps(ref, indent=None))
        print("concurrent identifies:", json.dumps(ide, indent=None))
        bad += ref["lost"] + (ref["writers"] - ref["exit 0"]) + len(ref["problems"])
        bad += ide["replaced models missing from history"] + (ide["writers"] - ide["exit 0"]) + len(ide["problems"])
        print(f"\nlost refreshes: {ref['lost']} of {ref['writers']}; replaced models missing from history: "
              f"{ide['replaced models missing from history']} of {ide['writers'] - 1}; "
              f"{time.monotonic() - t0:.0f} s in all")
        return 1 if bad else 0
    finally:
        if args.keep:
            print(f"work folder kept: {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
