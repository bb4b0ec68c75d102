"""The model's verdict at the door of the commands that build on a model (design, sweep, evaluate, train).

``heli identify`` and ``heli diagnose`` store a verdict in ``model.json`` (:mod:`model_store.verdict`).
Before any work, :func:`check_model` refuses an unusable model (:func:`model_store.model_file.require_usable`)
in one line (exit 2) naming its reasons and :data:`ACCEPT_FLAG`, and prints the doubts of a doubtful one. A model
file without a verdict (written before verdicts existed, or the shipped model) passes as before. Building the parser imports
nothing numeric (:mod:`heli_cli.main`): the model is read when the command runs.
"""

from __future__ import annotations

from pathlib import Path

ACCEPT_FLAG = "--accept-unusable-model"
"""The option of the commands that build on a model to use an unusable one anyway."""


def add_accept_option(parser, use: str) -> None:
    """The option to build on an unusable model anyway; ``use`` says what the command does with it."""
    parser.add_argument(ACCEPT_FLAG, dest="accept_unusable_model", action="store_true",
                        help=f"{use} even when the model's verdict (model.json, written by heli identify) is "
                        "'unusable' (default: refuse it, naming the reasons)")


def model_file(model) -> Path:
    """The ``model.json`` of ``--model`` (a folder or the file; None: the model shipped with heli-env)."""
    if model is None:
        from heli_env.env_model import default_model_dir

        model = default_model_dir()
    path = Path(model)
    return path / "model.json" if path.suffix != ".json" else path


def check_model(args, use: str):
    """Refuse an unusable ``args.model`` unless ``args.accept_unusable_model``; print a doubtful one's doubts.

    Returns the verdict (None when there is no model file: the command says so in its own words).

    Raises
    ------
    model_store.errors.UnusableModelError
        The model is judged unusable and the option was not given.
    """
    from model_store.model_dir import ModelDir
    from model_store.model_file import require_usable

    path = model_file(getattr(args, "model", None))
    if not path.is_file():
        return None
    document = ModelDir(path).load(library=False).document
    verdict = require_usable(document.verdict, str(path), accept=getattr(args, "accept_unusable_model", False),
                             flag=ACCEPT_FLAG, use=use)
    if verdict.unusable or verdict.doubtful:
        said = f"unusable ({ACCEPT_FLAG} given)" if verdict.unusable else "doubtful"
        print(f"warning: {path} is judged {said}:")
        for line in verdict.lines():
            print(f"  - {line}")
    return verdict
