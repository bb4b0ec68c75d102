"""The servo: a transport delay per axis, as the first-order Padé approximation of eq. (31), and a lag.

The paper models the lag between the commanded and the achieved blade pitch by
a delay ``exp(-s*tau)`` and replaces it by its first-order Padé approximation
(eq. 31, computed "using the *Pade* function")::

    theta + d1*theta' = n1*delta - n2*delta'                              (31)

A servo that also lags (a first-order time constant ``lag``, identified where the
data support one) keeps the form of eq. (31) with the lag added to ``d1``: the
servo is ``(1 - s tau/2) / (1 + s (tau/2 + lag))``, the Padé delay when
``lag = 0`` and the first-order lag ``1 / (1 + s lag)`` when ``tau = 0``. Both
shape the phase alike at low frequency (``tau + lag`` of lag); they differ in
the gain above ``1/lag``, which a lag attenuates and a delay does not.

Two forms of it are used: the coefficients, which the physics core turns into a
servo state of the continuous model (:func:`servo_coefficients`), and a
discrete filter that passes a whole recorded command through the delay, which
the identifiers and the disturbance estimate use (:func:`pade_filter`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


def per_axis(name: str, setting, upper: float, words: tuple = ("auto",)) -> list:
    """An identifier's servo setting (``delay``, ``servo_lag``) per axis (roll, pitch, yaw): seconds in
    [0, ``upper``], or one of ``words`` (``"auto"``: profiled; the ML estimator's delay also takes
    ``"detect"``). None means 0 on every axis, one value every axis the same; three values may mix words and
    seconds (``[0.02, 0.02, "detect"]``).

    Raises
    ------
    ValueError
        Anything else, naming the setting, what it takes and what came.
    """
    takes = "None, " + ", ".join(repr(w) for w in words) + ", seconds or 3 values in seconds"
    if setting is None:
        return [0.0, 0.0, 0.0]
    if isinstance(setting, str):
        if setting not in words:
            raise ValueError(f"{name} must be {takes}, got {setting!r}")
        return [setting] * 3
    if isinstance(setting, (list, tuple)) and len(setting) == 3 and any(isinstance(v, str) for v in setting):
        return [per_axis(name, v, upper, words)[0] for v in setting]  # a word on some axes, seconds on others
    try:
        values = np.asarray(setting, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {takes}, got {setting!r}") from None
    values = np.full(3, float(values)) if values.ndim == 0 else values
    if values.shape != (3,):
        raise ValueError(f"{name} needs one value per axis (roll, pitch, yaw) or one for all, got {setting!r}")
    if not np.all((values >= 0) & (values <= upper)):
        raise ValueError(f"{name} must be {takes} in [0, {upper:g}], got {setting!r}")
    return [float(v) for v in values]


@lru_cache(maxsize=256)
def servo_coefficients(tau: float, lag: float = 0.0) -> tuple[float, float, float]:
    """Coefficients ``(d1, n1, n2)`` of the servo model, eq. (31).

    ``theta + d1*theta' = n1*delta - n2*delta'`` is the first-order Padé
    approximation of ``exp(-s*tau)``, ``(1 - s tau/2) / (1 + s tau/2)``, with the
    servo's first-order ``lag`` added to ``d1`` (module docstring). The paper
    takes it from MATLAB's ``pade``; the closed form here is what
    ``control.pade(tau, 1)`` returns (``tests/test_model.py`` compares the two to
    1e-12), written out because importing python-control costs 1.4 s, most of
    building an env in a new process.

    Parameters
    ----------
    tau : float
        Delay [s]; 0 or less means no delay.
    lag : float
        First-order time constant [s]; 0 or less means none.

    Returns
    -------
    d1 : float
        [s]
    n1 : float
        [-]
    n2 : float
        [s]; ``(0, 1, 0)`` without a delay or a lag.
    """
    lag = max(float(lag), 0.0)
    if tau <= 0.0:
        return (lag, 1.0, 0.0)
    half = float(tau) / 2.0
    return (half + lag, 1.0, half)


def pade_filter(command: np.ndarray, tau: float, fs: float, lag: float = 0.0) -> np.ndarray:
    """Pass a command through the servo of eq. (31): the first-order Padé delay (and the servo's lag).

    The continuous filter ``(n1 - n2 s)/(1 + d1 s)`` (coefficients from
    :func:`servo_coefficients`) is discretised with the
    bilinear transform and run from rest at the first sample's value.

    Parameters
    ----------
    command : ndarray, shape (..., n)
        Stick command sampled at ``fs`` [stick units].
    tau : float
        Delay [s]; 0 or less returns the command unchanged (as a float array).
    fs : float
        Sample rate [Hz].
    lag : float
        The servo's first-order time constant [s]; 0 means none.

    Returns
    -------
    ndarray, shape (..., n)
        The servo-side command [stick units].
    """
    if tau <= 0 and lag <= 0:
        return np.asarray(command, dtype=float)
    from scipy import signal

    b, a, zi_unit = _pade_discrete(float(tau), float(fs), float(lag))
    zi = zi_unit * command[..., :1]
    return signal.lfilter(b, a, command, axis=-1, zi=zi)[0]


@lru_cache(maxsize=256)
def _pade_discrete(tau: float, fs: float, lag: float = 0.0):
    """Bilinear-transform coefficients (b, a) of the servo (Padé delay and lag) and the filter state for a
    unit step.

    Cached: scipy's bilinear takes about a millisecond, longer than filtering a whole flight.
    """
    from scipy import signal

    d1, n1, n2 = servo_coefficients(tau, lag)
    b, a = signal.bilinear([-n2, n1], [d1, 1.0], fs=fs)
    zi = signal.lfilter_zi(b, a)
    for arr in (b, a, zi):
        arr.setflags(write=False)
    return b, a, zi
