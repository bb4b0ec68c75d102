"""argparse types shared by the ``heli`` sub-commands: numbers checked at the command line.

Each returns a function for ``add_argument(type=...)`` that raises
:class:`argparse.ArgumentTypeError` saying what was expected and what came, so a
bad value ends the command with argparse's usage line and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import os


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


def seconds_or(words: tuple, what: str, upper: float):
    """One of ``words`` (``"auto"``, ``"none"``, ...) or ``what`` in seconds within [0, ``upper``] (a servo
    delay or lag: the range :class:`heli_core.params.ModelParams` accepts)."""
    expected = " or ".join(repr(w) for w in words)
    seconds = number(f"{expected} or a {what} in seconds in [0, {upper:g}]", 0.0, upper, low_open=False,
                     high_open=False)

    def parse(text):
        return text if text in words else seconds(text)

    return parse


servo_lag = seconds_or(("detect", "auto", "none"), "servo lag", 1.0)
"""``--servo-lag`` of the commands that identify (``heli identify``, ``heli tune``): the likelihood's words or a
lag in seconds."""


def whole(minimum: int, maximum: int | None = None):
    """A whole number >= ``minimum`` (and <= ``maximum`` when given)."""

    def parse(text):
        try:
            v = int(text)
        except ValueError:
            v = minimum - 1
        if v < minimum or (maximum is not None and v > maximum):
            expected = f">= {minimum}" if maximum is None else f"from {minimum} to {maximum}"
            raise argparse.ArgumentTypeError(f"expected a whole number {expected}, got {text!r}")
        return v

    return parse


def input_hold(text):
    """``auto``, ``linear``, ``zoh`` or a hold fraction in [0, 1] (0 held over the sample, 1 interpolated)."""
    if text in ("auto", "linear", "zoh"):
        return text
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not 0.0 <= v <= 1.0:
        raise argparse.ArgumentTypeError(f"expected 'auto', 'linear', 'zoh' or a fraction in [0, 1], got {text!r}")
    return v


INPUT_HOLD_HELP = ("ml: how the sticks move between samples: 'auto' (default) estimates the fraction of "
                   "linear interpolation with the rest (a log rarely says; the wrong fixed choice biased the "
                   "damping 14-19 %%), 'linear' a pilot's hand sampled, 'zoh' commands held over each sample (a "
                   "digital link, a flight controller), or a fraction in [0, 1]")


FLIGHT_BYTES_PER_SECOND = 140_000
"""Peak memory of ``heli simulate-flight`` per second of flight at 100 Hz (measured: 112 MB for 30 s, 185 MB for
600 s, i.e. about 128 kB/s on top of the interpreter)."""

SEED_MAX = 2**32 - 1
"""Largest seed numpy's generators (and SB3's) accept."""


def seed():
    """A random seed: a whole number from 0 to :data:`SEED_MAX`."""
    return whole(0, SEED_MAX)


def seed_list(text):
    """Distinct seeds separated by commas, e.g. ``0,1,2`` (each as :func:`seed`)."""
    try:
        seeds = [int(v) for v in text.split(",") if v.strip() != ""]
    except ValueError:
        seeds = []
    if not seeds or len(set(seeds)) != len(seeds) or not all(0 <= v <= SEED_MAX for v in seeds):
        raise argparse.ArgumentTypeError(f"expected distinct whole numbers from 0 to {SEED_MAX} separated by "
                                         f"commas, got {text!r}")
    return seeds


def per_axis(expected: str):
    """One positive finite number for every axis, or three (roll,pitch,yaw) separated by commas: the float, or
    a list of three. ``expected`` names them in the message (e.g. "one positive cutoff in Hz or three
    (roll,pitch,yaw)")."""
    def parse(text):
        parts = [v for v in str(text).split(",") if v.strip()]
        try:
            values = [float(v) for v in parts]
        except ValueError:
            values = []
        if len(values) not in (1, 3) or not all(v > 0 and math.isfinite(v) for v in values):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return values[0] if len(values) == 1 else values
    return parse


def weights(count: int):
    """``count`` numbers >= 0 separated by commas, e.g. ``1,0.1,0.01``, as a tuple of floats."""
    def parse(text):
        try:
            values = tuple(float(v) for v in text.split(","))
        except ValueError:
            values = ()
        if len(values) != count or not all(math.isfinite(v) and v >= 0 for v in values):
            raise argparse.ArgumentTypeError(f"expected {count} numbers >= 0 separated by commas, got {text!r}")
        return values
    return parse


def json_object(text):
    """A JSON object, e.g. ``{"gamma": 0.995}``, as a dict."""
    try:
        value = json.loads(text)
    except ValueError:
        value = None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object such as '{{\"gamma\": 0.995}}', got {text!r}")
    return value


def output_path(text):
    """A path to write to: not empty (``''`` would name the current folder, or nothing at all)."""
    if not str(text).strip():
        raise argparse.ArgumentTypeError(f"expected a path to write to, got {text!r}")
    return text


def available_memory() -> int:
    """Bytes of memory this machine can give a new request (``MemAvailable``; else the physical memory)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - no sysconf
        return 2**63


def _gib(n: float) -> str:
    return f"{n / 2**30:.3g} GiB"


def memory_shortfall(need: float, memory=None) -> str:
    """Empty when ``need`` bytes fit in the available memory (``memory()``, default :func:`available_memory`), else
    how much that is against what there is, for a one-line refusal."""
    have = (memory or available_memory)()
    return "" if need <= have else f"about {_gib(need)} of memory and {_gib(have)} are available"


def affordable(what: str, bytes_per_unit: float, unit: str, low: float = 0.0, *, memory=available_memory):
    """Like :func:`number` (> ``low``), and refused up front when it would need more memory than is available.

    A request larger than the machine (``simulate-flight --duration 1e9``) would otherwise run until an
    allocation fails (or the kernel kills it); the message says what it would need.

    Parameters
    ----------
    what : str
        How the message names the expected value.
    bytes_per_unit : float
        Peak memory the command needs per unit of the value (measured), in bytes.
    unit : str
        The value's unit in the message, e.g. ``"s"``.
    memory : callable () -> int
        Available bytes (a test replaces it).
    """
    check = number(what, low)

    def parse(text):
        v = check(text)
        short = memory_shortfall(v * bytes_per_unit, memory)
        if short:
            raise argparse.ArgumentTypeError(f"expected {what}; {text} {unit} would need {short}")
        return v

    return parse


def segment_option(text):
    """``--segment``: 'auto', 'all' or ``T0:T1`` on the log's own clock (seconds, T0 < T1) as a pair."""
    if text in ("auto", "all"):
        return text
    try:
        a, b = (float(v) for v in text.split(":"))
    except ValueError:
        a = b = math.nan
    if not (math.isfinite(a) and math.isfinite(b) and b > a):
        raise argparse.ArgumentTypeError(f"expected 'auto', 'all' or T0:T1 in seconds with T0 < T1, got {text!r}")
    return (a, b)


def segment_or_each(text):
    """``--segment`` of ``heli import``: :func:`segment_option`, or 'each': every airborne run of a
    flight-controller log, a CSV each (``heli identify`` reads one flight per file: the runs' CSVs)."""
    if text == "each":
        return text
    try:
        return segment_option(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected 'auto', 'all', 'each' or T0:T1 in seconds with T0 < T1, "
                                         f"got {text!r}") from None


def fit_rate_option(text):
    """``--fit-rate``: 'auto', 'log' or a rate in Hz above 0 (the log's rate over a whole number, checked when the
    log is read: :func:`identification.fit_rate.every_for`)."""
    if text in ("auto", "log"):
        return text
    try:
        hz = float(text)
    except ValueError:
        hz = math.nan
    if not (math.isfinite(hz) and hz > 0):
        raise argparse.ArgumentTypeError(f"expected 'auto', 'log' or a rate in Hz above 0, got {text!r}")
    return hz
