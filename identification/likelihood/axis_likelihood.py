"""The likelihood of one axis of the wind-state model, with the linear parameters projected out.

For one body rate (eq. 18 or 21 with the wind of eqs. 41-42 as a random
process, :mod:`identification.likelihood.state_space`), :class:`AxisLikelihood` turns a
search vector (the damping, the gust time constants and levels, and the servo
delay when it is searched) into the innovations of the steady-state Kalman
filter, computed by linear filters (``scipy.signal.lfilter``'s arithmetic, compiled:
:func:`~identification.likelihood.kalman_kernels.filter_rows`) over every
flight at once. The parameters that enter linearly (control gain, offsets,
couplings, added terms) are solved exactly at every step (variable
projection), so that the search of
:class:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier` only sees the
concentrated likelihood. :meth:`AxisLikelihood.fisher` gives the standard errors
of the optimum from the Fisher information of the innovations (Gauss-Newton).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from .input_hold import hold_fraction
from .state_space import (HOLD_INDEX, N_NONLINEAR, discrete_system, innovation_filters, input_vectors, kalman,
                          servo_increments)

SYSTEMS_KEPT = 8
"""How many recent systems (:meth:`AxisLikelihood.system`) an axis keeps: the search's Jacobian perturbs one entry
at a time around one point, so the hold's and the alignment's columns find their point's system here."""

MIN_SERVO_DELAY = 1e-4
"""Delays below this are no delay (the Padé servo of eq. 31 degenerates at zero) [s]."""


@dataclass
class AxisData:
    """Signals of one axis over one or more flights, as the likelihood needs them."""

    y: list           # measured rate per flight (n_f,)
    regressors: list  # per flight (m, n_f): sign * feature, one offset column per flight
    names: tuple      # parameter names of the regressors (offsets as "kd1@0", "kd1@1", ...)
    dt: float
    hold: object  # the input's hold (name or fraction, state_space.hold_fraction): the search's start or fixed value
    burn: int
    wind_model: str = "gm2"
    servo_row: int | None = None  # regressor driven through the servo (eq. 31), or None
    servo_sticks: list | None = None  # the raw stick per flight for that regressor (sign applied)
    tau: float = 0.0
    causal_rows: tuple = ()  # regressors made of measured rates: held over the sample, never interpolated
    rebuild: object = None  # shift (s, < 0: the log's input lags) -> regressors with the axis' stick advanced
    lag: float = 0.0  # the servo's first-order lag (eq. 31's d1 grows by it) [s]
    corners: tuple = ()  # per flight, the gyro filter its log states [Hz] or None (gyro_path): the stick passes it

    def corner(self, i: int) -> float | None:
        """Flight ``i``'s stated gyro filter [Hz], None where its log states none."""
        return self.corners[i] if i < len(self.corners) else None


