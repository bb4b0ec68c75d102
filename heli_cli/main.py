"""Entry point of the ``heli`` command.

Each sub-command lives in its own module of :mod:`heli_cli` and exposes
``register(subparsers)``, which adds its parser and sets ``func`` to a function
taking the parsed arguments and returning an exit code. Building the parser
imports no numeric package: a command's handler imports what it needs when it
runs, so ``heli --help`` and every ``heli COMMAND --help`` answer at once.

Errors the user can fix (any :class:`heli_core.errors.HeliError`: bad input
files, unidentifiable data; and a path that is not what the command needs) are printed as one line without a traceback and
exit with status 2; anything else is a bug, printed as one line with a request
to report it, exit status 1. ``--debug`` adds the traceback to either. Ctrl-C ends a command with
"interrupted" and exit status 130 (:func:`run`, the console script, then ignores a second one).
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
import traceback
from pathlib import Path

from heli_core.errors import HeliError

COMMAND_MODULES = (
    "heli_cli.simulate_flight",
    "heli_cli.import_log",
    "heli_cli.identify",
    "heli_cli.diagnose",
    "heli_cli.refresh",
    "heli_cli.check",
    "heli_cli.compare_methods",
    "heli_cli.design",
    "heli_cli.sweep",
    "heli_cli.train",
    "heli_cli.evaluate",
    "heli_cli.tune",
)
"""Modules that register sub-commands, in the order ``heli --help`` lists them (a workflow's order)."""

USER_ERRORS = (HeliError,)
"""Errors the user can fix: every error the packages raise on purpose derives from
:class:`heli_core.errors.HeliError` (one line and exit status 2)."""

PATH_ERRORS = (FileNotFoundError, FileExistsError, NotADirectoryError, IsADirectoryError, PermissionError)
"""A path that is not what the command needs (an output folder that is a file, a read-only folder): exit 2."""

REPORT_HINT = "this is a bug in heli-env; please report it with the command line and the traceback --debug shows"


def version() -> str:
    """The installed package's version, else the one ``pyproject.toml`` beside the source states."""
    from importlib import metadata

    try:
        return metadata.version("heli-env")
    except metadata.PackageNotFoundError:
        pyproject = Path(__file__).resolve().parents[1] / "pyproject.toml"
        found = re.search(r'^version\s*=\s*"([^"]+)"', pyproject.read_text(), re.M) if pyproject.exists() else None
        return found.group(1) if found else "unknown"


class _Version(argparse.Action):
    """``--version``: the version is looked up only when asked for."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"heli (heli-env) {version()}")
        parser.exit()


def add_global_options(parser, *, on_command: bool) -> None:
    """``--quiet`` and ``--debug``, accepted before the command and after it.

    On a sub-command the defaults are suppressed, so ``heli --quiet identify ...`` is not undone by the
    sub-command's own default.
    """
    default = (lambda value: argparse.SUPPRESS) if on_command else (lambda value: value)
    parser.add_argument("-q", "--quiet", action="store_true", default=default(False),
                        help="no progress lines or bars (results, warnings and errors are still printed)")
    parser.add_argument("--no-progress", dest="quiet", action="store_true", default=default(False),
                        help=argparse.SUPPRESS)  # the flag's earlier name on sweep, train and compare-methods
    parser.add_argument("--debug", action="store_true", default=default(False),
                        help="show the traceback of an error")


class _HelpFormatter(argparse.HelpFormatter):
    """argparse's layout, with the commands aligned with the options and without the bare ``COMMAND`` line."""

    def _iter_indented_subactions(self, action):
        yield from getattr(action, "_get_subactions", list)()

    def _format_action(self, action):
        text = super()._format_action(action)
        if action.nargs == argparse.PARSER:
            text = text.split("\n", 1)[1]
        return text


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="heli", formatter_class=_HelpFormatter,
        description="Identify RC-helicopter attitude models from flight logs, replay their gusts in a "
        "Gymnasium environment, and design controllers against them.",
        epilog="Run 'heli COMMAND --help' for a command's options. A first look: 'make demo'.",
    )
    parser.add_argument("--version", action=_Version, help="print the version and exit")
    add_global_options(parser, on_command=False)
    parser._positionals.title = "commands"  # listed first, before the options
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    for command_parser in sub.choices.values():
        add_global_options(command_parser, on_command=True)
    return parser


