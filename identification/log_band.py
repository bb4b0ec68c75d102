"""The frequency band a log carries: where the rates' spectrum shows the log was low-pass filtered.

A gyro logged as it was measured has a noise floor: its spectrum flattens out, up to the
Nyquist frequency, some 20-50 dB below the flight's motion. A log that was low-pass
filtered before it was written (the T-REX 550 hover of ``../shared/fixtures/logs``:
inputs and outputs through a 5th-order filter near 2.2 Hz by its authors) has none: its
spectrum keeps falling, 60 dB and more below the motion at the top of the band. Above
the filter's corner such a log holds nothing: a mode faster than it cannot be identified,
the one-step prediction error is near zero for any model (the next sample of a smooth
signal is its last one) and the white-noise model of the gyro finds no noise.
:func:`log_band` finds the band from the spectrum (Welch's method, ``scipy.signal.welch``)
and says so; the reports name it instead of fitting what is not there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

FILTERED_DB = 60.0
"""A log whose rate spectrum at the top of its band (60-90 % of Nyquist) lies this far below its level at
0.1-1 Hz, with no floor, was low-pass filtered before it was written [dB]."""

EDGE_DB = 20.0
"""The band's edge: the frequency above which the spectrum stays this far below its 0.1-1 Hz level [dB]."""

LOW_BAND_HZ = (0.1, 1.0)
"""Where the flight's motion sets the reference level [Hz]."""


@dataclass(frozen=True)
class LogBand:
    """What the rates' spectrum says about the band of a log.

    Attributes
    ----------
    filtered : bool
        The spectrum has no noise floor: it falls :data:`FILTERED_DB` or more below its 0.1-1 Hz level.
    edge_hz : float
        Frequency above which every axis' spectrum stays :data:`EDGE_DB` below its 0.1-1 Hz level [Hz]
        (the Nyquist frequency when it never does).
    depth_db : float
        The least drop from the 0.1-1 Hz level to the top of the band over the axes [dB].
    nyquist_hz : float
    """

    filtered: bool
    edge_hz: float
    depth_db: float
    nyquist_hz: float

    def describe(self) -> str:
        """One sentence for the reports."""
        if not self.filtered:
            return (f"the rates' spectrum has a noise floor {self.depth_db:.0f} dB below the motion up to "
                    f"{self.nyquist_hz:g} Hz: the log is as measured")
        return (f"the rates carry nothing above about {self.edge_hz:.1f} Hz: their spectrum falls "
                f"{self.depth_db:.0f} dB below the motion by {self.nyquist_hz:g} Hz with no noise floor, so the "
                "log was low-pass filtered before it was written; a mode faster than that cannot be identified "
                "from it, and its one-step prediction R² says nothing (judge the model by its 0.5 s-ahead "
                "prediction, heli diagnose)")


def log_band(flight) -> LogBand | None:
    """The band of ``flight``'s rates (:class:`LogBand`), or None for a flight shorter than 20 s or sampled
    below 4 Hz."""
    fs = float(flight.sample_rate)
    if flight.duration < 20.0 or fs < 4.0:
        return None
    rates = np.asarray(flight.rates, dtype=float)
    nper = int(min(rates.shape[1], round(10.0 * fs)))
    freq, psd = signal.welch(rates, fs=fs, nperseg=nper, detrend="linear", axis=-1)
    nyq = fs / 2.0
    low = (freq >= LOW_BAND_HZ[0]) & (freq <= LOW_BAND_HZ[1])
    top = (freq >= 0.6 * nyq) & (freq <= 0.9 * nyq)
    if not low.any() or not top.any():
        return None
    depths, edges = [], []
    for row in psd:
        level = float(np.median(row[low]))
        if not level > 0.0:
            continue
        depths.append(10.0 * np.log10(level / max(float(np.median(row[top])), 1e-300)))
        above = row > level * 10.0 ** (-EDGE_DB / 10.0)
        last = np.nonzero(above)[0]
        edges.append(float(freq[last[-1] + 1]) if last.size and last[-1] + 1 < freq.size else nyq)
    if not depths:
        return None
    depth = float(min(depths))
    return LogBand(filtered=depth >= FILTERED_DB, edge_hz=float(max(edges)), depth_db=depth, nyquist_hz=nyq)
