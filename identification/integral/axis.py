"""The least-squares problem of the integral method for one axis, eqs. (32)-(40), and what it learns (:class:`AxisFit`).

:class:`IntegralAxisSystem` stacks every sample of every interval into the
linear problem of eq. (35) for one axis and solves it by the iteration of
eqs. (39)-(40); :class:`~identification.integral.method.IntegralIdentifier`
builds one per axis (and per candidate servo delay) from the intervals of its
flights (:class:`IntervalSignals`).

Implementation. The regressors of eq. (35), with the per-interval disturbance
polynomial projected out (Frisch-Waugh), and the projected increments ``y_p``
are the rows of one array ``A``; its Gram matrix holds the normal equations,
and after each solve ``d = A_x beta - y_p`` is ``p_approx - p`` at every sample
(eqs. 39-40), whose mean square is the least-squares error of the iteration.
The next iteration's integral of ``p_approx`` is the measured rate's integral
plus that of ``d`` (for the linear own-rate feature; other features are
re-evaluated on p_approx), and only the Gram rows of the own-rate regressors
are recomputed. The per-interval disturbance coefficients are obtained for the
best iterate only, from each regressor's polynomial coefficients.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from heli_core.terms import AXES, FEATURE_EXPRESSIONS, FEATURES, RATE_DEPENDENCE, TERMS

from ..errors import IdentifiabilityError
from .intervals import disturbance_basis, interval_integral, solve_small, sum_squares, symmetric_eigenvalues

MAX_CONDITION = 1e6
"""Largest condition number of the column-normalised regressor matrix accepted."""
SLOW_FRACTION = 0.05
"""An input feature keeping less than this share of its variance once a
per-interval polynomial (like the disturbance's) is removed is estimated
between intervals (see :mod:`identification.integral.method`)."""


@dataclass(frozen=True)
class AxisFit:
    """What the fit learned about one axis.

    Attributes
    ----------
    axis : str
    params : dict of str to float
        Identified values of the axis' parameters.
    std_errors : dict of str to float
        Standard errors of the last least-squares solve (residual-based).
    delay : float
        Servo delay used [s].
    condition : float
        Condition number of the column-normalised regressor matrix.
    r2 : float
        Coefficient of determination of the integral fit (last iteration).
    history : tuple of float
        Mean squared error between p_approx and the data after each iteration [(rad/s)^2].
    interval_offsets : ndarray, shape (n_intervals,)
        Per-interval offsets ū_{d,i} [rad/s^2] (``offsets="per_interval"``), else empty.
    interval_starts : ndarray, shape (n_intervals,)
        Start time of each interval [s].
    residual : ndarray, shape (n_intervals, N), optional
        Integral residual ``p_approx - p`` of the best iterate at samples 1..N of
        every interval (eqs. 39-40), with the per-interval disturbance polynomial
        removed; its increments are the equation error the residual tests of
        :mod:`identification.diagnosis.residual_tests` examine.
    """

    axis: str
    params: dict
    std_errors: dict
    delay: float
    condition: float
    r2: float
    history: tuple
    interval_offsets: np.ndarray
    interval_starts: np.ndarray
    residual: np.ndarray | None = None


@dataclass(frozen=True)
class IntervalSignals:
    """The flights' signals laid out by interval (:func:`~identification.integral.intervals.split_intervals`).

    Each signal is a pair ``(inner, first)``: samples 1..N of every interval,
    shape (..., n_int, N), and each interval's first sample, shape (..., n_int).

    Attributes
    ----------
    rates : tuple of list of ndarray
        p, q, r [rad/s].
    cmds : tuple of list of ndarray
        The three servo-side commands (eq. 31) [-1, 1].
    col : tuple of ndarray
        The collective stick [-1, 1].
    dt : float
        Sample interval [s].
    start_times : ndarray, shape (n_int,)
        Start time of each interval [s].
    """

    rates: tuple
    cmds: tuple
    col: tuple
    dt: float
    start_times: np.ndarray


def _feature(name: str, rates, cmd, col, shape) -> np.ndarray:
    """One feature of :data:`heli_core.terms.FEATURES` (broadcast to ``shape``)."""
    return np.broadcast_to(FEATURES[name](rates, cmd, col), shape)


class IntegralAxisSystem:
    """Eqs. (32)-(40) for one axis: the regressors integrated over every interval and the iteration.

    Parameters
    ----------
    a : int
        The axis (0 roll, 1 pitch, 2 yaw).
    axis_params : sequence of str
        The axis' parameters (:data:`heli_core.terms.TERMS`).
    signals : IntervalSignals
    per_interval : bool
        Joint per-interval disturbance offsets (projected out), else one constant offset.
    disturbance_order : int
        Degree of the per-interval disturbance polynomial.
    zoh : bool
        Inputs held over each sample (left rectangle) rather than interpolated (trapezium, eq. 36).

    Raises
    ------
    IdentifiabilityError
        Every regressor is constant within the intervals.
    """

    def __init__(self, a: int, axis_params, signals: IntervalSignals, per_interval: bool, disturbance_order: int,
                 zoh: bool):
        self.a, self.axis_params, self.signals = a, axis_params, signals
        self.per_interval, self.disturbance_order, self.zoh = per_interval, disturbance_order, zoh
        Rg, R0 = signals.rates
        self.n_int, self.N = Rg.shape[-2:]
        terms = [TERMS[p] for p in axis_params]
        self.feats = [t.feature for t in terms]
        self.keep = [j for j, f in enumerate(self.feats) if not (per_interval and f == "1")]
        self.kfeats = [self.feats[j] for j in self.keep]
        self.signs = [terms[j].sign for j in self.keep]
        self.input_only = [f not in RATE_DEPENDENCE for f in self.kfeats]
        own = [a in RATE_DEPENDENCE.get(f, ()) for f in self.kfeats]  # re-evaluated at each iteration
        self.slow = []
        if per_interval:
            _, self.Q, _, Qt, self.QB, self.QT = disturbance_basis(self.N, signals.dt, disturbance_order)
            self.o = self.Q.shape[1]
            self.slow = self._slow_features(Qt)
            self.slow_means = [(self.inner_of(i).sum(axis=1) + self.first_of(i)) * (self.signs[i] / (self.N + 1))
                               for i in self.slow]
        self.fixed = [i for i in range(len(self.kfeats)) if i not in self.slow and not own[i]]
        self.ownu = [i for i in range(len(self.kfeats)) if i not in self.slow and own[i]]
        self.order = self.fixed + self.ownu
        if not self.order:
            raise IdentifiabilityError(f"{AXES[a]}: every regressor is constant within the intervals")
        self.nf, self.k = len(self.fixed), len(self.order)
        self._build()

    # ------------------------------------------------------------ features
    def inner_of(self, i: int, rates_inner=None) -> np.ndarray:
        """Feature ``i`` at samples 1..N of every interval (on ``rates_inner``, default the measured rates)."""
        s = self.signals
        return _feature(self.kfeats[i], s.rates[0] if rates_inner is None else rates_inner, s.cmds[0], s.col[0],
                        (self.n_int, self.N))

    def first_of(self, i: int) -> np.ndarray:
        """Feature ``i`` at the first sample of every interval."""
        s = self.signals
        return _feature(self.kfeats[i], s.rates[1], s.cmds[1], s.col[1], (self.n_int,))

    def command_std(self) -> float:
        """Standard deviation of the axis' own command (named when the axis is not excited)."""
        Ug, U0 = self.signals.cmds
        return np.std(np.concatenate([U0[self.a][:, None], Ug[self.a]], axis=1))

    def _slow_features(self, Qt) -> list[int]:
        """Input features that hardly change within an interval (collective): all but absorbed by the
        per-interval disturbance, they are estimated between intervals."""
        n_int, N = self.n_int, self.N
        slow = []
        for i in range(len(self.kfeats)):
            if not self.input_only[i] or self.kfeats[i] == "1":
                continue
            f_inner, f_first = self.inner_of(i), self.first_of(i)
            centred = np.empty((n_int, N + 1))  # every interval's N+1 samples less the mean of all
            mean = (f_inner.sum() + f_first.sum()) / centred.size
            np.subtract(f_first, mean, out=centred[:, 0])
            np.subtract(f_inner, mean, out=centred[:, 1:])
            total = sum_squares(centred.ravel())
            fit_q = centred @ Qt  # constants lie in span(Qt): the fit of the feature less its mean
            within = total - sum_squares(fit_q.ravel())  # what a per-interval polynomial leaves
            if total > 0 and within < SLOW_FRACTION * total:
                slow.append(i)
        return slow

    # ------------------------------------------------------------ eq. (35)
    def project(self, row: int) -> np.ndarray:
        """Remove from every interval of A[row] its least-squares fit on Q; return its coefficients on B."""
        X = self.A[row]
        XQB = X @ self.QB
        np.matmul(XQB[:, :self.o], self.QT, out=self.scratch)
        X -= self.scratch
        return XQB[:, self.o:]

    def integrate(self, i: int, rates_inner=None, out=None) -> np.ndarray:
        """Integral of feature i from each interval start (eq. 36), sign of eq. (18)/(21) folded in."""
        rect = self.zoh and self.input_only[i]
        return interval_integral(self.inner_of(i, rates_inner), self.first_of(i), self.signals.dt * self.signs[i],
                                 diag=0.0 if rect else 0.5, first_weight=1.0 if rect else 0.5, out=out)

    def _build(self) -> None:
        """The rows of ``A`` (regressors, then the increments of eq. 37), projected, and their Gram matrix ``M``."""
        Rg, R0 = self.signals.rates
        k, nf, per_interval = self.k, self.nf, self.per_interval
        self.A = np.empty((k + 1, self.n_int, self.N))  # rows: regressors (fixed, then own-rate), then increments
        self.A2 = self.A.reshape(k + 1, self.n_int * self.N)
        self.scratch = np.empty((self.n_int, self.N))
        np.subtract(Rg[self.a], R0[self.a][:, None], out=self.A[k])  # eq. (37)
        self.coef_y = self.project(k) if per_interval else None
        self.coef_x = [None] * k  # per regressor: coefficients of its per-interval polynomial fit on B
        for r, i in enumerate(self.fixed):
            self.integrate(i, out=self.A[r])
            if per_interval:
                self.coef_x[r] = self.project(r)
        # The own-rate feature itself is linear in p_approx = p + d: its integral is the measured one plus d's.
        self.linear = [FEATURE_EXPRESSIONS[self.kfeats[i]] == "pqr"[self.a] for i in self.ownu]
        self.measured = {}
        for r, i in enumerate(self.ownu, start=nf):
            self.integrate(i, out=self.A[r])
            if self.linear[r - nf]:
                self.measured[r] = self.A[r].copy()
            if per_interval:
                self.coef_x[r] = self.project(r)
        # Normal equations of eq. (35): Gram of the regressors, right-hand side, |y_p|^2 (two plain
        # products: numpy's symmetric path for A @ A.T is slow for so few rows).
        A2 = self.A2
        M = np.hstack([A2 @ A2[:k].T, A2 @ A2[k:].T])
        self.M = np.triu(M) + np.triu(M, 1).T

    # ------------------------------------------------------------ eqs. (39)-(40)
    def fit(self, max_iter: int, tol: float, check: bool) -> AxisFit:
        """Iterate eqs. (39)-(40) at most ``max_iter`` times and describe the best iterate.

        Iterations stop when the least-squares error changes by less than ``tol``
        (relative) or stops improving; ``check`` raises for an ill-conditioned problem.
        """
        k, size = self.k, self.n_int * self.N
        d = np.empty(size)
        d2 = d.reshape(self.n_int, self.N)
        coefs = np.empty(k + 1)
        coefs[k] = -1.0
        history = []
        best = None
        for it in range(max(1, max_iter)):
            if it > 0:
                self._update_own_rows(d2)
            sol, G_raw, cond = self._solve(check)
            coefs[:k] = sol
            np.matmul(coefs, self.A2, out=d)  # p_approx - p: the fit less the projected increments
            sq = sum_squares(d)
            err = sq / size
            history.append(err)
            if best is None or err <= best[0]:
                best = (err, sol, self.coef_x[self.nf:], G_raw, cond, sq, d2.copy())
            if not self.ownu or (it > 0 and (abs(history[-2] - err) <= tol * max(history[-2], 1e-30)
                                             or err > history[-2])):
                break  # converged, or the Picard step stopped improving: keep the best iterate
        return self._result(best, history)

    def _update_own_rows(self, d2: np.ndarray) -> None:
        """Eqs. (39)-(40): p_approx = p + d replaces the measured own-axis rate in the integrals; the own-rate
        rows of ``A`` and of the Gram matrix are recomputed."""
        A, A2, M, nf, k = self.A, self.A2, self.M, self.nf, self.k
        Rg = self.signals.rates[0]
        rates_approx = None
        for r, i in enumerate(self.ownu, start=nf):
            if self.linear[r - nf]:
                interval_integral(d2, None, self.signals.dt * self.signs[i], out=A[r])
                A[r] += self.measured[r]
            else:
                if rates_approx is None:
                    rates_approx = [Rg[0], Rg[1], Rg[2]]
                    rates_approx[self.a] = Rg[self.a] + d2
                self.integrate(i, rates_approx, out=A[r])
            if self.per_interval:
                self.coef_x[r] = self.project(r)
        M_own = A2 @ A2[nf:k].T
        M[:, nf:k] = M_own
        M[nf:k, :] = M_own.T
        if k - nf > 1:
            block = M_own[nf:k]
            M[nf:k, nf:k] = np.triu(block) + np.triu(block, 1).T

    def _solve(self, check: bool) -> tuple[np.ndarray, np.ndarray, float]:
        """The column-normalised normal equations of eq. (35) solved: ``(solution, Gram, condition number)``."""
        k, axis = self.k, AXES[self.a]
        G_raw = self.M[:k, :k].copy()
        rhs = self.M[:k, k]
        scale = np.sqrt(np.diag(G_raw))
        if np.any(scale == 0):
            zero = self.axis_params[self.keep[self.order[int(np.argmin(scale))]]]
            raise IdentifiabilityError(
                f"{axis} axis is not identifiable from this flight: the regressor of {zero} is identically "
                f"zero (condition number inf); the input is probably not excited (command std "
                f"{self.command_std():.2g})"
            )
        G = G_raw / np.outer(scale, scale)
        ev = symmetric_eigenvalues(G)
        cond = float(np.sqrt(ev[-1] / ev[0])) if ev[0] > 0 else float("inf")
        if check and (not np.isfinite(cond) or cond > MAX_CONDITION):
            raise IdentifiabilityError(
                f"{axis} axis is not identifiable from this flight: the normalised least-squares "
                f"problem (eq. 35) has condition number {cond:.3g} (limit {MAX_CONDITION:.0e}); "
                f"the input is probably not excited (command std {self.command_std():.2g})"
            )
        return solve_small(G, rhs / scale) / scale, G_raw, cond

    # ------------------------------------------------------------ the result
    def _result(self, best, history) -> AxisFit:
        """Parameters, standard errors, per-interval offsets and R² of the best iterate."""
        err, sol, coef_own, G_raw, cond, sq, residual = best
        beta = np.zeros(len(self.keep))
        beta[self.order] = sol
        slow_se = None
        if self.per_interval:
            offsets, slow_se = self._interval_offsets(beta, sol, coef_own)
        else:
            offsets = np.zeros(0)
        size = self.n_int * self.N
        dof = max(size - beta.size - (self.n_int * (self.disturbance_order + 1) if self.per_interval else 0), 1)
        sigma2 = sq / dof  # sq: squared norm of the residual b - A_x beta of the best iterate
        se = np.full(beta.size, np.nan)
        try:
            se[self.order] = np.sqrt(np.clip(np.diag(sigma2 * np.linalg.inv(G_raw)), 0, None))
        except np.linalg.LinAlgError:
            pass
        if slow_se is not None:
            se[self.slow] = slow_se
        params = {self.axis_params[j]: float(beta[i]) for i, j in enumerate(self.keep)}
        std = {self.axis_params[j]: float(se[i]) for i, j in enumerate(self.keep)}
        if self.per_interval and "1" in self.feats:
            off_name = self.axis_params[self.feats.index("1")]
            params[off_name] = float(offsets.mean())
            spread = offsets - params[off_name]
            std[off_name] = float(np.sqrt(spread @ spread / offsets.size) / np.sqrt(offsets.size))
        b = self.A2[self.k]
        centred_b = b - b.mean()
        ss_tot = sum_squares(centred_b) or 1.0
        r2 = 1.0 - sq / ss_tot
        return AxisFit(AXES[self.a], params, std, 0.0, float(cond), r2, tuple(history), offsets,
                       self.signals.start_times, residual)

    def _interval_offsets(self, beta: np.ndarray, sol, coef_own) -> tuple[np.ndarray, np.ndarray | None]:
        """The per-interval disturbance of the best iterate (mean torque per interval, eq. 43) and, for the
        slow features, their coefficients (written into ``beta``) and standard errors from a between-interval
        regression of that torque on their interval means."""
        # polynomial fit of y - fitted on B
        coef = self.coef_y - sum(s * c for s, c in zip(sol, self.coef_x[:self.nf] + coef_own))
        coef = coef.T  # (o, n_int)
        T = self.N * self.signals.dt
        offsets = np.array([T**j / (j + 1) for j in range(coef.shape[0])]) @ coef  # mean torque
        if not self.slow:
            return offsets, None
        Mb = np.column_stack([np.ones(self.n_int)] + self.slow_means)
        c = np.linalg.lstsq(Mb, offsets, rcond=None)[0]
        beta[self.slow] = c[1:]
        r_between = offsets - Mb @ c
        s2 = float(r_between @ r_between) / max(self.n_int - Mb.shape[1], 1)
        slow_se = np.sqrt(np.clip(np.diag(s2 * np.linalg.pinv(Mb.T @ Mb)), 0, None))[1:]
        return offsets - Mb[:, 1:] @ c[1:], slow_se
