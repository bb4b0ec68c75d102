"""``heli check``: verify a model directory, and repair what an interrupted write left there."""

from __future__ import annotations


def register(sub):
    p = sub.add_parser(
        "check",
        help="verify a model folder; finish or roll back an interrupted write",
        description="Verify MODEL_DIR as one state: model.json, every version of the disturbance library (manifests "
        "and the SHA-256 of every trace), and what a killed command can leave behind. First repairs what can be "
        "repaired: an interrupted identify, refresh or diagnose is finished (it had committed) or rolled back (it "
        "had not), temporary files and trace files no manifest lists are deleted. A corrupt model or library is "
        "named, not changed. Exit status 0 when the folder is consistent, 2 when a problem remains.",
    )
    p.add_argument("model_dir", metavar="MODEL_DIR", help="directory written by 'heli identify'")
    p.add_argument("--no-repair", action="store_true", help="only report; change nothing")
    p.add_argument("--no-wait", action="store_true",
                   help="refuse at once when another command is writing MODEL_DIR (default: wait for it)")
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from identification.errors import ModelDirError, ModelFileError
    from model_store.model_dir import ModelDir

    folder = ModelDir(args.model_dir, notify=lambda message: None)
    if not folder.root.is_dir():
        raise ModelFileError(f"model directory {str(Path(args.model_dir))!r} does not exist")
    if not args.no_repair:
        for line in folder.repair(wait=not args.no_wait):
            print(f"repaired: {line}")
    problems = folder.verify()
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
