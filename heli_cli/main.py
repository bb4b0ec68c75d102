"""Entry point of the ``heli`` command.

Each sub-command lives in its own module of :mod:`heli_cli` and exposes
``register(subparsers)``, which adds its parser and sets ``func`` to a function
taking the parsed arguments and returning an exit code. Errors the user can fix
(bad input files, unidentifiable data) are printed as one line without a
traceback and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

COMMAND_MODULES = (
    "heli_cli.simulate_flight",
    "heli_cli.identify",
    "heli_cli.import_log",
    "heli_cli.refresh",
    "heli_cli.compare_methods",
    "heli_cli.design",
    "heli_cli.sweep",
    "heli_cli.train",
    "heli_cli.evaluate",
    "heli_cli.diagnose",
)
"""Modules that register sub-commands, in the order ``heli --help`` lists them."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="heli",
        description="Identify RC-helicopter attitude models from flight logs, replay their gusts in a "
        "Gymnasium environment, and design controllers against them.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv=None) -> int:
    from controllers.errors import AgentError, DesignError, SweepError
    from heli_env.errors import EnvModelError
    from identification.errors import (BackendError, DisturbanceError, FlightLogError, IdentifiabilityError,
                                       LibraryError, MissingDependency, ModelFileError, TaskFailed)

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (FlightLogError, IdentifiabilityError, ModelFileError, MissingDependency, DisturbanceError, LibraryError,
            BackendError, TaskFailed, SweepError, AgentError, DesignError, EnvModelError) as e:
        print(f"heli {args.command}: error: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    except (FileNotFoundError, FileExistsError, NotADirectoryError, IsADirectoryError, PermissionError) as e:
        # a path that is not what the command needs (an output folder that is a file, a read-only folder)
        what = f"{e.strerror}: {e.filename}" if e.strerror and e.filename else str(e)
        print(f"heli {args.command}: error: {what}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
