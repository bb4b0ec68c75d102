"""The aircraft's sensors identified from its flights: gyro white noise, vibration lines, attitude noise.

The noise of a sampled signal is read from its third difference: for white noise of standard deviation
σ the third difference has variance C(6, 3)·σ² = 20σ², while the motion of a rotorcraft sampled at tens
of Hz contributes almost nothing to it (its third derivative times dt³). A robust scale (1.4826 times the
median absolute deviation) keeps the estimate away from a few spikes. The gyros are read after their
vibration lines are removed by regression on their sinusoids (:func:`identification.vibration.remove_vibration_lines`,
and below 8 Hz the lines a slow log folded there, :func:`identification.vibration.remove_folded_lines`);
the lines themselves are kept, with their frequency as logged and their amplitude. Over several flights the
levels are the median of the flights'; the lines those found in any flight, each at its largest amplitude.

On the bench's flights (``identification.bench.cells``: gyro noise 0.01 and 0.03 rad/s, attitude noise 0.003 rad,
lines at 27, 30, 40 and 41.5 Hz) the levels come out within 3 % and every line within 0.1 Hz and 0.001 rad/s
(``tests/test_sensors.py``).
"""

from __future__ import annotations

import numpy as np

from heli_core.sensors import GyroLine, SensorModel
from heli_core.terms import AXES

from .flight import Flight
from .vibration import remove_folded_lines, remove_vibration_lines

DIFFERENCE_ORDER = 3
"""Order of the difference the white-noise level is read from."""
_GAIN = float(np.sqrt(20.0))  # std of the third difference of unit white noise: sqrt(C(6, 3))


def white_noise_level(x) -> np.ndarray:
    """Standard deviation of the white noise in each row of ``x`` (shape (m, n) or (n,)), from its third
    difference with a robust scale (module docstring)."""
    x = np.atleast_2d(np.asarray(x, dtype=float))
    d = np.diff(x, DIFFERENCE_ORDER, axis=1)
    mad = np.median(np.abs(d - np.median(d, axis=1, keepdims=True)), axis=1)
    return 1.4826 * mad / _GAIN


def identify_sensors(flights, min_hz: float = 8.0) -> SensorModel:
    """The :class:`~heli_core.sensors.SensorModel` of one flight or several (module docstring).

    Parameters
    ----------
    flights : Flight or sequence of Flight
    min_hz : float
        Lowest frequency searched for vibration lines [Hz].
    """
    flights = [flights] if isinstance(flights, Flight) else list(flights)
    if not flights:
        raise ValueError("identify_sensors needs at least one flight")
    gyro, att, lines = [], [], {}
    for f in flights:
        cleaned, found = remove_vibration_lines(f.rates, f.sample_rate, min_hz)
        cleaned, folded = remove_folded_lines(cleaned, f.attitude, f.sample_rate, min_hz)
        found = found + folded
        gyro.append(white_noise_level(cleaned))
        att.append(white_noise_level(np.unwrap(f.attitude, axis=1)))  # yaw across +-pi is not noise
        for line in found:
            key = (line["axis"], round(line["frequency_hz"], 1))
            if key not in lines or line["amplitude"] > lines[key].amplitude:
                lines[key] = GyroLine(line["axis"], float(line["frequency_hz"]), float(line["amplitude"]))
    ordered = sorted(lines.values(), key=lambda ln: (AXES.index(ln.axis), ln.frequency_hz))
    return SensorModel(tuple(np.median(gyro, axis=0)), tuple(np.median(att, axis=0)), tuple(ordered))