class AxisLikelihood:
    """The concentrated innovation likelihood of one axis, with the linear parameters projected out."""

    def __init__(self, data: AxisData, free_tau: bool = False):
        self.data = data
        self.free_tau = free_tau
        self.nw = N_NONLINEAR[data.wind_model]
        """Length of the model part of the search vector (damping, wind, hold fraction); the servo delay follows
        when ``free_tau``."""
        self._systems = {}
        self._servo = {}

    def unpack(self, x):
        """(damping, T_slow, T_fast, var_slow/R, var_fast/R, zeta) from the search vector."""
        damping, lts, ltf, lqs, lqf = x[:5]
        zeta = float(np.exp(x[HOLD_INDEX + 1])) if self.nw > HOLD_INDEX + 1 else 1.0
        return (float(damping), float(np.exp(lts)), float(np.exp(ltf)), float(np.exp(lqs)), float(np.exp(lqf)),
                zeta)

    def tau_of(self, x) -> float:
        """The alignment at ``x`` [s]: searched with the rest when ``free_tau``, else the data's servo delay.

        A positive alignment is the Padé servo delay of eq. (31); a negative one (searched only) a log whose
        input column lags the response, corrected by advancing the axis' stick.
        """
        return float(x[self.nw]) if self.free_tau else self.data.tau

    @staticmethod
    def hold_at(x) -> float:
        """The input's hold fraction at ``x`` (0 held over the sample, 1 linearly interpolated)."""
        return float(x[HOLD_INDEX])

    def system(self, x):
        """``(Ad, ga, gb, Qd, L, S)`` at ``x``: the discretised axis (:func:`~.state_space.discrete_system`) and
        its steady-state Kalman gain, which neither the hold nor the alignment changes. The last
        :data:`SYSTEMS_KEPT` are kept, keyed by the exact values they depend on, so that the Jacobian's hold and
        alignment columns and the Fisher information's reuse them (the same numbers: the same bits)."""
        key = self.unpack(x)
        hit = self._systems.get(key)
        if hit is None:
            Ad, ga, gb, Qd = discrete_system(*key, self.data.dt, self.data.wind_model)
            _, L, S = kalman(Ad, Qd)
            for shared in (Ad, ga, gb, Qd, L):
                shared.setflags(write=False)  # handed out again: nobody may change them in place
            if len(self._systems) >= SYSTEMS_KEPT:
                del self._systems[next(iter(self._systems))]
            hit = self._systems[key] = (Ad, ga, gb, Qd, L, S)
        return hit

    def predictor(self, x):
        """``(Ad, g0, g1, L, S)`` at ``x``: the discretised axis with its input vectors at ``x``'s hold
        (:func:`~.state_space.discrete_model`) and its steady-state Kalman gain and innovation variance."""
        Ad, ga, gb, _, L, S = self.system(x)
        return (Ad, *input_vectors(ga, gb, self.hold_at(x)), L, S)

    def filtered(self, x):
        """Innovation-domain measurements ``y~`` (n,) and regressors ``Z`` (m, n), burn-in removed, and ``S``."""
        d = self.data
        Ad, g0, g1, L, S = self.predictor(x)
        tau = self.tau_of(x)
        regressors = d.rebuild(tau) if tau < -MIN_SERVO_DELAY else d.regressors
        # the stick's own path: a servo (a delay or a lag), or a gyro filter the log states (gyro_path); an input
        # column advanced (tau < 0) enters by its regressor, filtered there
        path = d.lag > 0.0 or any(c is not None for c in d.corners)
        servo = d.servo_row is not None and (tau > MIN_SERVO_DELAY or (path and tau >= -MIN_SERVO_DELAY))
        # a measured rate at k+1 carries the noise of y[k+1]: only u[k] may predict y[k+1] (b_c); a command through
        # the servo enters the rate on its own (b_v)
        more = ([g0 + g1] if d.causal_rows else []) + ([np.eye(Ad.shape[0])[0]] if servo else [])
        b_y, b_u, a, *paths = innovation_filters(Ad, g0, g1, L, *more)
        b_c = paths[0] if d.causal_rows else None
        b_v = paths[-1] if servo else None
        from .kalman_kernels import filter_rows  # numba loads with the first evaluation, not with the package

        ys, zs = [], []
        for i, (y, X) in enumerate(zip(d.y, regressors)):
            # every row through its filter in one compiled pass (lfilter's arithmetic: kalman_kernels.filter_rows)
            rows, B = np.empty((1 + X.shape[0], y.size)), np.empty((1 + X.shape[0], a.size))
            rows[0], rows[1:], B[0], B[1:] = y, X, b_y, b_u
            for r in d.causal_rows:
                B[1 + r] = b_c
            if servo:
                rows[1 + d.servo_row] = self._servo_increments(i, x[0], max(tau, 0.0), self.hold_at(x))
                B[1 + d.servo_row] = b_v
            F = filter_rows(B, a, rows)
            ys.append((y - F[0])[d.burn:])
            zs.append(F[1:, d.burn:])
        return np.concatenate(ys), np.concatenate(zs, axis=1), S

    def _servo_increments(self, i: int, damping: float, tau: float, hold: float) -> np.ndarray:
        """Flight ``i``'s stick through the servo (:func:`~.state_space.servo_increments`) at ``damping``, delay
        ``tau`` and hold ``hold``. The last :data:`SYSTEMS_KEPT` are kept, keyed by those exact values, so that the
        Jacobian's gust columns, which leave them as they are, reuse them (the same numbers: the same bits)."""
        key = (i, float(damping), float(tau), float(hold))
        hit = self._servo.get(key)
        if hit is None:
            d = self.data
            hit = servo_increments(d.servo_sticks[i], damping, tau, d.dt, hold, d.lag, d.corner(i))
            hit.setflags(write=False)  # handed out again: nobody may change it in place
            if len(self._servo) >= SYSTEMS_KEPT * len(d.y):
                del self._servo[next(iter(self._servo))]
            self._servo[key] = hit
        return hit

    def solve_linear(self, x):
        """Innovations ``e``, the linear parameters ``theta`` minimising them at the nonlinear ``x``, and ``S``."""
        yt, Z, S = self.filtered(x)
        # normal equations of the column-scaled problem (a few columns, tens of thousands of rows)
        G = Z @ Z.T
        scale = np.sqrt(np.maximum(np.diag(G), 1e-300))
        theta = np.linalg.lstsq(G / np.outer(scale, scale), (Z @ yt) / scale, rcond=None)[0] / scale
        return yt - theta @ Z, theta, S

    def residual(self, x):
        return self.solve_linear(x)[0]

    def residual_at(self, x, theta):
        """Innovations at ``x`` with the linear parameters held at ``theta``."""
        yt, Z, _ = self.filtered(x)
        return yt - theta @ Z

    def fisher(self, x, theta, mse: float, free_damping: bool = True, fixed=()) -> tuple[np.ndarray, float]:
        """Standard errors of ``(x, theta)`` at the optimum and the condition number of the column-normalised
        Fisher information (Gauss-Newton: de/dx by central differences, de/dtheta = -Z); ``mse`` is the mean
        squared innovation. Entries of ``x`` not searched (``fixed`` indices; the damping of a structure
        without one) are left out of the information and get a standard error of 0.

        A searched hold fraction lies in [0, 1], which its linearised information does not know: beside a searched
        delay, with which it trades half a sample, the data may hardly decide it (a pilot's 120 s flight with a
        40 ms servo delay: the hold 1.0 +- 3.0, a spread no value in [0, 1] can have), and the delay's standard
        error carried it (16 ms where the delay was found within 1 ms). The other values' standard errors are
        read with the hold's information raised by that of its range (:data:`HOLD_RANGE_VARIANCE`); the hold's
        own is the data's alone (the log's hold is decided by pooling those: a range is no measurement)."""
        _, Z, _ = self.filtered(x)
        nx = len(x)
        held = set(int(i) for i in fixed) | (set() if free_damping else {0})
        J = np.zeros((Z.shape[1], nx + Z.shape[0]))
        for j in range(nx):
            if j in held:
                continue
            h = 1e-5 * max(1.0, abs(x[j]))
            xp, xm = x.copy(), x.copy()
            xp[j] += h
            xm[j] -= h
            J[:, j] = (self.residual_at(xp, theta) - self.residual_at(xm, theta)) / (2 * h)
        J[:, nx:] = -Z.T
        keep = np.array([j not in held for j in range(J.shape[1])])
        F = J[:, keep].T @ J[:, keep]
        se, cond = _standard_errors(F, mse, keep)
        if HOLD_INDEX < nx and HOLD_INDEX not in held:
            hold = int(np.count_nonzero(keep[:HOLD_INDEX]))  # its row among the kept
            bounded = F.copy()
            bounded[hold, hold] += mse / HOLD_RANGE_VARIANCE
            se_hold = se[HOLD_INDEX]
            se = _standard_errors(bounded, mse, keep)[0]
            se[HOLD_INDEX] = se_hold
        return se, cond


