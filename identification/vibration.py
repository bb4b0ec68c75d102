"""Rotor vibration lines in gyro signals, removed by regression on their sinusoids (not by a low-pass).

A flight controller flies on the gyro it logs, so its commands carry the same lines, and the aircraft
really responds to them at those frequencies. Removing the lines from the rates alone then leaves the model
predicting a response the cleaned rates no longer hold (on the autopilot bench cell a sub-sample input delay
came out likelier, likelihood-ratio statistic 50-85 on effect-free flights). :func:`remove_common_lines`
removes the lines from the commands and the rates together: the same prefilter on the input and the output,
which leaves their relation unchanged.

A gyro logged slower than twice a line's frequency folds the line into the aircraft's own band (27 Hz logged at
25 Hz is a line at 2 Hz, 30 Hz one at 5 Hz): on the bench at 25 Hz such lines, which the search above 8 Hz never
saw, left the dampings 450-600 % off. There a line cannot be told from the motion by its frequency, so
:func:`remove_folded_lines` asks the attitude: the aircraft's own motion at a frequency shows in the attitude
as the rate's integral, a sensor's line does not, and only the part of the line the attitude does not explain is
removed (the whole line behind a pilot, the sensor's share behind an autopilot that flew on it; nothing of a
sine-dwell the pilot flew). A flight controller whose loop runs faster than its log commands the line at its own
frequency, and the log folds the command's line with the gyro's: the aircraft answered it up there, not at the
folded frequency, so :func:`remove_fed_back_lines` takes it out of the commands and the gyro together.
"""

from __future__ import annotations

import numpy as np

from heli_core.terms import AXES


FOLDED_FLOOR_HZ = 0.5
"""Lowest frequency :func:`remove_folded_lines` searches [Hz]: below it the gusts' own power hides a line, and
the slow wind state absorbs one."""

_GAP = 8
"""Bins either side of a peak left out of its sides: the Hann window's main lobe, zero-padded 4x."""

_NARROW = 32
"""Bins just beyond the main lobe that a folded line must stand above on each side."""

_CANDIDATES = 64
"""Local maxima tried per axis, the strongest first."""


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
    nfft, freqs, half = _grid(n, fs)
    win = np.hanning(n)
    band = _searched_band(freqs, min_hz, half)
    found = []
    for a in range(rates.shape[0] if band.size else 0):
        for _ in range(max_lines):
            x = rates[a] - np.mean(rates[a])
            power = np.abs(np.fft.rfft(x * win, nfft)) ** 2
            k = band[np.argmax(power[band])]
            lo, hi = max(0, k - half), min(power.size, k + half + 1)
            neighbourhood = np.concatenate([power[lo:max(lo, k - _GAP)], power[min(hi, k + _GAP + 1):hi]])
            if neighbourhood.size == 0 or power[k] < prominence * np.median(neighbourhood):
                break
            f0 = _refined(power, freqs, k)
            basis = _basis(f0, t)
            coef = np.linalg.lstsq(basis.T, x, rcond=None)[0]
            rates[a] -= coef @ basis
            found.append(_line(rates, a, f0, float(np.hypot(*coef))))
    return rates, found


def _grid(n: int, fs: float) -> tuple:
    """The periodogram's length (``n`` zero-padded 4x, a power of two), its frequencies [Hz] and the bins in
    2 Hz (a line's neighbourhood on either side)."""
    nfft = 1 << int(np.ceil(np.log2(4 * n)))
    freqs = np.fft.rfftfreq(nfft, 1.0 / fs)
    return nfft, freqs, max(3, int(round(2.0 / freqs[1])))


def _searched_band(freqs, min_hz: float, half: int) -> np.ndarray:
    """The bins :func:`remove_vibration_lines` searches: from ``min_hz`` to below the last; none where that
    band is narrower than a line's two neighbourhoods (a log at 20 Hz above 8 Hz)."""
    band = np.where(freqs >= min_hz)[0]
    band = band[band < freqs.size - 1]
    return band if band.size >= 2 * half else band[:0]


def _line(rates, a: int, hz: float, amplitude: float, **more) -> dict:
    """The record of a line removed from row ``a`` of ``rates`` (named by its axis where there are three)."""
    return {"axis": AXES[a] if rates.shape[0] == 3 else a, "frequency_hz": hz, "amplitude": amplitude, **more}


