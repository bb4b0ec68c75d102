"""``heli check``: verify a model directory, and repair what an interrupted write left there."""

from __future__ import annotations


def register(sub):
    p = sub.add_parser(
        "check",
        help="verify a model folder; finish or roll back an interrupted write",
        description="Verify MODEL_DIR as one state: model.json, every version of the disturbance library (manifests "
        "and the SHA-256 of every trace), and what a killed command can leave behind. First repairs what can be "
        "repaired: an interrupted identify, refresh or diagnose is finished (it had committed) or rolled back (it "
        "had not), temporary files and trace files no manifest lists are deleted, an HTML report that no longer "
        "shows its Markdown report or figures (report.html after a refresh by an older heli) is written again. "
        "A corrupt model or library is named, not changed. Exit status 0 when the folder is consistent, 2 when a "
        "problem remains.",
    )
    p.add_argument("model_dir", metavar="MODEL_DIR", help="directory written by 'heli identify'")
    p.add_argument("--no-repair", action="store_true", help="only report; change nothing")
    p.add_argument("--no-wait", action="store_true",
                   help="refuse at once when another command is writing MODEL_DIR (default: wait for it)")
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from model_store.errors import ModelDirError, ModelFileError
    from model_store.model_dir import ModelDir

    if Path(args.model_dir).is_file():
        return _check_file(Path(args.model_dir))
    folder = ModelDir(args.model_dir, notify=lambda message: None)
    if not folder.root.is_dir():
        raise ModelFileError(f"model directory {str(Path(args.model_dir))!r} does not exist")
    if not args.no_repair:
        for line in folder.repair(wait=not args.no_wait):
            print(f"repaired: {line}")
    problems = folder.verify()
    problems += _html_reports(folder.root, repair=not args.no_repair)
    for line in problems:
        print(f"problem: {line}")
    if problems:
        raise ModelDirError(f"{folder.root}: {len(problems)} problem(s)"
                            + (" left after repair" if not args.no_repair else "; 'heli check' without --no-repair "
                               "repairs what can be repaired"))
    state = folder.load()
    history = folder.root / "history"
    print(f"{folder.root}: consistent: model.json SHA-256 {state.model_sha256[:12]}…, disturbance library "
          + (f"version {state.library_version} ({len(state.traces)} traces)" if state.library_version else "none")
          + f", {len(list(history.iterdir())) if history.is_dir() else 0} file(s) in history/")
    return 0


def _check_file(path) -> int:
    """A file given where a model folder is expected: a canonical CSV flight is checked as a flight (read and
    validated as ``heli identify`` reads it); anything else is one line saying what was expected and what came."""
    from identification.errors import FlightLogError
    from model_store.errors import ModelFileError
    from identification.io import detect_format, read_flight

    expected = f"expected a model folder (written by 'heli identify'), got the file {str(path)!r}"
    if path.name == "model.json":
        raise ModelFileError(f"{expected}, a model file: check the folder that holds it: heli check {path.parent}")
    try:
        fmt = detect_format(path)
    except FlightLogError as e:
        raise ModelFileError(f"{expected}, which is neither a flight nor a log ({e})") from e
    if fmt != "csv":
        raise ModelFileError(f"{expected}, a {fmt} log: import it first (heli import {path} --out FLIGHT.csv)")
    try:
        flight = read_flight(path)
    except FlightLogError as e:
        raise FlightLogError(f"{expected}, a CSV that is not a valid flight: "
                             + (f"{type(e).__name__}: " if type(e) is not FlightLogError else "") + str(e)) from e
    print(f"{path}: a valid flight, not a model folder: {flight.n} samples at {flight.sample_rate:.1f} Hz, "
          f"{flight.time[0]:.3f}..{flight.time[-1]:.3f} s ({flight.duration:.1f} s); 'heli check' verifies a model "
          "folder written by 'heli identify'")
    return 0


def _html_reports(root, repair: bool) -> list[str]:
    """Problems of the folder's HTML reports (:func:`.html_report.stale_reasons`); rewritten first when ``repair``."""
    from .html_report import rewrite_stale_html, stale_reasons

    if repair:
        for line in rewrite_stale_html(root):
            print(f"repaired: {line}")
    return [f"{page.name} does not show the current report: " + "; ".join(reasons)
            for page in sorted(root.glob("*.html")) if page.with_suffix(".md").is_file()
            for reasons in [stale_reasons(page)] if reasons]
