"""Rotor vibration lines in gyro signals, removed by regression on their sinusoids (not by a low-pass).

A flight controller flies on the gyro it logs, so its commands carry the same lines, and the aircraft
really responds to them at those frequencies. Removing the lines from the rates alone then leaves the model
predicting a response the cleaned rates no longer hold (on the autopilot bench cell a sub-sample input delay
came out likelier, likelihood-ratio statistic 50-85 on effect-free flights). :func:`remove_common_lines`
removes the lines from the commands and the rates together: the same prefilter on the input and the output,
which leaves their relation unchanged.
"""

from __future__ import annotations

import numpy as np

from heli_core.terms import AXES


def remove_vibration_lines(rates, fs: float, min_hz: float = 8.0, max_lines: int = 4, prominence: float = 30.0):
    """Remove narrow spectral lines (rotor vibration) from gyro signals by regression on their sinusoids.

    For each axis, the periodogram (zero-padded 4x, Hann window) is searched above
    ``min_hz`` for peaks standing ``prominence`` times above the median power of
    their neighbourhood (±2 Hz); each line's frequency is refined by parabolic
    interpolation, its amplitude and phase fitted by least squares over the whole
    record, and the sinusoid subtracted. A low-pass would also delay the rate
    (every 10 ms of lag costs about 20 % of damping); the regression does not.

    Parameters
    ----------
    rates : ndarray, shape (3, n)
    fs : float
        Sample rate [Hz].

    Returns
    -------
    cleaned : ndarray, shape (3, n)
    lines : list of dict
        ``axis``, ``frequency_hz``, ``amplitude`` [rad/s] of each line removed.
    """
    rates = np.array(rates, dtype=float, copy=True)
    n = rates.shape[1]
    if min_hz >= fs / 2 or n < 64:
        return rates, []
    t = np.arange(n) / fs
    nfft = 1 << int(np.ceil(np.log2(4 * n)))
    freqs = np.fft.rfftfreq(nfft, 1.0 / fs)
    win = np.hanning(n)
    df = freqs[1]
    half = max(3, int(round(2.0 / df)))
    found = []
    for a in range(rates.shape[0]):
        for _ in range(max_lines):
            x = rates[a] - np.mean(rates[a])
            power = np.abs(np.fft.rfft(x * win, nfft)) ** 2
            band = np.where(freqs >= min_hz)[0]
            band = band[band < power.size - 1]
            if band.size < 2 * half:
                break
            k = band[np.argmax(power[band])]
            lo, hi = max(0, k - half), min(power.size, k + half + 1)
            neighbourhood = np.concatenate([power[lo:max(lo, k - 8)], power[min(hi, k + 9):hi]])
            if neighbourhood.size == 0 or power[k] < prominence * np.median(neighbourhood):
                break
            y0, y1, y2 = np.log(power[k - 1:k + 2] + 1e-300)
            denom = y0 - 2 * y1 + y2
            shift = 0.5 * (y0 - y2) / denom if denom != 0 else 0.0
            f0 = float(freqs[k] + np.clip(shift, -0.5, 0.5) * df)
            basis = np.vstack([np.cos(2 * np.pi * f0 * t), np.sin(2 * np.pi * f0 * t)])
            coef = np.linalg.lstsq(basis.T, x, rcond=None)[0]
            rates[a] -= coef @ basis
            found.append({"axis": AXES[a] if rates.shape[0] == 3 else a, "frequency_hz": f0,
                          "amplitude": float(np.hypot(*coef))})
    return rates, found


def remove_lines(x, fs: float, frequencies) -> np.ndarray:
    """``x`` (n,) with its sinusoids at ``frequencies`` [Hz] removed by one least-squares regression."""
    x = np.asarray(x, dtype=float)
    if not len(frequencies):
        return x.copy()
    t = np.arange(x.size) / fs
    basis = np.vstack([f(2 * np.pi * float(hz) * t) for hz in frequencies for f in (np.cos, np.sin)])
    centred = x - np.mean(x)
    coef = np.linalg.lstsq(basis.T, centred, rcond=None)[0]
    return x - coef @ basis


def remove_common_lines(rates, commands, fs: float, min_hz: float = 8.0) -> tuple[np.ndarray, np.ndarray, list]:
    """Vibration lines removed from the gyro, and from the commands where these carry lines too.

    Each axis' gyro (``rates``, (3, n)) is cleaned by :func:`remove_vibration_lines`. Where that axis'
    command (``commands``, (3, n): lat, lon, ped) has lines of its own (a flight controller feeding its
    gyro back), the lines of either are removed from both, from the raw signals in one regression, so that
    input and output see the same prefilter. A pilot's sticks have no such lines: then only the gyro is
    cleaned, exactly as :func:`remove_vibration_lines` does.

    Returns
    -------
    rates, commands : ndarray, shape (3, n)
    lines : list of dict
        The gyro's lines, then those removed from the commands (``"signal": "command"``).
    """
    cleaned, found = remove_vibration_lines(rates, fs, min_hz)
    commands = np.array(commands, dtype=float, copy=True)
    _, in_commands = remove_vibration_lines(commands, fs, min_hz)
    lines = list(found)
    for a in range(commands.shape[0]):
        own = [ln["frequency_hz"] for ln in in_commands if ln["axis"] == AXES[a]]
        if not own:
            continue
        resolution = 0.5 * fs / commands.shape[1]  # the same line found in both: regressed once
        freqs = []
        for hz in own + [ln["frequency_hz"] for ln in found if ln["axis"] == AXES[a]]:
            if all(abs(hz - f) > resolution for f in freqs):
                freqs.append(hz)
        cleaned[a] = remove_lines(np.asarray(rates[a], dtype=float), fs, freqs)
        commands[a] = remove_lines(commands[a], fs, freqs)
        lines += [{**ln, "signal": "command"} for ln in in_commands if ln["axis"] == AXES[a]]
    return cleaned, commands, lines
