"""The servo: a transport delay per axis, as the first-order Padé approximation of eq. (31).

The paper models the lag between the commanded and the achieved blade pitch by
a delay ``exp(-s*tau)`` and replaces it by its first-order Padé approximation
(eq. 31, computed "using the *Pade* function")::

    theta + d1*theta' = n1*delta - n2*delta'                              (31)

Two forms of it are used: the coefficients, which the physics core turns into a
servo state of the continuous model (:func:`servo_coefficients`), and a
discrete filter that passes a whole recorded command through the delay, which
the identifiers and the disturbance estimate use (:func:`pade_filter`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=256)
def servo_coefficients(tau: float) -> tuple[float, float, float]:
    """Coefficients ``(d1, n1, n2)`` of the servo-delay model, eq. (31).

    ``theta + d1*theta' = n1*delta - n2*delta'`` is the first-order Padé
    approximation of ``exp(-s*tau)``, computed with ``control.pade``.

    Parameters
    ----------
    tau : float
        Delay [s]; 0 or less means no delay.

    Returns
    -------
    d1 : float
        [s]
    n1 : float
        [-]
    n2 : float
        [s]; ``(0, 1, 0)`` without a delay.
    """
    if tau <= 0.0:
        return (0.0, 1.0, 0.0)
    import control

    num, den = control.pade(tau, 1)  # (-s + 2/tau) / (s + 2/tau)
    return (den[0] / den[1], num[1] / den[1], -num[0] / den[1])


def pade_filter(command: np.ndarray, tau: float, fs: float) -> np.ndarray:
    """Pass a command through the first-order Padé delay of eq. (31).

    The continuous filter ``(n1 - n2 s)/(1 + d1 s)`` (coefficients from
    ``control.pade``, :func:`servo_coefficients`) is discretised with the
    bilinear transform and run from rest at the first sample's value.

    Parameters
    ----------
    command : ndarray, shape (..., n)
        Stick command sampled at ``fs`` [stick units].
    tau : float
        Delay [s]; 0 or less returns the command unchanged (as a float array).
    fs : float
        Sample rate [Hz].

    Returns
    -------
    ndarray, shape (..., n)
        The servo-side command [stick units].
    """
    if tau <= 0:
        return np.asarray(command, dtype=float)
    from scipy import signal

    b, a, zi_unit = _pade_discrete(float(tau), float(fs))
    zi = zi_unit * command[..., :1]
    return signal.lfilter(b, a, command, axis=-1, zi=zi)[0]


@lru_cache(maxsize=256)
def _pade_discrete(tau: float, fs: float):
    """Bilinear-transform coefficients (b, a) of the Padé delay and the filter state for a unit step.

    Cached: scipy's bilinear takes about a millisecond, longer than filtering a whole flight.
    """
    from scipy import signal

    d1, n1, n2 = servo_coefficients(tau)
    b, a = signal.bilinear([-n2, n1], [d1, 1.0], fs=fs)
    zi = signal.lfilter_zi(b, a)
    for arr in (b, a, zi):
        arr.setflags(write=False)
    return b, a, zi
