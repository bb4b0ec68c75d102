"""Extended Kalman filter parameter estimation, the paper's EKF baseline (Sections 2.6, 3.6).

The decoupled model (eq. 18 with ``k1 = k4 = 0`` for roll) is discretised with
Euler's method at the data's sample interval ``Ts`` (eq. 48)::

    p[k+1] = p[k] + Ts * (-k_damp * p[k] + k_gain * u[k] + kd) + w[k]        (48)

and the constant parameters are appended to the state (eqs. 49-53)::

    x = [p, k_damp, k_gain, kd],   Theta[k+1] = Theta[k]

so that the filter estimates them along with the rate. The paper's EKF section
names the parameters ``k1`` (damping), ``k2`` (gain) and ``kd``; for roll these
are our ``k3``, ``k2`` and ``kd1`` (see :mod:`identification.baselines.single_axis`).
Only the rate is measured (eqs. 54-55), ``H = [1, 0, 0, 0]``; process noise
enters the rate only, ``Gamma = [1, 0, 0, 0]^T`` (eq. 53).

The filter is a recursion over samples, so it runs as one loop over the data;
everything that does not depend on the estimate (the stick and offset
regressors) is computed for all samples at once from the term library.
The identified model is judged as the paper does: by forward-simulating it
(:meth:`ParameterEKF.predict`, through :func:`heli_core.physics.simulate`).
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass

import numpy as np

from heli_core.deprecation import module_getattr
from heli_core.terms import STICK_ROW, TERMS, evaluate_features

from ..flight import Flight
from .paper_tables import TABLE4_M0, TABLE5_LENGTHS
from .single_axis import (
    RateErrors,
    SingleAxisEstimator,
    axis_index,
    check_vector,
    make_params,
    parameter_names,
    rate_errors,
    simulate_rate,
)

P0_EQ74 = (1e-2, 1.0, 1.0, 1.0)
"""Diagonal of the initial covariance of eq. (74)."""

R_FLOOR = 1e-10
"""(rad/s)^2. Lower bound of the automatic measurement-noise variance."""


def estimate_noise_variance(rate) -> float:
    """Variance of the white measurement noise on a sampled rate [(rad/s)^2].

    Robust second-difference estimator: for white noise of variance ``s2`` the
    second difference has variance ``6*s2``, while a signal band-limited well
    below the Nyquist frequency contributes little to it; the median absolute
    value (scaled by 0.6745 for a normal law) ignores outliers. On a low-pass
    filtered rate (the paper's FIR filter, Section 3.1) it measures the noise
    left after filtering, which is what ``R`` in eq. (62) stands for.

    Parameters
    ----------
    rate : ndarray, shape (n,)
        Measured rate [rad/s], ``n >= 3``.

    Returns
    -------
    float
        At least :data:`R_FLOOR`.
    """
    d2 = np.diff(np.asarray(rate, dtype=float), n=2)
    sigma = float(np.median(np.abs(d2))) / 0.6745 / math.sqrt(6.0)
    return max(sigma * sigma, R_FLOOR)


@dataclass(frozen=True)
class EKFHistory:
    """Per-sample estimates of a :class:`ParameterEKF` run (Figs. 22-23).

    Row ``k`` is the corrected estimate after the measurement at ``time[k]``
    (row 0 is the prior ``m0``, ``p0``). After a divergence the rows are NaN.

    Attributes
    ----------
    names : tuple of str
        State names, e.g. ``("p", "k3", "k2", "kd1")``.
    time : ndarray, shape (n,)
        Sample times [s].
    state : ndarray, shape (n, n_state)
        Estimated rate [rad/s] and parameters.
    cov_diag : ndarray, shape (n, n_state)
        Diagonal of the corrected covariance (Fig. 22).
    innovation : ndarray, shape (n,)
        Measured minus predicted rate before each update [rad/s] (0 at row 0).
    """

    names: tuple[str, ...]
    time: np.ndarray
    state: np.ndarray
    cov_diag: np.ndarray
    innovation: np.ndarray

    @property
    def params(self) -> np.ndarray:
        """Parameter estimates, shape (n, n_params) (Fig. 23)."""
        return self.state[:, 1:]


class ParameterEKF(SingleAxisEstimator):
    """Joint state and parameter EKF on the decoupled model, eqs. (48)-(64).

    Parameters
    ----------
    axis : {"roll", "pitch", "yaw"}
        Axis to identify: roll ``(k3, k2, kd1)``, pitch ``(k7, k6, kd2)``,
        yaw ``(k11, k10, kd3)``.
    q : float
        Process-noise variance ``Q`` on the rate per sample [(rad/s)^2], eq. (60).
        Table 4 uses 1, 1e-8 and 1e-2 (:data:`~identification.baselines.paper_tables.TABLE4_Q`).
    r : float or "auto"
        Measurement-noise variance ``R`` [(rad/s)^2], eq. (62). ``"auto"``
        estimates the variance of the noise left on the (filtered) measured rate
        with :func:`estimate_noise_variance`; the paper tuned it by grid search
        without reporting it.
    m0 : sequence of float, shape (4,) or (5,)
        Initial state ``[p0, k_damp, k_gain, kd]`` (Table 4's ``m_o``): initial
        rate [rad/s], damping [1/s], gain [rad/s^2 per unit stick], offset
        [rad/s^2]. For roll these are ``[p0, k3, k2, kd1]`` (the paper's
        ``k1, k2, kd``). With ``collective=True`` a fifth value starts ``k12``.
        Default: case (a) of Table 4; case (b) is ``(0, 2, 3, 0)``
        (:data:`~identification.baselines.paper_tables.TABLE4_M0`).
    p0 : sequence of float, shape (n_state,), or ndarray, shape (n_state, n_state)
        Initial covariance, as its diagonal or in full. Default eq. (74),
        ``diag(1e-2, 1, 1, 1)``.
    collective : bool
        Yaw only: also estimate ``k12`` of the ``-k12*col`` term (eq. 21).
    substeps : int
        RK4 sub-steps of the forward simulation in :meth:`predict` (the filter
        itself uses the Euler model of eq. 48).

    Attributes
    ----------
    params_ : ModelParams
        Model from the final parameter estimates (other parameters 0).
    coef_ : ndarray, shape (n_params,)
        Final parameter estimates in the order of ``param_names_``.
    state_ : ndarray, shape (n_state,)
        Final augmented state ``[rate, params...]``.
    covariance_ : ndarray, shape (n_state, n_state)
        Final corrected covariance.
    r_ : float
        Measurement-noise variance used [(rad/s)^2].
    diverged_ : bool
        The estimate became non-finite; ``params_`` then holds the last finite
        estimate and the later rows of ``history_`` are NaN.
    cpu_time_ : float
        CPU time of the filter run [s] (:func:`time.process_time`).
    history_ : EKFHistory
        Per-sample estimates and covariance diagonals.

    Notes
    -----
    The Euler model of eq. (48) is biased against the continuous model by
    ``O(k_damp * Ts)``: on data from the exact model the damping and gain come
    out low by about ``k_damp*Ts/2`` (2.4 % for ``k3 = 2.42`` at 50 Hz).
    """

    def __init__(self, axis="roll", q=1e-2, r="auto", m0=TABLE4_M0["a"], p0=P0_EQ74,
                 collective=False, substeps=1):
        self.axis = axis
        self.q = q
        self.r = r
        self.m0 = m0
        self.p0 = p0
        self.collective = collective
        self.substeps = substeps

    # ------------------------------------------------------------------ checks
    def _check_args(self, names):
        state_names = ("rate",) + names
        m0 = check_vector("m0", self.m0, state_names)
        nx = m0.size
        p0 = np.asarray(self.p0, dtype=float)
        if p0.shape == (nx,):
            p0 = np.diag(p0)
        if p0.shape != (nx, nx):
            raise ValueError(
                f"p0 must be a diagonal of {nx} values or a {nx}x{nx} matrix for state "
                f"({', '.join(state_names)}), got shape {p0.shape}"
            )
        if not np.all(np.isfinite(p0)) or not np.allclose(p0, p0.T) or np.linalg.eigvalsh(p0).min() < 0:
            raise ValueError("p0 must be a finite, symmetric, positive semi-definite covariance")
        q = float(self.q)
        if not (math.isfinite(q) and q >= 0.0):
            raise ValueError(f"q must be a finite variance >= 0 [(rad/s)^2], got {self.q!r}")
        if isinstance(self.r, str):
            if self.r != "auto":
                raise ValueError(f"r must be a variance > 0 [(rad/s)^2] or 'auto', got {self.r!r}")
            r = None
        else:
            r = float(self.r)
            if not (math.isfinite(r) and r > 0.0):
                raise ValueError(f"r must be a finite variance > 0 [(rad/s)^2] or 'auto', got {self.r!r}")
        return m0, p0, q, r

    # --------------------------------------------------------------------- fit
    def fit(self, flight: Flight) -> "ParameterEKF":
        """Run the filter once through ``flight``; returns ``self``.

        Parameters
        ----------
        flight : Flight
            Measured rate (the observation ``z``) [rad/s] and sticks (the input
            ``u``, held over each sample interval). ``Ts`` is its median sample
            interval.
        """
        names = parameter_names(self.axis, self.collective)
        m0, p0, q, r = self._check_args(names)
        i = axis_index(self.axis)
        z = np.asarray(flight.rates[i], dtype=float)
        if z.size < 3:
            raise ValueError(f"the EKF needs at least 3 samples, got {z.size}")
        r = estimate_noise_variance(z) if r is None else r

        # Regressors that do not depend on the estimated rate (gain, offset, k12),
        # signed as in the equations, for all samples at once.
        damp, rest = TERMS[names[0]], [TERMS[n] for n in names[1:]]
        cmd = flight.sticks[list(STICK_ROW)]
        g = (evaluate_features([t.feature for t in rest], flight.rates, cmd, flight.sticks[2]).T
             * np.array([t.sign for t in rest]))
        t0 = _time.process_time()
        state, cov_diag, innovation, x, P, diverged = _run_filter(
            z, g, damp.sign, flight.dt, m0, p0, q, r)
        self.cpu_time_ = _time.process_time() - t0

        self.r_ = r
        self.state_ = x
        self.covariance_ = P
        self.diverged_ = diverged
        self.params_ = make_params(names, x[1:])
        self.history_ = EKFHistory(("rate",) + names, np.array(flight.time), state, cov_diag, innovation)
        return self


def _run_filter(z, g, damp_sign, ts, m0, p0, q, r):
    """Predict (eqs. 56-60) and update (eqs. 62-64) over all samples.

    Parameters
    ----------
    z : ndarray, shape (n,)
        Measured rate.
    g : ndarray, shape (n, n_params - 1)
        Signed regressors of the non-damping parameters.
    damp_sign : float
        Sign of the damping term (-1).
    ts : float
        Sample interval [s].
    m0, p0, q, r
        Prior mean and covariance, process and measurement noise variances.

    Returns
    -------
    state, cov_diag, innovation, x, P, diverged
    """
    n, nx = z.size, m0.size
    state = np.full((n, nx), np.nan)
    cov_diag = np.full((n, nx), np.nan)
    innovation = np.full(n, np.nan)
    x, P = m0.copy(), p0.copy()
    state[0], cov_diag[0], innovation[0] = x, np.diag(P), 0.0
    phi = np.eye(nx)
    for k in range(n - 1):
        rate, gk = x[0], g[k]
        # Jacobian of the Euler model, eq. (57): d/d(rate), d/d(k_damp), d/d(rest).
        phi[0, 0] = 1.0 + ts * damp_sign * x[1]
        phi[0, 1] = ts * damp_sign * rate
        phi[0, 2:] = ts * gk
        # Extrapolation, eqs. (58)-(60); Gamma*Q*Gamma^T adds Q to the rate only.
        x_pred = x.copy()
        x_pred[0] = rate + ts * (damp_sign * x[1] * rate + x[2:] @ gk)
        P_pred = phi @ P @ phi.T
        P_pred[0, 0] += q
        # Update, eqs. (62)-(64) with H = [1, 0, ..., 0].
        e = z[k + 1] - x_pred[0]
        K = P_pred[:, 0] / (P_pred[0, 0] + r)
        x_new = x_pred + K * e
        P_new = P_pred - np.outer(K, P_pred[0])
        P_new = 0.5 * (P_new + P_new.T)  # keep it symmetric against round-off
        if not math.isfinite(float(x_new.sum() + P_new.sum())):
            return state, cov_diag, innovation, x, P, True
        x, P = x_new, P_new
        state[k + 1], cov_diag[k + 1], innovation[k + 1] = x, np.diag(P), e
    return state, cov_diag, innovation, x, P, False


@dataclass(frozen=True)
class SampleLengthResult:
    """One row of Table 5: the EKF fitted on the first ``length`` seconds.

    Attributes
    ----------
    length : float
        Identification window [s], from the start of the flight.
    params : ModelParams
        Final EKF estimate on that window.
    errors : RateErrors
        MAE and 90th percentile [deg/s] of the forward simulation over the whole flight.
    cpu_time : float
        CPU time of the filter run [s].
    diverged : bool
        The filter diverged on the window.
    """

    length: float
    params: object
    errors: RateErrors
    cpu_time: float
    diverged: bool


def ekf_sample_length_study(flight: Flight, lengths=TABLE5_LENGTHS, **ekf_params) -> list[SampleLengthResult]:
    """Table 5: EKF convergence against the length of the identification window.

    For each length ``L`` the filter runs on ``[t0, t0 + L]`` (``t0`` the first
    sample time) and the identified model is forward-simulated over the whole
    flight; the error statistics are against the whole measured rate.

    Parameters
    ----------
    flight : Flight
    lengths : sequence of float
        Window lengths [s]; each at most the flight's duration. Default
        (4.84, 11, 22) as Table 5.
    **ekf_params
        Arguments of :class:`ParameterEKF` (``axis``, ``q``, ``r``, ``m0``, ...).
        Table 5 uses ``q=1e-2`` and ``m0`` of case (a), the defaults.

    Returns
    -------
    list of SampleLengthResult
        One per length, in the order given.
    """
    t0 = float(flight.time[0])
    out = []
    for length in lengths:
        length = float(length)
        if not 0.0 < length <= flight.duration + 1e-9:
            raise ValueError(
                f"window length must be in (0, {flight.duration:.3f}] s (the flight's duration), got {length}"
            )
        ekf = ParameterEKF(**ekf_params).fit(flight.segment(t0, t0 + length))
        sim = simulate_rate(ekf.params_, flight, ekf.axis, ekf.substeps)
        errors = rate_errors(sim, flight.rates[axis_index(ekf.axis)])
        out.append(SampleLengthResult(length, ekf.params_, errors, ekf.cpu_time_, ekf.diverged_))
    return out


__getattr__ = module_getattr(__name__)