def command_names() -> list:
    """The sub-commands, in the order ``heli --help`` lists them."""
    sub = next(a for a in build_parser()._actions if a.nargs == argparse.PARSER)
    return list(sub.choices)


def check_output(path, kind: str) -> None:
    """Refuse an output path the command could not write, before any work is done.

    ``kind`` is ``"file"`` (the path will be a file) or ``"dir"`` (a folder the command fills). Raises the
    :data:`PATH_ERRORS` a late write would have raised (one line, exit 2): the path is the wrong kind of thing,
    lies under a file, or its nearest existing folder is not writable. Nothing is created here.
    """
    import errno
    import os

    path = Path(path)
    if path.exists():
        if kind == "dir" and not path.is_dir():
            raise NotADirectoryError(errno.ENOTDIR, "the output folder is a file", str(path))
        if kind == "file" and path.is_dir():
            raise IsADirectoryError(errno.EISDIR, "the output file is a folder", str(path))
    parent = path if kind == "dir" and path.is_dir() else path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "the output path lies under a file", str(parent))
    if not os.access(parent, os.W_OK | os.X_OK):
        raise PermissionError(errno.EACCES, "the output folder is not writable", str(parent))


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)  # for advice that names the next command
    if args.command is None:  # 'heli' alone: what it can do, on the error stream as argparse's usage errors
        parser.print_help(sys.stderr)
        return 2
    from .option_wording import command_options

    args.cli_options = command_options(parser, args.command)  # errors advise these, not Python arguments
    created = None  # an output folder this run creates, removed again if the run fails and leaves it empty
    if getattr(args, "out", None) and getattr(args, "out_kind", None) == "dir" and not Path(args.out).exists():
        created = Path(args.out)
    from .closed_pipe import guarded_stdout

    with guarded_stdout():  # a reader who stops reading (`| head`) does not stop the files being written
        code = _run(args)
    if code != 0 and created is not None and created.is_dir() and not any(created.iterdir()):
        created.rmdir()
    return code


def _run(args) -> int:
    """Run the parsed command; every error ends in one line and an exit status (module docstring)."""
    prefix = f"heli {args.command}"
    try:
        if getattr(args, "out", None) and getattr(args, "out_kind", None):
            check_output(args.out, args.out_kind)
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"{prefix}: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # noqa: BLE001 -- every error ends in one line (module docstring)
        if args.debug:
            traceback.print_exc()
        if isinstance(e, USER_ERRORS):
            from .option_wording import as_cli_options

            message = as_cli_options(str(e), args.command, getattr(args, "cli_options", ()))
            print(f"{prefix}: error: {type(e).__name__}: {message}", file=sys.stderr)
            return 2
        if isinstance(e, PATH_ERRORS):
            what = f"{e.strerror}: {e.filename}" if e.strerror and e.filename else str(e)
            print(f"{prefix}: error: {what}", file=sys.stderr)
            return 2
        if isinstance(e, MemoryError):  # a request larger than the machine: what it would need, and what to do
            print(f"{prefix}: error: not enough memory for this request ({e or 'allocation failed'}); ask for "
                  "less (a shorter --duration, a smaller gain grid, fewer windows)", file=sys.stderr)
            return 2
        print(f"{prefix}: unexpected error: {type(e).__name__}: {e}", file=sys.stderr)
        print(f"{prefix}: {REPORT_HINT}", file=sys.stderr)
        return 1


def run() -> int:
    """The ``heli`` program (its console script): :func:`main` on the command line's arguments.

    After an interrupt the command has ended ("interrupted", 130), a second SIGINT is ignored: the exit hooks
    still to run (a worker pool's join) would otherwise print Python's "Exception ignored" traceback. A
    terminal's double Ctrl-C and ``timeout -s INT`` (the child, then its group) both send one. :func:`main`
    itself leaves the caller's SIGINT handler alone.
    """
    code = main()
    if code == 130:
        import signal

        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(run())
