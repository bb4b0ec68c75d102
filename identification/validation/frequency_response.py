"""Frequency-response comparison of a model and the flights, with coherence (the rotorcraft norm).

Rotorcraft system identification judges a model in the frequency domain (Tischler & Remple's CIFER): per
axis, the frequency response of the flight from its stick to its body rate is estimated from the spectra,
``H(f) = Pxy(f) / Pxx(f)`` (the H1 estimate: cross-spectrum of stick ``x`` and rate ``y`` over the stick's
auto-spectrum), with the coherence ``gamma²(f) = |Pxy|² / (Pxx Pyy)`` saying at which frequencies the stick
explains the rate linearly. Only where ``gamma² >= 0.6`` (:data:`COHERENCE_MIN`, CIFER's guideline) is the
estimate trusted; there the model's own response is laid over it and their distance measured by CIFER's
weighted cost (:func:`cifer_cost`).

The spectra are Welch estimates (``scipy.signal.welch`` and ``scipy.signal.csd``, Hann windows of
``window_s`` seconds, half overlapping, each segment's mean removed); several flights are pooled by adding
their segments' spectra, so for one flight the coherence is exactly ``scipy.signal.coherence``'s. The model's
response is that of the physics core linearised about hover at the flights' mean collective
(:func:`heli_core.linear.hover_linearisation`: eqs. 18, 21, the coupling terms, the first-order Padé servo
delay and lag of eq. 31, gains scheduled on the collective), from one stick to its own axis' rate with the
other sticks still.

Two things bias ``H`` that the model does not have. A pilot who moves the stick against gusts (closed-loop
piloting correlates the stick with the wind) pulls ``H`` towards the inverse of his own law where his
corrections dominate the stick's power, mostly below the sweeps' band; the coherence does not warn of it, for
stick and rate stay linearly related there, only not through the aircraft (on the project's windy synthetic
flights it is most of the true model's cost, docs/method.md). Sticks of other axes moved together with this
one bias a single-input estimate too (CIFER conditions on the other inputs); that one lowers the coherence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from heli_core.linear import hover_linearisation
from heli_core.params import ModelParams
from heli_core.terms import AXES, STICK_ROW

from ..errors import IdentifiabilityError
from ..flight import Flight

COHERENCE_MIN = 0.6
"""Coherence ``gamma²`` from which a frequency of the flight's estimate is trusted (CIFER's guideline)."""

WINDOW_S = 10.0
"""Default length of the Welch segments [s]: 0.1 Hz resolution, below the sweeps' lowest 0.3 Hz."""

MIN_SEGMENTS = 16
"""Fewest (half-overlapping) segments a flight is cut into: the coherence of ``n`` averages is biased towards
1 (one segment gives exactly 1), and where stick and rate are unrelated it still passes 0.6 with probability
``0.4^(n-1)`` per frequency (about 1 in 60 000 at ``n = 13`` independent averages, against 1 in 250 at 7 over
the few hundred frequencies compared); so the segments shorten on a short flight."""

MIN_RUN = 3
"""Fewest adjacent coherent frequencies kept as part of the band: a lone frequency passing the threshold in a
band of noise is chance, not response."""

PERIODS_PER_WINDOW = 2.0
"""Periods of the lowest frequency compared that a Welch segment holds (Tischler & Remple: a window of
``T`` seconds identifies down to about ``2/T`` Hz; lower bins are the trim's and the window's leakage)."""

F_MAX_HZ = 10.0
"""Highest frequency compared [Hz]: past the attitude dynamics and the servos, where rotor vibration and
gyro noise, not the stick, make the rate."""

COST_POINTS = 20
"""Frequencies of the cost (CIFER's ``n_omega``), spaced logarithmically over the coherent band."""

PHASE_WEIGHT = 0.01745
"""CIFER's weight of the squared phase error [1/deg²] against the magnitude's [1/dB²] (1 dB ~ 7.6 deg)."""

COST_GOOD = 100.0
"""A cost up to which CIFER's guidelines call an axis' fit good (Tischler & Remple: J <= 100; up to about 200
still acceptable for a single response)."""


