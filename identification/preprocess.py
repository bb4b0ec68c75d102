"""Preprocessing of flights before identification (Section 3.1).

The paper passes the measured rates through a finite-impulse-response low-pass
filter with pass band edge 4 Hz and stop band edge 8 Hz to remove airframe
vibration (Fig. 8). We design that filter with :func:`scipy.signal.kaiserord`
/ :func:`scipy.signal.firwin` and apply it forwards and backwards
(:func:`scipy.signal.filtfilt`), so it has zero phase and does not shift the
response against the command (see :func:`zero_phase_lowpass`). It is applied to the rates *and* the sticks, so
that any linear term of eqs. (18)/(21) holds between the filtered signals
exactly as it held between the raw ones.
"""

from __future__ import annotations

from functools import lru_cache
from types import MappingProxyType

import numpy as np
from scipy import fft as sp_fft
from scipy import signal

from .flight import Flight

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
    if stop_hz >= nyq:
        raise ValueError(f"stop band edge {stop_hz} Hz must lie below the Nyquist frequency {nyq} Hz")
    numtaps, beta = signal.kaiserord(attenuation_db, (stop_hz - pass_hz) / nyq)
    numtaps |= 1  # odd length: a type I filter
    return signal.firwin(numtaps, 0.5 * (pass_hz + stop_hz), window=("kaiser", beta), fs=fs)


def zero_phase_lowpass(values: np.ndarray, fs: float, pass_hz: float = DEFAULT_PASS_HZ,
                       stop_hz: float = DEFAULT_STOP_HZ) -> np.ndarray:
    """Zero-phase FIR low-pass of ``values`` (shape (..., n)) along the last axis."""
    values = np.asarray(values, dtype=float)
    n = values.shape[-1]
    kernel = _zero_phase_kernel(float(fs), float(pass_hz), float(stop_hz))
    # Forward-backward FIR filtering is one convolution with the symmetric kernel
    # taps * reversed(taps), done here by FFT on all rows at once (both cores),
    # with odd reflection at both ends as scipy.signal.filtfilt pads by default.
    pad = min(kernel.size // 2, n - 1)
    first, last = values[..., :1], values[..., -1:]
    head = 2 * first - values[..., pad:0:-1]
    tail = 2 * last - values[..., -2 : -pad - 2 : -1]
    ext = np.concatenate([head, values, tail], axis=-1)
    nfft = sp_fft.next_fast_len(ext.shape[-1] + kernel.size - 1, real=True)
    spec = sp_fft.rfft(ext, nfft, axis=-1, workers=-1) * _kernel_spectrum(kernel.tobytes(), nfft)
    full = sp_fft.irfft(spec, nfft, axis=-1, workers=-1)
    start = kernel.size // 2 + pad
    return full[..., start : start + n]


@lru_cache(maxsize=32)
def _zero_phase_kernel(fs: float, pass_hz: float, stop_hz: float) -> np.ndarray:
    taps = fir_lowpass(fs, pass_hz, stop_hz)
    k = np.convolve(taps, taps[::-1])
    k.setflags(write=False)
    return k


@lru_cache(maxsize=32)
def _kernel_spectrum(kernel_bytes: bytes, nfft: int) -> np.ndarray:
    return sp_fft.rfft(np.frombuffer(kernel_bytes, dtype=float), nfft)


def lowpass_flight(flight: Flight, pass_hz: float = DEFAULT_PASS_HZ, stop_hz: float = DEFAULT_STOP_HZ) -> Flight:
    """A copy of ``flight`` with rates and sticks low-pass filtered (zero phase), Section 3.1.

    The attitude is left as measured (it is compared after the 10 s detrend).
    """
    both = zero_phase_lowpass(np.vstack([flight.rates, flight.sticks]), flight.sample_rate, pass_hz, stop_hz)
    meta = {**flight.metadata, "prefilter": {"type": "FIR zero-phase (Kaiser, filtfilt)", "pass_hz": pass_hz,
                                             "stop_hz": stop_hz, "taps": int(fir_lowpass(flight.sample_rate, pass_hz, stop_hz).size)}}
    sticks = np.clip(both[3:], -1.0, 1.0)
    return Flight(flight.time, both[:3], flight.attitude, sticks, MappingProxyType(meta), flight.extra)
