"""Configuration objects: a function's many settings as one frozen dataclass, or its fields by keyword.

A function with more than a handful of settings (a gain sweep, a training run, the flight tests, an
agent's evaluation) takes them as one frozen dataclass, its fields documented and checked once in
``__post_init__``, passed as ``config=``; its fields keep working as keywords, which replace the config's
(``sweep_gains(model, kp, kd, config, duration=3.0)`` sweeps ``config`` for 3 s). :func:`configured` is that
rule, written once for every such function; :func:`check` and :func:`whole_number` are the checks the
configs share, each raising the package's own error (a ``ValueError``) that names the field, what was
expected and what came.
"""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np


def configured(cls, config, settings: dict, what: str):
    """``config`` (default ``cls()``) with the keyword ``settings`` replacing its fields, checked again.

    Parameters
    ----------
    cls : frozen dataclass type
        The configuration class (:class:`controllers.sweep.SweepConfig`, ...).
    config : cls or None
        The caller's config.
    settings : dict
        Fields of ``cls`` given by keyword; each replaces the config's (a keyword wins over the config).
    what : str
        What the settings configure, for the error message ("sweep", "training", ...).

    Returns
    -------
    cls
        ``config`` itself when no setting is given.

    Raises
    ------
    TypeError
        ``config`` is not a ``cls``, or a keyword is not one of its fields (the message lists them).
    ValueError
        A bad field (the class's own check in ``__post_init__``).
    """
    if config is not None and not isinstance(config, cls):
        article = "an" if cls.__name__[0] in "AEIOU" else "a"
        raise TypeError(f"config must be {article} {cls.__name__} (the settings go by keyword), got {config!r}")
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(settings) - set(names))
    if unknown:
        raise TypeError(f"unknown {what} settings {', '.join(unknown)}; expected fields of {cls.__name__} "
                        f"({', '.join(names)})")
    if config is None:
        return cls(**settings)
    return dataclasses.replace(config, **settings) if settings else config


def check(ok: bool, name: str, expected: str, value, error=ValueError) -> None:
    """Raise ``error("<name> must be <expected>, got <value!r>")`` unless ``ok``."""
    if not ok:
        raise error(f"{name} must be {expected}, got {value!r}")


def is_real(value) -> bool:
    """A finite real number (not a bool, a string or a complex number)."""
    return (isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
            and math.isfinite(value))


def is_flag(value) -> bool:
    """True or False (Python's or numpy's)."""
    return isinstance(value, (bool, np.bool_))


def whole_number(value, name: str, minimum: int = 0, error=ValueError) -> int:
    """``value`` as an int when it is a whole number >= ``minimum`` (``3`` or ``3.0``, not ``True``), else ``error``."""
    whole = isinstance(value, numbers.Integral) or (isinstance(value, float) and value.is_integer())
    check(whole and not isinstance(value, (bool, np.bool_)) and value >= minimum, name,
          f"a whole number >= {minimum}", value, error)
    return int(value)
