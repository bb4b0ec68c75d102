"""Advice in an error message worded for the command line.

The packages' errors advise their own Python arguments (``pass segment='all'``,
``allow_damaged=True``, ``episode_seconds=200``): that is what a caller of the Python API
can act on. A ``heli`` user acts on options instead, so before the CLI prints a message,
:func:`as_cli_options` rewrites each such argument that is an option of the running command
into that option (``--segment all``, ``--allow-damaged``, ``--episode-seconds 200``), and drops
a CLI hint in parentheses that the rewritten advice makes redundant
(``allow_damaged=True (heli import --allow-damaged)`` becomes ``--allow-damaged``).
Arguments that are not options of the command are left as they are.
"""

from __future__ import annotations

import re

_ARGUMENT = re.compile(r"(?<![\w.\-])([a-z][a-z0-9_]*)=('[^']*'|\"[^\"]*\"|True|\([^()]*\)|-?[\w.:]+)")
_HINT = re.compile(r"\s*\((?:heli (\w[\w-]*) )?(--[^()]*)\)")


def _option(name: str, value: str, options) -> str | None:
    flag = "--" + name.replace("_", "-")
    if flag not in options:
        return None
    if value == "True":
        return flag
    if value.startswith("(") and value.endswith(")"):  # a (T0, T1) pair: the CLI's T0:T1
        value = ":".join(v.strip() for v in value[1:-1].split(","))
    return f"{flag} {value.strip(chr(39) + chr(34))}"


def as_cli_options(text: str, command: str, options) -> str:
    """``text`` with each Python argument that is one of ``options`` (a command's option strings, e.g.
    ``{"--segment", "--allow-damaged"}``) written as that option (module docstring)."""
    out, pos = [], 0
    for m in _ARGUMENT.finditer(text):
        cli = _option(m.group(1), m.group(2), options)
        if cli is None:
            continue
        end = m.end()
        hint = _HINT.match(text, end)
        if hint and (hint.group(1) in (None, command)) and hint.group(2).split()[0] == cli.split()[0]:
            end = hint.end()  # the same advice again, for the command line: said once
        out.append(text[pos:m.start()] + cli)
        pos = end
    return "".join(out) + text[pos:]


def command_options(parser, command: str) -> set:
    """The option strings of ``command``'s sub-parser of the ``heli`` parser (empty if there is none)."""
    import argparse

    for action in getattr(parser, "_actions", ()):  # a stand-in parser (tests) has none
        if isinstance(action, argparse._SubParsersAction) and command in action.choices:
            return set(action.choices[command]._option_string_actions)
    return set()
