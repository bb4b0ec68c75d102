"""Preprocessing of flights before identification (Section 3.1).

The paper passes the measured rates through a finite-impulse-response low-pass
filter with pass band edge 4 Hz and stop band edge 8 Hz to remove airframe
vibration (Fig. 8). We design that filter with :func:`scipy.signal.kaiserord`
/ :func:`scipy.signal.firwin` and apply it forwards and backwards
(:func:`scipy.signal.filtfilt`), so it has zero phase and does not shift the
response against the command (see :func:`zero_phase_lowpass`). It is applied to the rates *and* the sticks, so
that any linear term of eqs. (18)/(21) holds between the filtered signals
exactly as it held between the raw ones.

A log whose input column lags the response (found by the alignment search of ``delay="auto"`` or by the
diagnosis) is aligned before a model sees it by advancing its sticks (:func:`shift_inputs`).
"""

from __future__ import annotations

from functools import lru_cache
from types import MappingProxyType

import numpy as np
from scipy import fft as sp_fft
from scipy import signal

from heli_core.terms import INPUT_FOR_AXIS, STICK_ROW

from .errors import FlightLogError
from .flight import Flight
from .vibration import remove_all_folded_lines

DEFAULT_PASS_HZ = 4.0
DEFAULT_STOP_HZ = 8.0
DEFAULT_ATTENUATION_DB = 40.0


@lru_cache(maxsize=32)
def fir_lowpass(fs: float, pass_hz: float = DEFAULT_PASS_HZ, stop_hz: float = DEFAULT_STOP_HZ,
                attenuation_db: float = DEFAULT_ATTENUATION_DB) -> np.ndarray:
    """Taps of a linear-phase FIR low-pass (Kaiser window) meeting the band edges.

    Parameters
    ----------
    fs : float
        Sample rate [Hz].
    pass_hz, stop_hz : float
        Pass-band and stop-band edges [Hz] (paper: 4 and 8 Hz).
    attenuation_db : float
        Stop-band attenuation of one pass [dB] (filtfilt doubles it).
    """
    nyq = 0.5 * fs
    if not 0 < pass_hz < stop_hz:
        raise ValueError(f"need 0 < pass_hz < stop_hz, got {pass_hz} and {stop_hz}")
    if stop_hz >= nyq:  # a flight logged too slowly for the paper's prefilter (Section 3.1)
        raise FlightLogError(
            f"the flight is sampled at {fs:.3g} Hz; the {pass_hz:g}/{stop_hz:g} Hz prefilter needs more than "
            f"{2 * stop_hz:g} Hz (its stop band must lie below the Nyquist frequency {nyq:.3g} Hz): log faster "
            "(50-100 Hz resolves the attitude dynamics), or identify without the prefilter (--no-filter)")
    numtaps, beta = signal.kaiserord(attenuation_db, (stop_hz - pass_hz) / nyq)
    numtaps |= 1  # odd length: a type I filter
    return signal.firwin(numtaps, 0.5 * (pass_hz + stop_hz), window=("kaiser", beta), fs=fs)


def zero_phase_lowpass(values: np.ndarray, fs: float, pass_hz: float = DEFAULT_PASS_HZ,
                       stop_hz: float = DEFAULT_STOP_HZ) -> np.ndarray:
    """Zero-phase FIR low-pass of ``values`` (shape (..., n)) along the last axis."""
    values = np.asarray(values, dtype=float)
    rows = values.reshape(int(np.prod(values.shape[:-1])), values.shape[-1])
    return _zero_phase_rows([rows], float(fs), float(pass_hz), float(stop_hz)).reshape(values.shape)