def _refined(power, freqs, k: int) -> float:
    """The frequency of the line at bin ``k``, refined by a parabola through the log-power of its 3 bins."""
    y0, y1, y2 = np.log(power[k - 1:k + 2] + 1e-300)
    denom = y0 - 2 * y1 + y2
    shift = 0.5 * (y0 - y2) / denom if denom != 0 else 0.0
    return float(freqs[k] + np.clip(shift, -0.5, 0.5) * freqs[1])


def _basis(hz: float, t) -> np.ndarray:
    return np.vstack([np.cos(2 * np.pi * hz * t), np.sin(2 * np.pi * hz * t)])


def remove_folded_lines(rates, attitude, fs: float, below_hz: float = 8.0, max_lines: int = 4,
                        prominence: float = 30.0):
    """Remove from the gyro the lines a slow log folded into the aircraft's band (module docstring).

    Each axis' periodogram (zero-padded 4x, Hann window) between :data:`FOLDED_FLOOR_HZ` and ``below_hz`` is
    searched for narrow peaks: a local maximum standing ``prominence`` times above the median power on *each*
    side of it, both over ±2 Hz and over the :data:`_NARROW` bins just beyond its main lobe. A line lasting the
    whole record is that narrow; a sweep's or a gust's spectral bump is not, and one side alone would take the
    edge of a band that a logger low-passed (the T-REX log: nothing above 2.4 Hz) for a line. On the bench's
    flights of 60 and 300 s at 20-100 Hz the motion's peaks stood at most 16.6 times above their sides, folded
    rotor lines 18-30 000 times.

    Each line's rate amplitude is fitted by least squares, and so is that of the attitude's central
    difference at the same frequency (corrected by the difference's ``wdt / sin(wdt)``; the attitude itself
    would let a heading's drift over the flight leak in). That rate, the kinematics near hover, is the
    aircraft's motion; the rest is the sensor's. Where the sensor's share is at least half the line, that share
    is subtracted from the rate. A line's frequency is the least-squares one near its peak.

    Parameters
    ----------
    rates, attitude : ndarray, shape (3, n)
        Gyro [rad/s] and Euler angles [rad] (yaw unwrapped here).
    fs : float
        Sample rate [Hz].

    Returns
    -------
    cleaned : ndarray, shape (3, n)
    lines : list of dict
        ``axis``, ``frequency_hz``, ``amplitude`` [rad/s] (the share removed) and ``folded`` (True) of each.
    """
    rates = np.array(rates, dtype=float, copy=True)
    angles = np.unwrap(np.asarray(attitude, dtype=float), axis=1)
    n = rates.shape[1]
    if n < 64:
        return rates, []
    nfft, freqs, half = _grid(n, fs)
    top = below_hz if _searched_band(freqs, below_hz, half).size else fs / 2  # above it remove_vibration_lines
    band = np.where((freqs >= FOLDED_FLOOR_HZ) & (freqs < top))[0]
    band = band[band < freqs.size - 1]
    if band.size < 3:
        return rates, []
    t = np.arange(n) / fs
    win = np.hanning(n)
    turn = np.gradient(angles, 1.0 / fs, axis=1)  # the attitude's rate: a heading's drift leaks into no line
    found = []
    for a in range(rates.shape[0]):
        x = rates[a] - np.mean(rates[a])
        power = np.abs(np.fft.rfft(x * win, nfft)) ** 2
        inner = power[band[1:-1]]
        peaks = band[1:-1][(inner > power[band[:-2]]) & (inner >= power[band[2:]])]  # local maxima
        removed = 0
        for k in peaks[np.argsort(power[peaks])[::-1][:_CANDIDATES]]:
            if not _stands_out(power, k, half, prominence):
                continue
            hz = _least_squares_frequency(x, t, _refined(power, freqs, k), 2 * freqs[1])
            basis = _basis(hz, t)
            line = np.linalg.lstsq(basis.T, x, rcond=None)[0]
            wdt = 2 * np.pi * hz / fs  # a central difference passes a sinusoid's rate times sin(wdt) / wdt
            moving = np.linalg.lstsq(basis.T, turn[a], rcond=None)[0] * (wdt / np.sin(wdt))
            sensor = line - moving
            if np.hypot(*sensor) < 0.5 * np.hypot(*line):
                continue  # the aircraft moved so: its motion, not a sensor's line
            rates[a] -= sensor @ basis
            x = x - sensor @ basis
            found.append(_line(rates, a, hz, float(np.hypot(*sensor)), folded=True))
            removed += 1
            if removed == max_lines:
                break
        rates[a], line = _nyquist_line(rates[a], x, power, half, prominence)
        if line:
            found.append(_line(rates, a, fs / 2, line, folded=True))
    return rates, found