@dataclass(frozen=True, eq=False)
class AxisFrequencyResponse:
    """The flight's and the model's response of one axis, from its stick to its rate.

    Attributes
    ----------
    axis : str
        ``"roll"``, ``"pitch"`` or ``"yaw"``.
    freq : ndarray, shape (m,)
        Frequencies [Hz] compared (from :data:`PERIODS_PER_WINDOW` periods per segment to ``f_max``).
    flight : ndarray of complex, shape (m,)
        The flight's estimate ``Pxy / Pxx`` [rad/s per unit stick].
    coherence : ndarray, shape (m,)
        ``gamma²`` of stick and rate, in [0, 1].
    model : ndarray of complex, shape (m,)
        The model's response at ``freq`` [rad/s per unit stick].
    coherent : ndarray of bool, shape (m,)
        Where ``coherence >= coherence_min`` over :data:`MIN_RUN` adjacent frequencies or more
        (:func:`coherent_band`).
    cost : float
        CIFER's weighted cost ``J`` over the coherent band (:func:`cifer_cost`); NaN with no coherent frequency.
    magnitude_error_db : float
        Mean absolute magnitude error over the coherent frequencies [dB]; NaN with none.
    phase_error_deg : float
        Mean absolute phase error over the coherent frequencies [deg]; NaN with none.
    """

    axis: str
    freq: np.ndarray
    flight: np.ndarray
    coherence: np.ndarray
    model: np.ndarray
    coherent: np.ndarray
    cost: float
    magnitude_error_db: float
    phase_error_deg: float

    @property
    def band_hz(self) -> tuple[float, float] | None:
        """Lowest and highest coherent frequency [Hz], or None when no frequency is coherent (the band may
        have gaps: :attr:`coherent` says where)."""
        if not self.coherent.any():
            return None
        f = self.freq[self.coherent]
        return float(f.min()), float(f.max())

    def to_dict(self) -> dict:
        """The axis' summary as plain values (the curves left out)."""
        band = self.band_hz
        return {"band_hz": list(band) if band else None, "coherent_points": int(self.coherent.sum()),
                "cost": self.cost, "magnitude_error_db": self.magnitude_error_db,
                "phase_error_deg": self.phase_error_deg}


@dataclass(frozen=True, eq=False)
class FrequencyComparison:
    """Per axis, the flights' and the model's frequency responses (:func:`compare_frequency_response`).

    Attributes
    ----------
    axes : dict of str to AxisFrequencyResponse
    window_s : float
        Length of the Welch segments [s].
    segments : int
        Segments averaged over all flights.
    coherence_min : float
        Coherence from which a frequency is compared.
    collective : float
        Collective stick the model was linearised at (the flights' mean).
    duration_s : float
        Flight time the spectra come from [s].
    f_min_hz, f_max_hz : float
        Lowest and highest frequency compared [Hz].
    """

    axes: dict
    window_s: float
    segments: int
    coherence_min: float
    collective: float
    duration_s: float
    f_min_hz: float
    f_max_hz: float

    def to_dict(self) -> dict:
        """Plain JSON-ready values: the settings and every axis' :meth:`AxisFrequencyResponse.to_dict`."""
        from heli_core.files import jsonable

        return jsonable({"window_s": self.window_s, "segments": self.segments,
                         "coherence_min": self.coherence_min, "collective": self.collective,
                         "duration_s": self.duration_s, "f_min_hz": self.f_min_hz, "f_max_hz": self.f_max_hz,
                         "cost_points": COST_POINTS,
                         "axes": {a: r.to_dict() for a, r in self.axes.items()}})