def _zero_phase_rows(parts, fs: float, pass_hz: float, stop_hz: float) -> np.ndarray:
    """Zero-phase low-pass of the rows of the 2-D arrays ``parts`` (same length n), stacked (rows, n).

    Forward-backward FIR filtering is one convolution with the symmetric kernel
    taps * reversed(taps), with odd reflection at both ends as
    scipy.signal.filtfilt pads by default. The convolution is done by FFT in
    overlap-save blocks of a few kernel lengths, all blocks of all rows in one
    batched transform (single-threaded): as fast as one long FFT per row, with
    a working set that stays in cache.
    """
    n = parts[0].shape[-1]
    n_rows = sum(p.shape[0] for p in parts)
    if n == 0:
        return np.empty((n_rows, 0))
    kernel = _zero_phase_kernel(fs, pass_hz, stop_hz)
    K = kernel.size
    half = K // 2
    pad = max(min(half, n - 1), 0)
    lead = half - pad  # zeros beyond the reflection when the signal is shorter than the kernel
    nfft = _block_length(K, n)
    step = nfft - K + 1  # outputs per block
    n_blocks = -(-n // step)
    # extended signal: zeros, odd reflection, signal, odd reflection, zeros up to a whole block
    ext = np.empty((n_rows, n_blocks * step + K - 1))
    ext[:, :lead] = 0.0
    ext[:, lead + pad + n + pad :] = 0.0
    r = 0
    for part in parts:
        rows = slice(r, r + part.shape[0])
        ext[rows, lead + pad : lead + pad + n] = part
        if pad:
            np.subtract(2 * part[:, :1], part[:, pad:0:-1], out=ext[rows, lead : lead + pad])
            np.subtract(2 * part[:, -1:], part[:, -2 : -pad - 2 : -1], out=ext[rows, lead + pad + n : lead + 2 * pad + n])
        r += part.shape[0]
    blocks = np.lib.stride_tricks.as_strided(ext, shape=(n_rows, n_blocks, nfft),
                                             strides=(ext.strides[0], step * ext.strides[1], ext.strides[1]),
                                             writeable=False)
    spec = sp_fft.rfft(blocks, axis=-1, workers=1)
    spec *= _kernel_spectrum(fs, pass_hz, stop_hz, nfft)
    conv = sp_fft.irfft(spec, nfft, axis=-1, workers=1, overwrite_x=True)  # valid from index K-1 on
    out = np.empty((n_rows, n))
    whole = n // step
    out[:, : whole * step].reshape(n_rows, whole, step)[...] = conv[:, :whole, K - 1 :]
    if whole < n_blocks:
        out[:, whole * step :] = conv[:, whole, K - 1 : K - 1 + n - whole * step]
    return out


def _block_length(kernel_size: int, n: int) -> int:
    """FFT length of the overlap-save blocks: a power of two near 8 kernel lengths, or one block for short signals."""
    whole = sp_fft.next_fast_len(n + kernel_size - 1, real=True)
    return min(1 << int(np.ceil(np.log2(8 * kernel_size))), whole)


@lru_cache(maxsize=32)
def _zero_phase_kernel(fs: float, pass_hz: float, stop_hz: float) -> np.ndarray:
    taps = fir_lowpass(fs, pass_hz, stop_hz)
    k = np.convolve(taps, taps[::-1])
    k.setflags(write=False)
    return k


@lru_cache(maxsize=32)
def _kernel_spectrum(fs: float, pass_hz: float, stop_hz: float, nfft: int) -> np.ndarray:
    spec = sp_fft.rfft(_zero_phase_kernel(fs, pass_hz, stop_hz), nfft)
    spec.setflags(write=False)
    return spec


def lowpass_flight(flight: Flight, pass_hz: float = DEFAULT_PASS_HZ, stop_hz: float = DEFAULT_STOP_HZ) -> Flight:
    """A copy of ``flight`` with rates and sticks low-pass filtered (zero phase), Section 3.1.

    The attitude is left as measured (it is compared after the 10 s detrend).
    """
    both = _zero_phase_rows([flight.rates, flight.sticks], float(flight.sample_rate), float(pass_hz), float(stop_hz))
    meta = {**flight.metadata, "prefilter": {"type": "FIR zero-phase (Kaiser, filtfilt)", "pass_hz": pass_hz,
                                             "stop_hz": stop_hz, "taps": int(fir_lowpass(flight.sample_rate, pass_hz, stop_hz).size)}}
    sticks = np.clip(both[3:], -1.0, 1.0, out=both[3:])
    return Flight(flight.time, both[:3], flight.attitude, sticks, MappingProxyType(meta), flight.extra)


def without_folded_lines(flight: Flight) -> tuple[Flight, list]:
    """``flight`` with the sensor share of the vibration lines a slow log folded into the aircraft's band taken
    out of its gyro (:func:`identification.vibration.remove_folded_lines`; no low-pass can remove them), and,
    where the sticks are a flight controller's commands from a loop faster than the log, those it fed back into them
    out of both (:func:`identification.vibration.remove_fed_back_lines`), and those lines: ``(flight, [])`` itself
    where there are none."""
    from .validation.fit_warnings import loop_ticks  # it imports the likelihood's package, which imports this module

    rows = list(STICK_ROW)
    rates, commands, found = remove_all_folded_lines(flight.rates, flight.sticks[rows], flight.attitude,
                                                     flight.sample_rate, faster_loop=loop_ticks(flight) > 1)
    if not found:
        return flight, []
    sticks = flight.sticks
    if any(ln.get("signal") == "command" for ln in found):
        sticks = np.array(flight.sticks, dtype=float, copy=True)
        sticks[rows] = commands
    meta = MappingProxyType({**flight.metadata, "vibration_lines": found})
    return Flight(flight.time, rates, flight.attitude, sticks, meta, flight.extra), found


def shift_inputs(flight: Flight, shifts) -> Flight:
    """Shift the cyclic and pedal stick columns of a flight in time.

    Parameters
    ----------
    flight : Flight
    shifts : sequence of 3 float
        Per axis (roll, pitch, yaw: sticks lat, lon, ped) [s]. Positive ``s``
        delays the stick (the result holds ``u(t - s)``), negative advances it
        (``u(t + |s|)``). Values between samples are interpolated linearly;
        beyond the ends the first or last value is held.

    Returns
    -------
    Flight
        The same flight with the shifted sticks (the collective is unchanged);
        ``metadata["input_shift_s"]`` records the shifts.

    Raises
    ------
    ValueError
        ``shifts`` is not three finite numbers.
    """
    s = np.asarray(shifts, dtype=float)
    if s.shape != (3,) or not np.all(np.isfinite(s)):
        raise ValueError(f"shifts must be 3 finite seconds (roll, pitch, yaw), got {shifts!r}")
    if not s.any():
        return flight
    sticks = np.array(flight.sticks)
    for a, name in enumerate(INPUT_FOR_AXIS):
        if s[a] != 0.0:
            i = ("lat", "lon", "col", "ped").index(name)
            sticks[i] = np.interp(flight.time - s[a], flight.time, flight.sticks[i])
    sticks.setflags(write=False)
    meta = dict(flight.metadata)
    before = np.asarray(meta.get("input_shift_s", (0.0, 0.0, 0.0)), dtype=float)
    meta["input_shift_s"] = [float(v) for v in before + s]
    # the flight was validated at the edge; interpolation inside the stick range keeps it valid
    return Flight(flight.time, flight.rates, flight.attitude, sticks, MappingProxyType(meta), flight.extra)
