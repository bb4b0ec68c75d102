"""The coefficients of the two firmwares' discrete filters (the compiled ticks apply them).

ArduPilot (master, libraries/Filter/LowPassFilter2p.cpp ``DigitalBiquadFilter::compute_params`` and
``apply``; libraries/AP_Math ``calc_lowpass_alpha_dt``):

* :func:`ap_alpha` — the first-order low-pass of AC_PID's target, error and derivative filters,
  ``a = dt/(dt + 1/(2π f))``, 1 (no filter) when ``f <= 0``;
* :func:`biquad_lpf2p` — the gyro's 2-pole Butterworth low-pass (``INS_GYRO_FILTER``), applied in direct
  form II with delay elements ``d1, d2`` (``d0 = x − a1·d1 − a2·d2``, ``y = b0·d0 + b1·d1 + b2·d2``);
  ``f <= 0`` passes through.

Rotorflight (rotorflight-firmware src/main/common/filter.c, read at 0185315f/b92aac00):

* :func:`rf_first_order` — ``firstOrderFilterUpdate``: bilinear first-order low-pass,
  ``W = tan(π f/fs)``, ``a1 = (W − 1)/(W + 1)``, ``b0 = b1 = W/(W + 1)``, ``y = b0·x + b1·x₁ − a1·y₁``
  (the per-axis ``gyro_cutoff`` with ``gyro_filter_type`` LPF_1ST_ORDER, the research notes' reading of
  ``lowpassFilterInit``, not checked line by line);
* :func:`rf_pt1` — ``pt1FilterGain``: ``a = f/(f + fs/2π)`` (``gyro_lpf1`` of type PT1 and the I-term
  relax filter);
* :func:`rf_dif` — ``difFilterUpdate`` / ``difFilterApply``: the band-limited differentiator of the D and
  B terms, ``K = tan(π f/fs)``, ``a = (K − 1)/(K + 1)``, ``b = 2π f/(K + 1)``,
  ``y = b·x − b·x₁ − a·y₁``.

Cut-offs above 47.5 % of the sample rate are limited there, as Rotorflight's ``limitCutoff`` does.
The firmware uses ``tan_approx``/``sin_approx``; here the exact functions (differences below 1e-6).
"""

from __future__ import annotations

import math


def ap_alpha(cutoff_hz: float, dt: float) -> float:
    """ArduPilot's ``calc_lowpass_alpha_dt``: ``dt/(dt + 1/(2π f))``; 1 for ``f <= 0`` (no filter).

    Parameters
    ----------
    cutoff_hz : float
        Cut-off [Hz]; 0 switches the filter off.
    dt : float
        Tick [s].
    """
    if cutoff_hz <= 0.0:
        return 1.0
    if dt <= 0.0:
        return 0.0
    return dt / (dt + 1.0 / (2.0 * math.pi * cutoff_hz))


def biquad_lpf2p(sample_hz: float, cutoff_hz: float) -> tuple | None:
    """Coefficients ``(b0, b1, b2, a1, a2)`` of ArduPilot's ``LowPassFilter2p``, or None (pass-through).

    Parameters
    ----------
    sample_hz : float
        Rate the filter runs at [Hz].
    cutoff_hz : float
        Cut-off [Hz]; <= 0 passes the signal through, as the firmware does.
    """
    if cutoff_hz <= 0.0:
        return None
    ohm = math.tan(math.pi * cutoff_hz / sample_hz)
    c = 1.0 + 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm
    b0 = ohm * ohm / c
    return b0, 2.0 * b0, b0, 2.0 * (ohm * ohm - 1.0) / c, (1.0 - 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm) / c


def _limit(cutoff_hz: float, sample_hz: float) -> float:
    """Rotorflight's ``limitCutoff``: at most 95 % of the Nyquist frequency."""
    return min(float(cutoff_hz), 0.475 * float(sample_hz))


def rf_first_order(cutoff_hz: float, sample_hz: float) -> tuple | None:
    """``(b0, b1, a1)`` of Rotorflight's bilinear first-order low-pass, or None when ``cutoff_hz <= 0`` (off).

    ``y = b0·x + b1·x₁ − a1·y₁``.
    """
    if cutoff_hz <= 0.0:
        return None
    w = math.tan(math.pi * _limit(cutoff_hz, sample_hz) / sample_hz)
    return w / (w + 1.0), w / (w + 1.0), (w - 1.0) / (w + 1.0)


def rf_pt1(cutoff_hz: float, sample_hz: float) -> float:
    """Gain of Rotorflight's PT1 low-pass ``y += a·(x − y)``: ``a = f/(f + fs/2π)``, at most 1; 1 when off."""
    if cutoff_hz <= 0.0:
        return 1.0
    f = _limit(cutoff_hz, sample_hz)
    return min(f / (f + sample_hz / (2.0 * math.pi)), 1.0)


def rf_dif(cutoff_hz: float, sample_hz: float) -> tuple:
    """``(a, b)`` of Rotorflight's band-limited differentiator ``s·Wc/(s + Wc)`` by the bilinear transform.

    ``y = b·x − b·x₁ − a·y₁``; ``cutoff_hz <= 0`` gives ``(−1, 0)``: output 0 (the firmware's
    ``tan(0) = 0`` and ``Wc = 0``).
    """
    f = max(_limit(cutoff_hz, sample_hz), 0.0)
    k = math.tan(math.pi * f / sample_hz)
    return (k - 1.0) / (k + 1.0), 2.0 * math.pi * f / (k + 1.0)