def _stands_out(power, k: int, half: int, prominence: float) -> bool:
    """Bin ``k`` of ``power`` stands ``prominence`` times above the median power on *each* side of its main lobe,
    both over the :data:`_NARROW` bins just beyond it and over ``half`` bins (2 Hz): a line lasting the record."""
    left, right = max(0, k - _GAP), k + _GAP + 1
    sides = (power[max(0, left - _NARROW):left], power[right:right + _NARROW],  # the cheap ones first
             power[max(0, k - half):left], power[right:k + half + 1])
    return all(side.size for side in sides) and all(power[k] >= prominence * np.median(side) for side in sides)


def _nyquist_line(rate, x, power, half: int, prominence: float) -> tuple:
    """``rate`` without a line folded onto half the sample rate (a 30 Hz rotor logged at 20 Hz: the samples
    alternate, ``B (-1)^k``), and ``|B|`` (0.0 if none): the last bin standing ``prominence`` times above the
    medians of the bins below it, over ±2 Hz and just beyond the main lobe. No aircraft moves at that
    frequency; the attitude cannot tell (its central difference passes nothing there)."""
    end = power.size - 1 - _GAP
    if end - half < 0 or power[-1] < prominence * max(np.median(power[end - half:end]),
                                                       np.median(power[end - _NARROW:end])):
        return rate, 0.0
    alternating = np.where(np.arange(x.size) % 2, -1.0, 1.0)
    b = float(alternating @ x) / x.size
    return rate - b * alternating, abs(b)


COMMAND_PROMINENCE = 10.0
"""A command's periodogram at a folded gyro line's frequency standing this many times above each side of it (the
test of :func:`remove_folded_lines` at a frequency known beforehand, not searched for: a periodogram bin of noise
stands ten times above its sides' median with a probability of 2^-10, and the peak is sought among the few independent
bins of the line's main lobe) is a line the flight controller fed back (reported as the command's)."""


