"""Classic residual tests: where a model and a flight disagree.

A model that captures the dynamics leaves a residual that is white and
uncorrelated with every past input (Ljung, *System Identification*, 2nd ed.,
Section 16.6). The tests here, applied per axis by :mod:`identification.diagnosis.heldout_diagnoser`
to the forward-simulation residual (the paper's validation, Section 3.2) and to
the equation error of the integral method (eqs. 32-40):

* **whiteness**: normalised autocorrelation ρ_εε(k), k = 1..M, against the
  bound ±z/√N, and the Ljung–Box statistic Q = N(N+2) Σ ρ²(k)/(N-k) with its
  χ²(M) p-value;
* **cross-correlation** with every input and state at lags -M..M:
  ρ_εu(k) = corr(ε(t+k), u(t)). k > 0 (the signal leads the residual) points
  at missing dynamics, e.g. a delay; k < 0 (the residual leads the signal) at
  feedback — a pilot reacting to what the model missed. The bound accounts for
  the colour of both series (Bartlett's formula, var ρ ≈ Σ_j ρ_εε(j) ρ_uu(j) / N);
* **frequency band**: the share of the residual's power (Welch) per band and
  its ratio to the measured signal's power in that band;
* **time windows**: the windows holding the largest squared error.

Everything is vectorised with FFTs; inputs are (n,) or (m, n) arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal, stats

CONFIDENCE = 0.99
"""Two-sided confidence level of the correlation bounds."""

BANDS_HZ: tuple = ((0.0, 0.3), (0.3, 1.0), (1.0, 3.0), (3.0, 8.0))
"""Frequency bands of the error-concentration report [Hz]: slow drift / wind, pilot hold, sweeps, fast."""


def _z(confidence: float = CONFIDENCE) -> float:
    return float(stats.norm.ppf(0.5 + confidence / 2.0))


def _normalised(x) -> np.ndarray:
    x = np.atleast_2d(np.asarray(x, dtype=float))
    x = x - x.mean(axis=-1, keepdims=True)
    sd = x.std(axis=-1, keepdims=True)
    return x / np.where(sd > 0, sd, 1.0)


def correlations(x, y, max_lag: int) -> np.ndarray:
    """Normalised cross-correlations ``corr(x(t+k), y_i(t))`` for k = -max_lag..max_lag.

    Parameters
    ----------
    x : array_like, shape (n,)
        The residual.
    y : array_like, shape (m, n) or (n,)
        Signals to correlate with (inputs, states, or ``x`` itself).
    max_lag : int
        Largest lag [samples].

    Returns
    -------
    ndarray, shape (m, 2*max_lag + 1)
        Biased estimates (divided by n), as in Ljung's tests; lag k at column
        ``k + max_lag``. A constant signal correlates 0.
    """
    xs = _normalised(x)[0]
    ys = _normalised(y)
    n = xs.size
    if not 0 <= max_lag < n:
        raise ValueError(f"max_lag must be in [0, {n - 1}] for {n} samples, got {max_lag}")
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    fx = np.fft.rfft(xs, nfft)
    fy = np.fft.rfft(ys, nfft, axis=-1)
    c = np.fft.irfft(fx[None, :] * np.conj(fy), nfft, axis=-1) / n  # c[k] = sum x(t+k) y(t) / n
    return np.concatenate([c[:, nfft - max_lag:], c[:, : max_lag + 1]], axis=1)


@dataclass(frozen=True)
class Whiteness:
    """Autocorrelation test of one residual.

    Attributes
    ----------
    lags : ndarray (M,)
        Lags 1..M [samples].
    rho : ndarray (M,)
        Normalised autocorrelation at those lags.
    bound : float
        ±bound for a white residual at :data:`CONFIDENCE`.
    outside : float
        Share of lags with |ρ| beyond the bound.
    q : float
        Ljung–Box statistic.
    p_value : float
        χ²(M) p-value of ``q`` (small: not white).
    """

    lags: np.ndarray
    rho: np.ndarray
    bound: float
    outside: float
    q: float
    p_value: float

    @property
    def white(self) -> bool:
        """True when the Ljung–Box test does not reject whiteness at 1 - CONFIDENCE."""
        return self.p_value > 1.0 - CONFIDENCE

    def to_dict(self) -> dict:
        return {"bound": self.bound, "share_outside_bound": self.outside, "ljung_box_q": self.q,
                "p_value": self.p_value, "white": self.white, "max_abs_rho": float(np.abs(self.rho).max()),
                "lag_of_max": int(self.lags[int(np.argmax(np.abs(self.rho)))])}


def whiteness(residual, max_lag: int) -> Whiteness:
    """Whiteness test of a residual: autocorrelation with bounds and Ljung–Box.

    Parameters
    ----------
    residual : array_like, shape (n,)
    max_lag : int
        Number of lags M tested [samples].
    """
    e = np.asarray(residual, dtype=float)
    n = e.size
    rho = correlations(e, e, max_lag)[0, max_lag + 1:]
    k = np.arange(1, max_lag + 1)
    q = float(n * (n + 2) * np.sum(rho**2 / (n - k)))
    bound = _z() / np.sqrt(n)
    return Whiteness(k, rho, float(bound), float(np.mean(np.abs(rho) > bound)), q, float(stats.chi2.sf(q, max_lag)))


@dataclass(frozen=True)
class CrossCorrelation:
    """Cross-correlation test of one residual against named signals.

    Attributes
    ----------
    names : tuple of str
    lags : ndarray (2M+1,)
        Lags -M..M [samples]; k > 0: the signal leads the residual.
    rho : ndarray (m, 2M+1)
    bounds : ndarray (m,)
        ±bound per signal (Bartlett's formula with both autocorrelations).
    """

    names: tuple
    lags: np.ndarray
    rho: np.ndarray
    bounds: np.ndarray

    def summary(self, dt: float) -> dict:
        """Per signal: the largest |ρ| at lags >= 0 and < 0, their lags [s], and whether they cross the bound."""
        out = {}
        for i, name in enumerate(self.names):
            r = self.rho[i]
            row = {"bound": float(self.bounds[i])}
            for side, m in (("signal_leads", self.lags >= 0), ("residual_leads", self.lags < 0)):
                j = int(np.argmax(np.abs(np.where(m, r, 0.0))))
                row[side] = {"rho": float(r[j]), "lag_s": float(self.lags[j] * dt),
                             "significant": bool(abs(r[j]) > self.bounds[i])}
            out[name] = row
        return out

    def significant(self) -> list[str]:
        """Signals correlated beyond their bound at some lag."""
        return [n for i, n in enumerate(self.names) if np.any(np.abs(self.rho[i]) > self.bounds[i])]


def cross_correlation(residual, signals: dict, max_lag: int) -> CrossCorrelation:
    """Cross-correlate a residual with named signals at lags -max_lag..max_lag.

    Parameters
    ----------
    residual : array_like, shape (n,)
    signals : dict of str to array_like (n,)
        Inputs and states, e.g. ``{"lat": ..., "p": ...}``.
    max_lag : int
        Largest lag [samples].
    """
    names = tuple(signals)
    e = np.asarray(residual, dtype=float)
    y = np.array([np.asarray(signals[k], dtype=float) for k in names])
    if y.shape[-1] != e.size:
        raise ValueError(f"signals must have {e.size} samples like the residual, got {y.shape[-1]}")
    rho = correlations(e, y, max_lag)
    # Bartlett: var(rho_xy(k)) ~ sum_j rho_xx(j) rho_yy(j) / n, for uncorrelated x and y
    acf_e = correlations(e, e, max_lag)[0]
    acf_y = np.array([correlations(row, row, max_lag)[0] for row in y])
    var = np.clip((acf_y * acf_e[None, :]).sum(axis=1), 1.0, None) / e.size
    return CrossCorrelation(names, np.arange(-max_lag, max_lag + 1), rho, _z() * np.sqrt(var))


def band_shares(residual, measured, fs: float, bands=BANDS_HZ) -> list[dict]:
    """Where in frequency a residual's power lies.

    Parameters
    ----------
    residual, measured : array_like, shape (n,)
        Residual and the measured signal [any unit, the same for both].
    fs : float
        Sample rate [Hz].
    bands : sequence of (float, float)
        Band edges [Hz].

    Returns
    -------
    list of dict
        Per band: ``band_hz``, ``error_share`` (of the residual's power),
        ``error_to_signal`` (residual power / measured power in the band).
    """
    e = np.asarray(residual, dtype=float)
    m = np.asarray(measured, dtype=float)
    nper = int(min(e.size, max(64, round(20.0 * fs))))
    f, pe = signal.welch(e, fs=fs, nperseg=nper)
    _, pm = signal.welch(m, fs=fs, nperseg=nper)
    total = pe.sum() or 1.0
    out = []
    for lo, hi in bands:
        sel = (f >= lo) & (f < hi)
        pm_b = pm[sel].sum()
        out.append({"band_hz": [lo, hi], "error_share": float(pe[sel].sum() / total),
                    "error_to_signal": float(pe[sel].sum() / pm_b) if pm_b > 0 else None})
    return out


def spectrum(x, fs: float):
    """Welch power spectral density (frequencies [Hz], PSD [unit²/Hz]) with 20 s segments."""
    x = np.asarray(x, dtype=float)
    return signal.welch(x, fs=fs, nperseg=int(min(x.size, max(64, round(20.0 * fs)))))