def segment_samples(flights, window_s: float | None = None) -> int:
    """Samples per Welch segment: ``window_s`` seconds, or :data:`WINDOW_S` shortened so that the longest
    flight gives :data:`MIN_SEGMENTS` half-overlapping segments.

    Raises
    ------
    IdentifiabilityError
        No flight long enough for a segment of at least 64 samples.
    ValueError
        A ``window_s`` that is not a positive number of seconds.
    """
    fs = flights[0].sample_rate
    longest = max(f.n for f in flights)
    if window_s is None:
        n = min(int(round(WINDOW_S * fs)), int(2 * longest // (MIN_SEGMENTS + 1)))
    elif not (isinstance(window_s, (int, float)) and 0.0 < window_s < math.inf):
        raise ValueError(f"window_s must be a positive number of seconds, got {window_s!r}")
    else:
        n = int(round(window_s * fs))
    if n < 64 or n > longest:
        raise IdentifiabilityError(
            f"a frequency response needs Welch segments of 64 samples or more within the longest flight "
            f"({longest} samples, {longest / fs:.1f} s); got segments of {n} samples")
    return n


def flight_spectra(flights, axis: int, nperseg: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Pooled Welch spectra of one axis' stick ``x`` and rate ``y`` over ``flights``.

    Parameters
    ----------
    flights : sequence of Flight
        At one sample rate; flights shorter than a segment are left out.
    axis : int
        0 roll, 1 pitch, 2 yaw.
    nperseg : int
        Samples per segment.

    Returns
    -------
    freq : ndarray, shape (m,)
        [Hz].
    pxx, pyy : ndarray, shape (m,)
        Auto-spectra of stick [1/Hz] and rate [(rad/s)²/Hz].
    pxy : ndarray of complex, shape (m,)
        Cross-spectrum [rad/s/Hz].
    segments : int
        Segments averaged (each flight's spectra weighted by its segment count).
    """
    from scipy import signal

    fs = flights[0].sample_rate
    step = nperseg - nperseg // 2
    kw = {"fs": fs, "nperseg": nperseg, "noverlap": nperseg // 2, "window": "hann", "detrend": "constant"}
    total = [0.0, 0.0, 0.0]
    count = 0
    freq = None
    for f in flights:
        if f.n < nperseg:
            continue
        x, y = f.sticks[STICK_ROW[axis]], f.rates[axis]
        k = 1 + (f.n - nperseg) // step
        freq, pxx = signal.welch(x, **kw)
        pyy = signal.welch(y, **kw)[1]
        pxy = signal.csd(x, y, **kw)[1]
        for i, s in enumerate((pxx, pyy, pxy)):
            total[i] = total[i] + k * s
        count += k
    return freq, total[0] / count, total[1] / count, total[2] / count, count


def model_frequency_response(params: ModelParams, axis: int, freq, collective: float = 0.0) -> np.ndarray:
    """The model's response from the stick of ``axis`` to its rate, linearised about hover.

    ``H(s) = C (sI - A)^-1 b`` with ``A``, ``b`` of :func:`heli_core.linear.hover_linearisation` at
    ``collective`` (eqs. 18, 21 and the Padé servo of eq. 31; coupled axes through ``A``), ``C`` picking the
    rate.

    Parameters
    ----------
    params : ModelParams
    axis : int
        0 roll, 1 pitch, 2 yaw.
    freq : array_like, shape (m,)
        Frequencies [Hz].
    collective : float
        Collective stick of the hover point.

    Returns
    -------
    ndarray of complex, shape (m,)
        [rad/s per unit stick].
    """
    lin = hover_linearisation(params, collective)
    s = 2j * np.pi * np.asarray(freq, dtype=float)
    # (sI - A)^-1 b solved per frequency: scipy.signal.freqresp goes through a transfer function, whose
    # polynomial coefficients are badly conditioned for a coupled model with servo states
    resolvent = s[:, None, None] * np.eye(lin.A.shape[0]) - lin.A
    b = np.broadcast_to(lin.Bu[:, axis], (s.size, lin.A.shape[0]))[..., None]
    return np.linalg.solve(resolvent, b)[:, lin.rate_idx[axis], 0]


def cifer_cost(freq, flight, model, coherence, coherent) -> float:
    """CIFER's weighted frequency-response cost ``J`` of a model against a flight estimate.

    ``J = 20/n Σ W_γ [(|H_m| - |H_f|)² + W_p (∠H_m - ∠H_f)²]``, magnitudes in dB, phases in degrees (the
    difference wrapped into ±180°), ``W_p`` :data:`PHASE_WEIGHT`, ``W_γ = (1.58 (1 - exp(-γ²)))²``, over
    ``n`` of the coherent frequencies nearest to :data:`COST_POINTS` logarithmically spaced ones spanning the
    coherent band (no frequency twice). ``J <= 100`` is a good fit (:data:`COST_GOOD`).

    Parameters
    ----------
    freq : ndarray, shape (m,)
        [Hz].
    flight, model : ndarray of complex, shape (m,)
    coherence : ndarray, shape (m,)
    coherent : ndarray of bool, shape (m,)

    Returns
    -------
    float
        ``J``; NaN when no frequency is coherent.
    """
    idx = np.flatnonzero(coherent)
    if idx.size == 0:
        return math.nan
    f = freq[idx]
    targets = np.geomspace(f.min(), f.max(), COST_POINTS) if f.min() < f.max() else f[:1]
    pick = np.unique(idx[np.abs(np.log(f)[None, :] - np.log(targets)[:, None]).argmin(axis=1)])
    mag = 20.0 * np.log10(np.abs(model[pick]) / np.abs(flight[pick]))
    phase = phase_difference_deg(model[pick], flight[pick])
    weight = (1.58 * (1.0 - np.exp(-coherence[pick]))) ** 2
    return float(20.0 / pick.size * np.sum(weight * (mag ** 2 + PHASE_WEIGHT * phase ** 2)))


def coherent_band(coherence, coherence_min: float = COHERENCE_MIN) -> np.ndarray:
    """Where ``coherence >= coherence_min`` over at least :data:`MIN_RUN` adjacent frequencies (bool mask)."""
    from scipy import ndimage

    labels, _ = ndimage.label(np.asarray(coherence) >= coherence_min)
    sizes = np.bincount(labels.ravel())
    return (labels > 0) & (sizes[labels] >= MIN_RUN)


def phase_difference_deg(a, b) -> np.ndarray:
    """Phase of ``a`` less that of ``b`` [deg], wrapped into (-180, 180]."""
    return np.degrees(np.angle(np.asarray(a) * np.conj(b)))


def compare_frequency_response(params: ModelParams, flights, window_s: float | None = None,
                               coherence_min: float = COHERENCE_MIN, f_max: float = F_MAX_HZ,
                               axes=AXES) -> FrequencyComparison:
    """Per axis, the flights' stick-to-rate frequency response with its coherence, and the model's over it.

    Parameters
    ----------
    params : ModelParams
        The model (its servo delay and lag included through eq. 31's Padé form).
    flights : Flight or sequence of Flight
        The flights as the model was fitted on them (inputs aligned, vibration removed or prefiltered), at one
        sample rate; their spectra are pooled.
    window_s : float, optional
        Welch segment length [s]; default :data:`WINDOW_S`, shorter on a short flight (:func:`segment_samples`).
    coherence_min : float
        Coherence from which a frequency is compared, in (0, 1).
    f_max : float
        Highest frequency compared [Hz] (capped at Nyquist); the lowest is :data:`PERIODS_PER_WINDOW` periods
        per segment.
    axes : sequence of str
        Axes compared.

    Returns
    -------
    FrequencyComparison

    Raises
    ------
    ValueError
        No flights, flights at different sample rates, or a ``coherence_min`` outside (0, 1).
    IdentifiabilityError
        Flights too short for a segment of 64 samples.
    """
    flights = [flights] if isinstance(flights, Flight) else list(flights)
    if not flights:
        raise ValueError("compare_frequency_response needs at least one flight, got none")
    fs = flights[0].sample_rate
    if any(not math.isclose(f.sample_rate, fs, rel_tol=1e-3) for f in flights):
        raise ValueError("flights must share one sample rate to pool their spectra; got "
                         + ", ".join(f"{f.sample_rate:g}" for f in flights) + " Hz")
    if not 0.0 < coherence_min < 1.0:
        raise ValueError(f"coherence_min must lie in (0, 1), got {coherence_min!r}")
    nperseg = segment_samples(flights, window_s)
    f_min, f_max = PERIODS_PER_WINDOW * fs / nperseg, min(float(f_max), fs / 2)
    collective = float(np.mean(np.concatenate([f.sticks[2] for f in flights])))
    out, segments = {}, 0
    for name in axes:
        a = AXES.index(name)
        freq, pxx, pyy, pxy, segments = flight_spectra(flights, a, nperseg)
        keep = (freq >= f_min - 1e-9) & (freq <= f_max)
        freq, pxx, pyy, pxy = freq[keep], pxx[keep], pyy[keep], pxy[keep]
        with np.errstate(invalid="ignore", divide="ignore"):
            coherence = np.nan_to_num(np.abs(pxy) ** 2 / (pxx * pyy))
            estimate = pxy / pxx
        model = model_frequency_response(params, a, freq, collective)
        coherent = coherent_band(coherence, coherence_min) & np.isfinite(estimate) & (estimate != 0)
        out[name] = _axis_result(name, freq, estimate, coherence, model, coherent)
    return FrequencyComparison(out, round(nperseg / fs, 6), segments, float(coherence_min), collective,
                               float(sum(f.duration for f in flights)), f_min, f_max)


def _axis_result(name, freq, estimate, coherence, model, coherent) -> AxisFrequencyResponse:
    """One axis' :class:`AxisFrequencyResponse` with its errors over the coherent frequencies."""
    if coherent.any():
        mag = np.abs(20.0 * np.log10(np.abs(model[coherent]) / np.abs(estimate[coherent])))
        phase = np.abs(phase_difference_deg(model[coherent], estimate[coherent]))
        mag_err, phase_err = float(mag.mean()), float(phase.mean())
    else:
        mag_err = phase_err = math.nan
    cost = cifer_cost(freq, estimate, model, coherence, coherent)
    return AxisFrequencyResponse(name, freq, estimate, coherence, model, coherent, cost, mag_err, phase_err)