HOLD_RANGE_VARIANCE = 0.25
"""The largest variance a value in [0, 1] can have (half its weight at each end: the two named holds, between which
:func:`~identification.likelihood.input_hold.decide_hold` chooses where the data cannot tell): a hold fraction is
known at least that well, whatever its linearised information says (:meth:`AxisLikelihood.fisher`)."""


def _standard_errors(F: np.ndarray, mse: float, keep: np.ndarray) -> tuple[np.ndarray, float]:
    """Standard errors from the Gauss-Newton information ``F`` of the ``keep`` columns (0 elsewhere) at mean squared
    innovation ``mse``, and the condition number of ``F`` normalised by its diagonal."""
    dscale = np.sqrt(np.maximum(np.diag(F), 1e-300))
    Fn = F / np.outer(dscale, dscale)
    w = np.linalg.eigvalsh(Fn)
    se = np.zeros(keep.size)
    se[keep] = np.sqrt(np.maximum(np.diag(np.linalg.pinv(Fn)) * mse, 0.0)) / dscale
    return se, float(w[-1] / max(w[0], 1e-300))


def simulation_r2(data: AxisData, damping: float, theta, hold=None) -> float:
    """R^2 of the wind- and noise-free response to the inputs, each flight started at its first sample, the
    inputs under ``hold`` (a name or fraction; default the data's)."""
    dt = data.dt
    frac = hold_fraction(data.hold if hold is None else hold)
    ad = float(np.exp(-damping * dt))
    if abs(damping) > 1e-9:
        g = (1.0 - ad) / damping
        g1 = frac * (dt - g) / (damping * dt)
    else:
        g, g1 = dt, frac * dt / 2
    g0 = g - g1
    num = den = 0.0
    for y, X in zip(data.y, data.regressors):
        u = theta @ X
        sim = np.empty_like(y)
        sim[0] = y[0]
        sim[1:] = signal.lfilter([1.0], [1.0, -ad], g0 * u[:-1] + g1 * u[1:], zi=[ad * y[0]])[0]
        err = (y - sim)[data.burn:]
        yc = y[data.burn:] - np.mean(y[data.burn:])
        num += float(err @ err)
        den += float(yc @ yc)
    return 1.0 - num / (den or 1.0)