def remove_fed_back_lines(rates, commands, fs: float, folded: list, prominence: float = COMMAND_PROMINENCE) -> tuple:
    """The folded lines (:func:`remove_folded_lines`' ``folded``) regressed out of the commands and, what the
    sensor's share left of them, out of the gyro: the same prefilter on input and output (module docstring).

    A loop that flies on a vibrating gyro puts the line into its commands at the line's own frequency; the log
    folds it to the same frequency as the gyro's. The aircraft answered it up there (27 Hz: a yaw gain of 13.5
    rad/s² turns a command line of 0.0075 into 0.0006 rad/s), but a model driven by the logged commands answers
    it at the folded frequency (2 Hz: 0.008 rad/s, thirteen times as much, and in another phase), and the fit bends
    its damping and a servo lag to damp an answer the aircraft never gave (the bench's autopilot, 200 Hz loop logged
    at 25 Hz: the paper aircraft's yaw damping +296 % behind a 46 ms lag; docs/method.md). Where a command stands
    out at such a line's frequency (``prominence`` times above each side of it, as :func:`remove_folded_lines` tests
    a line), the line is regressed out of that command and of its axis' gyro. A pilot's sticks carry none, and
    nothing is done: taking the frequency out of sticks and gyro regardless is not free (a sweep passing through it
    has its share there, and the regression's is not the aircraft's answer to it: on the bench's pilot flights at
    25 Hz the dampings moved by up to 6 points, the integral method's by 4).

    Returns
    -------
    rates, commands : ndarray, shape (3, n)
    lines : list of dict
        Those removed from the commands: ``"signal": "command"``, ``folded`` True, ``amplitude`` the command's.
    """
    rates = np.array(rates, dtype=float, copy=True)
    commands = np.array(commands, dtype=float, copy=True)
    n = commands.shape[1]
    if n < 64 or not folded:
        return rates, commands, []
    nfft, freqs, half = _grid(n, fs)
    t, win = np.arange(n) / fs, np.hanning(n)
    alternating = np.where(np.arange(n) % 2, -1.0, 1.0)
    found = []
    for a in range(commands.shape[0]):
        x = commands[a] - np.mean(commands[a])
        power = np.abs(np.fft.rfft(x * win, nfft)) ** 2
        inside = []
        for hz in (ln["frequency_hz"] for ln in folded if ln["axis"] == AXES[a]):
            if hz >= 0.5 * fs - freqs[1]:  # the line on half the sample rate: the samples alternate
                commands[a], b = _nyquist_line(commands[a], x, power, half, prominence)
                if b:
                    rates[a] -= float(alternating @ (rates[a] - np.mean(rates[a]))) / n * alternating
                    found.append(_line(commands, a, hz, b, folded=True, signal="command"))
                continue
            k = int(round(hz / freqs[1]))
            lo, hi = max(1, k - _GAP // 2), min(power.size - 1, k + _GAP // 2 + 1)
            if _stands_out(power, lo + int(np.argmax(power[lo:hi])), half, prominence):  # its peak in the lobe
                inside.append(hz)
                amplitude = np.hypot(*np.linalg.lstsq(_basis(hz, t).T, x, rcond=None)[0])
                found.append(_line(commands, a, hz, float(amplitude), folded=True, signal="command"))
        if inside:
            commands[a] = remove_lines(commands[a], fs, inside)
            rates[a] = remove_lines(rates[a], fs, inside)
    return rates, commands, found


def _least_squares_frequency(x, t, hz: float, width: float) -> float:
    """The frequency within ``hz`` ± ``width`` whose sinusoid explains most of ``x`` (least squares). The
    parabola through the periodogram is pulled by the motion around a line inside the motion's band (by
    0.0003 Hz at 2 Hz: a quarter turn of phase over 300 s); the fit is not."""
    from scipy.optimize import minimize_scalar

    def unexplained(f):
        basis = _basis(f, t)
        return -float(np.sum((np.linalg.lstsq(basis.T, x, rcond=None)[0] @ basis) ** 2))

    return float(minimize_scalar(unexplained, bounds=(hz - width, hz + width), method="bounded",
                                 options={"xatol": width * 1e-4}).x)


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


def remove_common_lines(rates, commands, fs: float, min_hz: float = 8.0,
                        attitude=None, faster_loop: bool = False) -> tuple[np.ndarray, np.ndarray, list]:
    """Vibration lines removed from the gyro, and from the commands where these carry lines too.

    Each axis' gyro (``rates``, (3, n)) is cleaned by :func:`remove_vibration_lines`. Where that axis'
    command (``commands``, (3, n): lat, lon, ped) has lines of its own (a flight controller feeding its
    gyro back), the lines of either are removed from both, from the raw signals in one regression, so that
    input and output see the same prefilter. A pilot's sticks have no such lines: then only the gyro is
    cleaned, exactly as :func:`remove_vibration_lines` does. With the ``attitude`` (3, n) the lines a slow
    log folded below ``min_hz`` are then taken out of the gyro by :func:`remove_folded_lines` (only the sensor's
    share: what the aircraft answered is in the attitude). Where the commands are a flight controller's from a loop
    faster than the log (``faster_loop``), those it fed back are taken out of the commands and the gyro together
    (:func:`remove_fed_back_lines`); a loop at the log's rate holds its command over each sample, and the aircraft
    felt the line there at the folded frequency: the commands keep it (the bench's autopilot at 20-25 Hz, its
    loop at the log's rate: taking the lines out of its commands left k7 +53 and +82 % on two flights).

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
    if attitude is not None:
        cleaned, commands, folded = remove_all_folded_lines(cleaned, commands, attitude, fs, min_hz, faster_loop)
        lines += folded
    return cleaned, commands, lines


def remove_all_folded_lines(rates, commands, attitude, fs: float, min_hz: float = 8.0,
                            faster_loop: bool = False) -> tuple[np.ndarray, np.ndarray, list]:
    """The lines a slow log folded below ``min_hz`` taken out of the gyro (their sensor's share,
    :func:`remove_folded_lines`) and, where the commands are a flight controller's from a loop faster than the log
    (``faster_loop``), those it fed back out of the commands and the gyro together (:func:`remove_fed_back_lines`).
    Returns the rates, the commands and the lines (the gyro's, then the commands')."""
    rates, folded = remove_folded_lines(rates, attitude, fs, min_hz)
    fed = []
    if faster_loop:
        rates, commands, fed = remove_fed_back_lines(rates, commands, fs, folded)
    return rates, commands, folded + fed
