"""argparse types shared by the ``heli`` sub-commands: numbers checked at the command line.

Each returns a function for ``add_argument(type=...)`` that raises
:class:`argparse.ArgumentTypeError` saying what was expected and what came, so a
bad value ends the command with argparse's usage line and exit status 2.
"""

from __future__ import annotations

import argparse
import math


def number(what: str, low: float | None = None, high: float | None = None, *, low_open: bool = True,
           high_open: bool = True):
    """A finite float within ``low``..``high`` (open bounds by default; None: unbounded).

    Parameters
    ----------
    what : str
        How the message names the expected value, e.g. ``"a positive rate in Hz"``.
    low, high : float, optional
        Bounds.
    low_open, high_open : bool
        Whether a bound itself is excluded.
    """

    def parse(text):
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        ok = (math.isfinite(v) and (low is None or (v > low if low_open else v >= low))
              and (high is None or (v < high if high_open else v <= high)))
        if not ok:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return v

    return parse


def whole(minimum: int):
    """A whole number >= ``minimum``."""

    def parse(text):
        try:
            v = int(text)
        except ValueError:
            v = minimum - 1
        if v < minimum:
            raise argparse.ArgumentTypeError(f"expected a whole number >= {minimum}, got {text!r}")
        return v

    return parse
