"""Integral-based parameter identification (Section 2.5.2, Fig. 5).

For each axis, e.g. roll (eq. 18), the data are partitioned into intervals
``[T_{i-1}, T_i)`` of equal length; within each interval the model is integrated
from the measured initial value (eq. 34)::

    p(t) - p(T_{i-1}) = sum_j k_j * s_j * int_{T_{i-1}}^t f_j dt            (32)-(33)

with the features ``f_j`` of :mod:`identification.terms` (``q*r``, ``u_lat``,
``p``, ``q``, ``1``), integrated by the trapezium rule (eq. 36). Stacking every
sample of every interval gives the linear least-squares problem of eq. (35),
solved for X = [k1, k2, k3, k4, kd1] (eq. 38). The solution defines the
per-interval approximation ``p_approx`` (eqs. 39-40), which replaces the
measured rate inside the integrals of the next iteration; iterations stop when
the least-squares error between ``p_approx`` and the data changes by less than
``tol`` (relative). Everything is vectorised over samples and intervals.

Wind and the pilot. Pilots fight gusts, so the stick is correlated with the
unmeasured wind torque, and an ordinary fit with a single constant offset kd
biases the damping and gain. The paper's own disturbance model (eqs. 41-43)
is piecewise constant; ``offsets="per_interval"`` (the default) fits it
*jointly*: each interval gets its own offset ``ū_{d,i}`` (eliminated exactly by
projecting the regressors on the within-interval time ramp), so the intrinsic
parameters are identified only from what happens *within* an interval, where
the wind has had little time to change. ``kd`` is then the mean of the
per-interval offsets (eq. 42 with zero-mean u_d). ``offsets="global"`` is the
plain single-offset fit of eq. (35). The bias of both on synthetic flights is
measured in ``scripts/identification_bias.py`` and reported in the README.

Servo delay (eq. 31). With ``delay="auto"`` the delay of each axis is chosen on
a grid as the one whose Padé-delayed command best explains the response (the
highest coefficient of determination of the integral fit, i.e. the best
correlation between the command-driven prediction and the measured rate); the
command is then passed through the first-order Padé filter whose coefficients
come from ``control.pade``.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import signal

from .errors import IdentifiabilityError, NotFittedError
from .flight import Flight
from .model import ModelParams, servo_coefficients
from .preprocess import DEFAULT_PASS_HZ, DEFAULT_STOP_HZ, lowpass_flight
from .terms import AXES, COUPLED, DECOUPLED, EXTRA_PARAMS, RATE_DEPENDENCE, TERMS, evaluate_features

MAX_CONDITION = 1e6
"""Largest condition number of the column-normalised regressor matrix accepted."""
MIN_ROWS_PER_PARAM = 20
SLOW_FRACTION = 0.05
"""An input feature keeping less than this share of its variance once a
per-interval polynomial (like the disturbance's) is removed is estimated
between intervals (see the module docstring)."""


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


def pade_filter(command: np.ndarray, tau: float, fs: float) -> np.ndarray:
    """Pass a command through the first-order Padé delay of eq. (31).

    The continuous filter ``(n1 - n2 s)/(1 + d1 s)`` (coefficients from
    ``control.pade``) is discretised with the bilinear transform and run from
    rest at the first sample's value.
    """
    if tau <= 0:
        return np.asarray(command, dtype=float)
    d1, n1, n2 = servo_coefficients(tau)
    b, a = signal.bilinear([-n2, n1], [d1, 1.0], fs=fs)
    zi = signal.lfilter_zi(b, a) * command[..., :1]
    return signal.lfilter(b, a, command, axis=-1, zi=zi)[0]


def _windows(values: np.ndarray, starts: np.ndarray, length: int) -> np.ndarray:
    """values (..., n) -> (..., n_intervals, length + 1) sharing interval end points (a read-only view).

    ``starts`` must be ``arange(n_intervals) * length`` (equal, adjacent intervals).
    """
    values = np.ascontiguousarray(values, dtype=float)
    step = values.strides[-1]
    shape = values.shape[:-1] + (starts.size, length + 1)
    strides = values.strides[:-1] + (length * step, step)
    return np.lib.stride_tricks.as_strided(values, shape=shape, strides=strides, writeable=False)


@lru_cache(maxsize=16)
def _disturbance_basis(N: int, dt: float, order: int):
    """Per-interval disturbance basis of degree ``order`` on N samples of step dt.

    Returns ``B`` (N, o): integrals t^(j+1)/(j+1) of the torque polynomial t^j;
    ``Q``: orthonormal basis of B; ``B_pinv``; ``Qt`` (N+1, o): orthonormal basis
    of the polynomials themselves on the N+1 samples of an interval.
    """
    tt = np.arange(1, N + 1) * dt
    B = np.stack([tt ** (j + 1) / (j + 1) for j in range(order + 1)], axis=1)
    Q, _ = np.linalg.qr(B)
    Qt, _ = np.linalg.qr(np.vander(np.arange(N + 1) * dt, order + 1))
    for a in (B, Q, Qt):
        a.setflags(write=False)
    return B, Q, np.linalg.pinv(B), Qt


@lru_cache(maxsize=16)
def _prefix_blocks(N: int):
    """Block size b (a divisor of N near sqrt(N)) and the triangular matrices of a two-level prefix sum."""
    divisors = [b for b in range(4, N // 4 + 1) if N % b == 0]
    if not divisors:
        return None
    b = min(divisors, key=lambda d: abs(d - N**0.5))
    nb = N // b
    return b, np.triu(np.ones((b, b))), np.triu(np.ones((nb, nb)), 1)


def _interval_cumsum(D: np.ndarray) -> np.ndarray:
    """Cumulative sum along the last axis (length N), as two small matrix products.

    numpy's cumsum runs at several ns per element; splitting each row into
    blocks, prefix-summing inside the blocks and adding the exclusive prefix of
    the block totals turns it into BLAS work, about twice as fast for the
    interval lengths used here. Exact up to rounding (the same sums, regrouped).
    """
    N = D.shape[-1]
    blocks = _prefix_blocks(N)
    if blocks is None:
        return np.cumsum(D, axis=-1)
    b, inner, outer = blocks
    P = (D.reshape(-1, b) @ inner).reshape(-1, N // b, b)
    return (P + (P[..., -1] @ outer)[..., None]).reshape(D.shape)


def _project_out(Z: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Remove from every interval (last axis) its least-squares fit on the orthonormal columns Q."""
    flat = Z.reshape(-1, Z.shape[-1])
    return (flat - (flat @ Q) @ Q.T).reshape(Z.shape)


class IntegralIdentifier:
    """Identify the attitude model with the integral method of Fig. 5.

    Parameters
    ----------
    structure : {"decoupled", "coupled"} or dict
        Which parameters to fit: the decoupled models of Section 3.2, the
        coupled model of eqs. (18)-(24), or a dict ``{axis_index: (names...)}``.
    extra_terms : sequence of str
        Catalogue terms (:data:`identification.terms.EXTRA_PARAMS`) fitted in
        addition, e.g. ``("nld1",)``.
    interval : float
        Length of the intervals ``T_i - T_{i-1}`` [s].
    offsets : {"per_interval", "global"}
        Joint piecewise-constant disturbance offsets (default) or one constant
        offset kd per axis (eq. 35 as written).
    disturbance_order : int
        With ``offsets="per_interval"``: degree of the polynomial in time that
        models the disturbance torque within one interval (0 is the paper's
        piecewise-constant ū_d of eq. 43; 1 and 2 follow a smoothly varying gust
        through the interval).
    input_hold : {"linear", "zoh"}
        How inputs behave between samples: "linear" integrates them with the
        trapezium rule (eq. 36; right for a pilot's continuously moving sticks),
        "zoh" with the left rectangle (exact for commands a digital controller
        holds over each sample, as in the environment).
    prefilter : bool
        Zero-phase FIR low-pass, pass 4 Hz / stop 8 Hz, on rates and sticks (Section 3.1).
    pass_hz, stop_hz : float
        Filter band edges [Hz].
    delay : None, float, sequence of 3 float, or "auto"
        Servo delay per axis [s]; "auto" searches ``delay_grid``.
    delay_grid : sequence of float
        Candidate delays for ``delay="auto"`` [s] (default 0 to 0.5 s in 10 ms).
    max_iter : int
        Iterations of eqs. (39)-(40).
    tol : float
        Relative change of the least-squares error that stops the iteration.
    axes : sequence of str
        Axes to identify.

    Attributes
    ----------
    params_ : ModelParams
        Identified model (axes not identified stay 0).
    axes_ : dict of str to AxisFit
    fit_time_ : float
        Wall time of ``fit`` [s].
    flights_ : list of Flight
        The (filtered) flights the model was fitted on.
    """

    def __init__(self, structure="decoupled", extra_terms=(), interval: float = 1.0, offsets: str = "per_interval",
                 prefilter: bool = True, pass_hz: float = DEFAULT_PASS_HZ, stop_hz: float = DEFAULT_STOP_HZ,
                 disturbance_order: int = 2, input_hold: str = "linear", delay=None, delay_grid=None,
                 max_iter: int = 20, tol: float = 1e-3, axes=AXES):
        self.structure = structure
        self.extra_terms = extra_terms
        self.interval = interval
        self.offsets = offsets
        self.prefilter = prefilter
        self.pass_hz = pass_hz
        self.stop_hz = stop_hz
        self.disturbance_order = disturbance_order
        self.input_hold = input_hold
        self.delay = delay
        self.delay_grid = delay_grid
        self.max_iter = max_iter
        self.tol = tol
        self.axes = axes

    # ----------------------------------------------------------------- set-up
    def _param_names(self) -> dict[int, tuple[str, ...]]:
        if isinstance(self.structure, dict):
            base = {int(k): tuple(v) for k, v in self.structure.items()}
        elif self.structure == "decoupled":
            base = dict(DECOUPLED)
        elif self.structure == "coupled":
            base = dict(COUPLED)
        else:
            raise ValueError(f"structure must be 'decoupled', 'coupled' or a dict, got {self.structure!r}")
        for name in self.extra_terms:
            if name not in EXTRA_PARAMS:
                raise ValueError(f"unknown extra term {name!r}; known: {', '.join(EXTRA_PARAMS)}")
            axis = TERMS[name].axis
            base[axis] = tuple(base.get(axis, ())) + (name,)
        for axis, names in base.items():
            for name in names:
                if name not in TERMS or TERMS[name].axis != axis:
                    raise ValueError(f"parameter {name!r} does not act on axis {axis}")
        return base

    def _delays(self) -> list:
        d = self.delay
        if d is None:
            return [0.0, 0.0, 0.0]
        if isinstance(d, str):
            if d != "auto":
                raise ValueError(f"delay must be None, seconds, 3 values or 'auto', got {d!r}")
            return ["auto"] * 3
        if np.ndim(d) == 0:
            return [float(d)] * 3
        d = [float(v) for v in d]
        if len(d) != 3:
            raise ValueError(f"delay needs one value per axis (roll, pitch, yaw), got {len(d)}")
        return d

    # ------------------------------------------------------------------- fit
    def fit(self, flight) -> "IntegralIdentifier":
        """Identify the parameters of every requested axis.

        Parameters
        ----------
        flight : Flight or sequence of Flight
            One flight, or several flights of the same sample rate: their
            intervals are pooled into one least-squares problem (eq. 35), which
            is possible because every interval restarts from measured data (eq. 34).

        Raises
        ------
        IdentifiabilityError
            A flight is too short for the intervals, the flights' sample rates
            differ, or an axis is not excited (the normalised least-squares
            problem is ill-conditioned; its condition number is reported).
        """
        t0 = _time.perf_counter()
        if self.offsets not in ("per_interval", "global"):
            raise ValueError(f"offsets must be 'per_interval' or 'global', got {self.offsets!r}")
        if self.input_hold not in ("linear", "zoh"):
            raise ValueError(f"input_hold must be 'linear' or 'zoh', got {self.input_hold!r}")
        if int(self.disturbance_order) != self.disturbance_order or not 0 <= self.disturbance_order <= 3:
            raise ValueError(f"disturbance_order must be an integer 0..3, got {self.disturbance_order!r}")
        flights = [flight] if isinstance(flight, Flight) else list(flight)
        if not flights:
            raise ValueError("fit needs at least one flight")
        names = self._param_names()
        delays = self._delays()
        datas = [lowpass_flight(f, self.pass_hz, self.stop_hz) if self.prefilter else f for f in flights]
        fs = datas[0].sample_rate
        for d in datas[1:]:
            if abs(d.sample_rate - fs) > 1e-3 * fs:
                raise IdentifiabilityError(
                    f"flights must share one sample rate to be pooled; got {fs:.3f} Hz and {d.sample_rate:.3f} Hz"
                )
        dt = 1.0 / fs
        N = int(round(self.interval * fs))
        if N < 2:
            raise IdentifiabilityError(f"interval {self.interval} s holds {N} samples at {fs:.1f} Hz; need at least 2")
        starts = [np.arange((d.n - 1) // N) * N for d in datas]
        n_int = sum(s.size for s in starts)
        if n_int < 2:
            raise IdentifiabilityError(
                f"flight of {sum(d.duration for d in datas):.2f} s holds {n_int} interval(s) of {self.interval} s; "
                "need at least 2 (use a longer flight or shorter intervals)"
            )
        Wr = np.concatenate([_windows(d.rates, s, N) for d, s in zip(datas, starts)], axis=1)  # (3, n_int, N+1)
        Wcol = np.concatenate([_windows(d.sticks[2], s, N) for d, s in zip(datas, starts)], axis=0)
        start_times = np.concatenate([d.time[s] for d, s in zip(datas, starts)])

        def command_windows(a, tau):
            out = []
            for d, s in zip(datas, starts):
                cmd = d.sticks[[0, 1, 3]].copy()
                cmd[a] = pade_filter(cmd[a], tau, fs)
                out.append(_windows(cmd, s, N))
            return np.concatenate(out, axis=1)

        fits = {}
        values = {}
        for axis_name in self.axes:
            a = AXES.index(axis_name)
            axis_params = names.get(a, ())
            if not axis_params:
                continue
            if len(axis_params) * MIN_ROWS_PER_PARAM > n_int * N:
                raise IdentifiabilityError(
                    f"{axis_name}: {n_int * N} samples for {len(axis_params)} parameters; need at least "
                    f"{len(axis_params) * MIN_ROWS_PER_PARAM}"
                )
            grid = delays[a]
            if grid == "auto":
                candidates = self.delay_grid if self.delay_grid is not None else np.arange(0.0, 0.501, 0.01)
                scores = [self._fit_axis(a, axis_params, Wr, command_windows(a, tau), Wcol, dt, start_times,
                                         max_iter=1, check=False).r2 for tau in candidates]
                tau = float(candidates[int(np.argmax(scores))])
            else:
                tau = float(grid)
            fit = self._fit_axis(a, axis_params, Wr, command_windows(a, tau), Wcol, dt, start_times,
                                 max_iter=self.max_iter, check=True)
            fit = AxisFit(**{**fit.__dict__, "delay": tau})
            fits[axis_name] = fit
            values.update(fit.params)
            values[f"tau_{axis_name}"] = tau
        self.axes_ = fits
        self.params_ = ModelParams().with_values(**values)
        self.flights_ = datas
        self.fit_time_ = _time.perf_counter() - t0
        return self

    def _fit_axis(self, a, axis_params, Wr, Wc, Wcol, dt, start_times, max_iter, check) -> AxisFit:
        """Eqs. (32)-(40) for one axis on windows (3, n_int, N+1) of rates and commands."""
        N = Wr.shape[-1] - 1
        terms = [TERMS[p] for p in axis_params]
        feats = [t.feature for t in terms]
        per_interval = self.offsets == "per_interval"
        keep = [j for j, f in enumerate(feats) if not (per_interval and f == "1")]
        kfeats = [feats[j] for j in keep]
        signs = np.array([terms[j].sign for j in keep])[:, None, None]
        input_only = [f not in RATE_DEPENDENCE for f in kfeats]
        own = [a in RATE_DEPENDENCE.get(f, ()) for f in kfeats]  # re-evaluated at each iteration
        y_meas = Wr[a][:, 1:]
        p0 = Wr[a][:, :1]
        y = y_meas - p0  # eq. (37)
        n_int = y.shape[0]
        if per_interval:
            B, Q, B_pinv, Qt = _disturbance_basis(N, dt, self.disturbance_order)
            yp = _project_out(y, Q)
        else:
            yp = y
        b = yp.ravel()
        history = []
        best = None
        # Integrals of every feature from each interval start (eq. 36), sign of eq. (18)/(21) folded in.
        F = evaluate_features(kfeats, Wr, Wc, Wcol)  # (m, n_int, N+1)
        scale_f = (0.5 * dt) * signs
        X = _interval_cumsum(F[..., 1:] + F[..., :-1]) * scale_f
        if self.input_hold == "zoh" and any(input_only):
            X[input_only] = (np.cumsum(F[:, :, :-1], axis=-1) * (dt * signs))[input_only]
        slow = []
        if per_interval:
            # Input features that hardly change within an interval (collective) are all but
            # absorbed by the per-interval disturbance: estimate them between intervals.
            cand = [i for i in range(len(kfeats)) if input_only[i] and kfeats[i] != "1"]
            if cand:
                Fs = F[cand]
                Fw = _project_out(Fs, Qt)  # the feature less a per-interval polynomial like the disturbance's
                Fc = Fs - Fs.mean(axis=(1, 2), keepdims=True)
                within = np.einsum("ijk,ijk->i", Fw, Fw)
                total = np.einsum("ijk,ijk->i", Fc, Fc)
                slow = [i for k, i in enumerate(cand) if total[k] > 0 and within[k] < SLOW_FRACTION * total[k]]
            slow_means = [F[i].mean(axis=1) * signs[i, 0, 0] for i in slow]
        fixed = [i for i in range(len(kfeats)) if i not in slow and not own[i]]
        ownu = [i for i in range(len(kfeats)) if i not in slow and own[i]]
        order = fixed + ownu
        if not order:
            raise IdentifiabilityError(f"{AXES[a]}: every regressor is constant within the intervals")

        def projected(Z):
            if len(Z) == 0:
                return np.zeros((0, b.size))
            return (_project_out(Z, Q) if per_interval else Z).reshape(len(Z), -1)  # Frisch-Waugh

        X_fixed_flat = X[fixed].reshape(len(fixed), b.size)
        Xp_fixed = projected(X[fixed])
        G_ff = Xp_fixed @ Xp_fixed.T
        b_f = Xp_fixed @ b
        X_own = X[ownu]
        for it in range(max(1, max_iter)):
            if it > 0:
                # eqs. (39)-(40): p_approx replaces the measured own-axis rate in the integrals
                rates = list(Wr)
                rates[a] = np.concatenate([p0, approx], axis=1)
                Fo = evaluate_features([kfeats[i] for i in ownu], rates, Wc, Wcol)
                X_own = _interval_cumsum(Fo[..., 1:] + Fo[..., :-1]) * scale_f[ownu]
            Xp_own = projected(X_own)
            nf = len(fixed)
            G_raw = np.empty((len(order), len(order)))
            G_raw[:nf, :nf] = G_ff
            G_raw[:nf, nf:] = Xp_fixed @ Xp_own.T
            G_raw[nf:, :nf] = G_raw[:nf, nf:].T
            G_raw[nf:, nf:] = Xp_own @ Xp_own.T
            rhs = np.concatenate([b_f, Xp_own @ b])
            scale = np.sqrt(np.diag(G_raw))
            if np.any(scale == 0):
                zero = axis_params[keep[order[int(np.argmin(scale))]]]
                raise IdentifiabilityError(
                    f"{AXES[a]} axis is not identifiable from this flight: the regressor of {zero} is identically "
                    f"zero (condition number inf); the input is probably not excited (command std {np.std(Wc[a]):.2g})"
                )
            G = G_raw / np.outer(scale, scale)
            ev = np.linalg.eigvalsh(G)
            cond = float(np.sqrt(ev[-1] / ev[0])) if ev[0] > 0 else float("inf")
            if check and (not np.isfinite(cond) or cond > MAX_CONDITION):
                raise IdentifiabilityError(
                    f"{AXES[a]} axis is not identifiable from this flight: the normalised least-squares "
                    f"problem (eq. 35) has condition number {cond:.3g} (limit {MAX_CONDITION:.0e}); "
                    f"the input is probably not excited (command std {np.std(Wc[a]):.2g})"
                )
            beta = np.zeros(len(keep))
            beta[order] = np.linalg.solve(G, rhs / scale) / scale
            fitted = (beta[fixed] @ X_fixed_flat + beta[ownu] @ X_own.reshape(len(ownu), b.size)).reshape(y.shape)
            slow_se = None
            if per_interval:
                coef = B_pinv @ (y - fitted).T  # (o, n_int): the per-interval disturbance
                T = N * dt
                offsets = sum(coef[j] * T**j / (j + 1) for j in range(coef.shape[0]))  # mean torque
                if slow:
                    # between-interval regression of the mean torque on the slow features' means
                    M = np.column_stack([np.ones(n_int)] + slow_means)
                    c = np.linalg.lstsq(M, offsets, rcond=None)[0]
                    beta[slow] = c[1:]
                    r_between = offsets - M @ c
                    s2 = float(r_between @ r_between) / max(n_int - M.shape[1], 1)
                    slow_se = np.sqrt(np.clip(np.diag(s2 * np.linalg.pinv(M.T @ M)), 0, None))[1:]
                    offsets = offsets - M[:, 1:] @ c[1:]
                approx = p0 + fitted + coef.T @ B.T  # eqs. (39)-(40)
            else:
                offsets = np.zeros(0)
                approx = p0 + fitted
            d = approx - y_meas
            err = float(np.einsum("ij,ij->", d, d)) / d.size
            history.append(err)
            if best is None or err <= best[0]:
                best = (err, beta, offsets, Xp_own, G_raw, cond, slow_se)
            if not ownu or (it > 0 and (abs(history[-2] - err) <= self.tol * max(history[-2], 1e-30)
                                        or err > history[-2])):
                break  # converged, or the Picard step stopped improving: keep the best iterate
        err, beta, offsets, Xp_own, G_raw, cond, slow_se = best
        resid = b - beta[fixed] @ Xp_fixed - beta[ownu] @ Xp_own
        dof = max(b.size - beta.size - (n_int * (self.disturbance_order + 1) if per_interval else 0), 1)
        sigma2 = float(resid @ resid) / dof
        se = np.full(beta.size, np.nan)
        try:
            se[order] = np.sqrt(np.clip(np.diag(sigma2 * np.linalg.inv(G_raw)), 0, None))
        except np.linalg.LinAlgError:
            pass
        if slow_se is not None:
            se[slow] = slow_se
        params = {axis_params[j]: float(beta[i]) for i, j in enumerate(keep)}
        std = {axis_params[j]: float(se[i]) for i, j in enumerate(keep)}
        if per_interval and "1" in feats:
            off_name = axis_params[feats.index("1")]
            params[off_name] = float(np.mean(offsets))
            std[off_name] = float(np.std(offsets) / np.sqrt(offsets.size))
        ss_tot = float(np.sum((b - b.mean()) ** 2)) or 1.0
        r2 = 1.0 - float(resid @ resid) / ss_tot
        return AxisFit(AXES[a], params, std, 0.0, float(cond), r2, tuple(history), offsets, start_times)

    # ----------------------------------------------------------------- use
    def _check_fitted(self):
        if not hasattr(self, "params_"):
            raise NotFittedError("this IntegralIdentifier is not fitted yet; call fit(flight) first")

    def predict(self, flight: Flight) -> np.ndarray:
        """Forward-simulate the identified model with the flight's sticks; rates (3, n) [rad/s]."""
        self._check_fitted()
        from .model import initial_state, simulate

        x0 = initial_state(rates=flight.rates[:, 0], euler=flight.attitude[:, 0], sticks=flight.sticks[[0, 1, 3], 0])
        return simulate(self.params_, flight.time, flight.sticks, x0=x0)[:3]

    def summary(self) -> dict:
        """JSON-ready fit statistics per axis."""
        self._check_fitted()
        return {
            name: {
                "params": f.params, "std_errors": f.std_errors, "delay_s": f.delay,
                "condition_number": f.condition, "r2": f.r2, "iterations": len(f.history),
                "lsq_error_history": list(f.history),
            }
            for name, f in self.axes_.items()
        }
