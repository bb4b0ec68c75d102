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
from scipy.linalg import lapack

from heli_core.params import ModelParams
from heli_core.servo import pade_filter  # noqa: F401  (re-exported: it lived here before heli_core)
from heli_core.terms import (AXES, COUPLED, DECOUPLED, EXTRA_PARAMS, FEATURE_EXPRESSIONS, FEATURES, RATE_DEPENDENCE,
                             STICK_ROW, TERMS)

from .errors import IdentifiabilityError, NotFittedError
from .fit_warnings import require_moving_sticks
from .flight import Flight
from .preprocess import DEFAULT_PASS_HZ, DEFAULT_STOP_HZ, lowpass_flight

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
    residual : ndarray, shape (n_intervals, N), optional
        Integral residual ``p_approx - p`` of the best iterate at samples 1..N of
        every interval (eqs. 39-40), with the per-interval disturbance polynomial
        removed; its increments are the equation error the residual tests of
        :mod:`identification.residual_tests` examine.
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


def _split_intervals(values: np.ndarray, n_int: int, length: int):
    """values (..., n) -> (inner (..., n_int, length), first (..., n_int)) for adjacent intervals of ``length`` steps.

    Interval i spans samples ``i*length .. (i+1)*length``: ``first`` holds its
    first sample (the measured initial value of eq. 34) and ``inner`` the
    remaining ``length``, so an interval's end point is the next one's first
    sample. Both are views of ``values`` (no copy).
    """
    values = np.asarray(values, dtype=float)
    stop = n_int * length
    inner = values[..., 1 : stop + 1].reshape(values.shape[:-1] + (n_int, length))
    return inner, values[..., 0:stop:length]


def _pool(parts):
    """Concatenate per-flight (inner, first) pairs along the interval axis (no copy for one flight)."""
    if len(parts) == 1:
        return parts[0]
    return (np.concatenate([p[0] for p in parts], axis=-2), np.concatenate([p[1] for p in parts], axis=-1))


@lru_cache(maxsize=16)
def _disturbance_basis(N: int, dt: float, order: int):
    """Per-interval disturbance basis of degree ``order`` on N samples of step dt.

    Returns ``B`` (N, o): integrals t^(j+1)/(j+1) of the torque polynomial t^j;
    ``Q``: orthonormal basis of B; ``B_pinv``; ``Qt`` (N+1, o): orthonormal basis
    of the polynomials themselves on the N+1 samples of an interval; ``QB``
    (N, 2o) = [Q, B_pinv^T], so that one product gives both the projection
    coefficients and the least-squares polynomial coefficients of a signal.
    """
    tt = np.arange(1, N + 1) * dt
    B = np.stack([tt ** (j + 1) / (j + 1) for j in range(order + 1)], axis=1)
    Q, _ = np.linalg.qr(B)
    Qt, _ = np.linalg.qr(np.vander(np.arange(N + 1) * dt, order + 1))
    B_pinv = np.linalg.pinv(B)
    QB = np.ascontiguousarray(np.hstack([Q, B_pinv.T]))
    QT = np.ascontiguousarray(Q.T)
    for arr in (B, Q, Qt, B_pinv, QB, QT):
        arr.setflags(write=False)
    return B, Q, B_pinv, Qt, QB, QT


@lru_cache(maxsize=64)
def _integral_plan(N: int, diag: float, scale: float):
    """Block size b (a divisor of N near sqrt(N)) and the matrices of a two-level weighted prefix sum.

    ``inner`` (b, b) maps a block of samples to ``scale`` times its weighted
    running sums (weight 1 on earlier samples, ``diag`` on the current one);
    ``outer`` (nb, nb) sums the totals of the earlier blocks.
    """
    divisors = [b for b in range(4, N // 4 + 1) if N % b == 0]
    if not divisors:
        return None
    b = min(divisors, key=lambda d: abs(d - N**0.5))
    inner = scale * (np.triu(np.ones((b, b)), 1) + diag * np.eye(b))
    outer = np.triu(np.ones((N // b, N // b)), 1)
    for arr in (inner, outer):
        arr.setflags(write=False)
    return b, inner, outer


def _interval_integral(inner: np.ndarray, first, scale: float, diag: float = 0.5, first_weight: float = 0.5,
                       out=None) -> np.ndarray:
    """Running integral over every interval (eq. 36), as small matrix products.

    For interval samples ``f_0 = first`` and ``f_1..f_N = inner`` (n_int, N)
    returns, for k = 1..N, ``scale * (first_weight*f_0 + f_1 + ... + f_{k-1} + diag*f_k)``:
    the trapezium rule times dt when ``scale = dt`` (weights 1/2, 1/2), the left
    rectangle with ``diag=0, first_weight=1``. ``first=None`` means f_0 = 0.
    ``out`` must be C-contiguous.

    numpy's cumsum runs at several ns per element; splitting each interval into
    blocks, prefix-summing inside the blocks (one BLAS product) and adding the
    prefix of the block totals turns it into BLAS work. Exact up to rounding
    (the same sums, regrouped).
    """
    n_int, N = inner.shape
    if out is None:
        out = np.empty((n_int, N))
    plan = _integral_plan(N, float(diag), float(scale))
    if plan is None:
        np.cumsum(inner, axis=-1, out=out)
        if diag != 1.0:
            out -= (1.0 - diag) * inner
        out *= scale
        if first is not None:
            out += (scale * first_weight) * first[:, None]
        return out
    b, inner_m, outer_m = plan
    nb = N // b
    blocks = inner.reshape(n_int * nb, b)
    running = out.reshape(n_int * nb, b)
    np.matmul(blocks, inner_m, out=running)  # weighted running sums within each block
    totals = running[:, b - 1] + (scale * (1.0 - diag)) * blocks[:, b - 1]
    before = totals.reshape(n_int, nb) @ outer_m  # sums of the earlier blocks
    if first is not None:
        before += (scale * first_weight) * first[:, None]
    out.reshape(n_int, nb, b)[...] += before[:, :, None]
    return out


_DOT_CHUNK = 8192


def _sum_squares(x: np.ndarray) -> float:
    """``x @ x`` for a contiguous 1-D array, summed over chunks.

    OpenBLAS runs ddot on more than 10000 elements on several threads; when the
    other cores are busy, the call then waits for them for milliseconds. The
    chunks stay single-threaded (the sum is the same up to rounding).
    """
    if x.size <= _DOT_CHUNK:
        return float(np.dot(x, x))
    total = 0.0
    for i in range(0, x.size, _DOT_CHUNK):
        part = x[i : i + _DOT_CHUNK]
        total += float(np.dot(part, part))
    return total


def _eigvalsh(G: np.ndarray) -> np.ndarray:
    """Eigenvalues of the small symmetric matrix G, ascending (LAPACK dsyevd, as numpy's eigvalsh, less its overhead)."""
    w, _, info = lapack.dsyevd(G, compute_v=0, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError("Eigenvalues did not converge")
    return w


def _solve(G: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solution of the small system G x = rhs (LAPACK dgesv, as numpy's solve, less its overhead)."""
    _, _, x, info = lapack.dgesv(G, rhs)
    if info != 0:
        raise np.linalg.LinAlgError("Singular matrix")
    return x


def _feature(name: str, rates, cmd, col, shape) -> np.ndarray:
    """One feature of :data:`identification.terms.FEATURES` (broadcast to ``shape``)."""
    return np.broadcast_to(FEATURES[name](rates, cmd, col), shape)


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
        require_moving_sticks(flights, self.axes)
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
        counts = [(d.n - 1) // N for d in datas]
        n_int = sum(counts)
        if n_int < 2:
            raise IdentifiabilityError(
                f"flight of {sum(d.duration for d in datas):.2f} s holds {n_int} interval(s) of {self.interval} s; "
                "need at least 2 (use a longer flight or shorter intervals)"
            )
        # Every signal as (samples 1..N of each interval (n_int, N), first sample of each interval (n_int,)).
        rates = _pool([_split_intervals(d.rates, m, N) for d, m in zip(datas, counts)])
        col = _pool([_split_intervals(d.sticks[2], m, N) for d, m in zip(datas, counts)])
        sticks = [_pool([_split_intervals(d.sticks[i], m, N) for d, m in zip(datas, counts)]) for i in STICK_ROW]
        start_times = np.concatenate([d.time[: m * N : N] for d, m in zip(datas, counts)])

        def commands(a, tau):
            """Servo-side commands (eq. 31): the stick of axis ``a`` through the Padé delay ``tau``."""
            cmd = list(sticks)
            if tau > 0:
                i = STICK_ROW[a]
                cmd[a] = _pool([_split_intervals(pade_filter(d.sticks[i], tau, fs), m, N)
                                for d, m in zip(datas, counts)])
            return [c[0] for c in cmd], [c[1] for c in cmd]

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
                scores = [self._fit_axis(a, axis_params, rates, commands(a, tau), col, dt, start_times,
                                         max_iter=1, check=False).r2 for tau in candidates]
                tau = float(candidates[int(np.argmax(scores))])
            else:
                tau = float(grid)
            fit = self._fit_axis(a, axis_params, rates, commands(a, tau), col, dt, start_times,
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

    def _fit_axis(self, a, axis_params, rates, cmds, col, dt, start_times, max_iter, check) -> AxisFit:
        """Eqs. (32)-(40) for one axis.

        ``rates`` (3 rates), ``cmds`` (3 servo-side commands) and ``col`` come as
        ``(inner, first)``: samples 1..N of every interval, shape (..., n_int, N),
        and each interval's first sample, shape (..., n_int) (:func:`_split_intervals`).

        Implementation. The regressors of eq. (35), with the per-interval
        disturbance polynomial projected out (Frisch-Waugh), and the projected
        increments ``y_p`` are the rows of one array ``A``; its Gram matrix holds
        the normal equations, and after each solve ``d = A_x beta - y_p`` is
        ``p_approx - p`` at every sample (eqs. 39-40), whose mean square is the
        least-squares error of the iteration. The next iteration's integral of
        ``p_approx`` is the measured rate's integral plus that of ``d`` (for the
        linear own-rate feature; other features are re-evaluated on p_approx),
        and only the Gram rows of the own-rate regressors are recomputed. The
        per-interval disturbance coefficients are obtained for the best iterate
        only, from each regressor's polynomial coefficients.
        """
        Rg, R0 = rates
        Ug, U0 = cmds
        Cg, C0 = col
        n_int, N = Rg.shape[-2:]
        shape = (n_int, N)
        size = n_int * N
        terms = [TERMS[p] for p in axis_params]
        feats = [t.feature for t in terms]
        per_interval = self.offsets == "per_interval"
        keep = [j for j, f in enumerate(feats) if not (per_interval and f == "1")]
        kfeats = [feats[j] for j in keep]
        signs = [terms[j].sign for j in keep]
        input_only = [f not in RATE_DEPENDENCE for f in kfeats]
        own = [a in RATE_DEPENDENCE.get(f, ()) for f in kfeats]  # re-evaluated at each iteration
        zoh = self.input_hold == "zoh"
        y_meas = Rg[a]
        p0 = R0[a]

        def inner_of(i, rates_inner=Rg):
            return _feature(kfeats[i], rates_inner, Ug, Cg, shape)

        def first_of(i):
            return _feature(kfeats[i], R0, U0, C0, (n_int,))

        def command_std():
            return np.std(np.concatenate([U0[a][:, None], Ug[a]], axis=1))

        slow = []
        if per_interval:
            _, Q, _, Qt, QB, QT = _disturbance_basis(N, dt, self.disturbance_order)
            o = Q.shape[1]
            # Input features that hardly change within an interval (collective) are all but
            # absorbed by the per-interval disturbance: estimate them between intervals.
            for i in range(len(kfeats)):
                if not input_only[i] or kfeats[i] == "1":
                    continue
                f_inner, f_first = inner_of(i), first_of(i)
                centred = np.empty((n_int, N + 1))  # every interval's N+1 samples less the mean of all
                mean = (f_inner.sum() + f_first.sum()) / centred.size
                np.subtract(f_first, mean, out=centred[:, 0])
                np.subtract(f_inner, mean, out=centred[:, 1:])
                total = _sum_squares(centred.ravel())
                fit_q = centred @ Qt  # constants lie in span(Qt): the fit of the feature less its mean
                within = total - _sum_squares(fit_q.ravel())  # what a per-interval polynomial leaves
                if total > 0 and within < SLOW_FRACTION * total:
                    slow.append(i)
            slow_means = [(inner_of(i).sum(axis=1) + first_of(i)) * (signs[i] / (N + 1)) for i in slow]
        fixed = [i for i in range(len(kfeats)) if i not in slow and not own[i]]
        ownu = [i for i in range(len(kfeats)) if i not in slow and own[i]]
        order = fixed + ownu
        if not order:
            raise IdentifiabilityError(f"{AXES[a]}: every regressor is constant within the intervals")
        nf, k = len(fixed), len(order)

        A = np.empty((k + 1, n_int, N))  # rows: regressors (fixed, then own-rate), then the increments
        A2 = A.reshape(k + 1, size)
        scratch = np.empty(shape)

        def project(row):
            """Remove from every interval of A[row] its least-squares fit on Q; return its coefficients on B."""
            X = A[row]
            XQB = X @ QB
            np.matmul(XQB[:, :o], QT, out=scratch)
            X -= scratch
            return XQB[:, o:]

        def integrate(i, rates_inner=Rg, out=None):
            """Integral of feature i from each interval start (eq. 36), sign of eq. (18)/(21) folded in."""
            rect = zoh and input_only[i]
            return _interval_integral(inner_of(i, rates_inner), first_of(i), dt * signs[i],
                                      diag=0.0 if rect else 0.5, first_weight=1.0 if rect else 0.5, out=out)

        np.subtract(y_meas, p0[:, None], out=A[k])  # eq. (37)
        coef_y = project(k) if per_interval else None
        coef_x = [None] * k  # per regressor: coefficients of its per-interval polynomial fit on B
        for r, i in enumerate(fixed):
            integrate(i, out=A[r])
            if per_interval:
                coef_x[r] = project(r)
        # The own-rate feature itself is linear in p_approx = p + d: its integral is the measured one plus d's.
        linear = [FEATURE_EXPRESSIONS[kfeats[i]] == "pqr"[a] for i in ownu]
        measured = {}
        for r, i in enumerate(ownu, start=nf):
            integrate(i, out=A[r])
            if linear[r - nf]:
                measured[r] = A[r].copy()
            if per_interval:
                coef_x[r] = project(r)

        # Normal equations of eq. (35): Gram of the regressors, right-hand side, |y_p|^2 (two plain
        # products: numpy's symmetric path for A @ A.T is slow for so few rows).
        M = np.hstack([A2 @ A2[:k].T, A2 @ A2[k:].T])
        M = np.triu(M) + np.triu(M, 1).T
        d = np.empty(size)
        d2 = d.reshape(shape)
        coefs = np.empty(k + 1)
        coefs[k] = -1.0
        history = []
        best = None
        for it in range(max(1, max_iter)):
            if it > 0:
                # eqs. (39)-(40): p_approx = p + d replaces the measured own-axis rate in the integrals
                rates_approx = None
                for r, i in enumerate(ownu, start=nf):
                    if linear[r - nf]:
                        _interval_integral(d2, None, dt * signs[i], out=A[r])
                        A[r] += measured[r]
                    else:
                        if rates_approx is None:
                            rates_approx = [Rg[0], Rg[1], Rg[2]]
                            rates_approx[a] = y_meas + d2
                        integrate(i, rates_approx, out=A[r])
                    if per_interval:
                        coef_x[r] = project(r)
                M_own = A2 @ A2[nf:k].T
                M[:, nf:k] = M_own
                M[nf:k, :] = M_own.T
                if k - nf > 1:
                    block = M_own[nf:k]
                    M[nf:k, nf:k] = np.triu(block) + np.triu(block, 1).T
            G_raw = M[:k, :k].copy()
            rhs = M[:k, k]
            scale = np.sqrt(np.diag(G_raw))
            if np.any(scale == 0):
                zero = axis_params[keep[order[int(np.argmin(scale))]]]
                raise IdentifiabilityError(
                    f"{AXES[a]} axis is not identifiable from this flight: the regressor of {zero} is identically "
                    f"zero (condition number inf); the input is probably not excited (command std {command_std():.2g})"
                )
            G = G_raw / np.outer(scale, scale)
            ev = _eigvalsh(G)
            cond = float(np.sqrt(ev[-1] / ev[0])) if ev[0] > 0 else float("inf")
            if check and (not np.isfinite(cond) or cond > MAX_CONDITION):
                raise IdentifiabilityError(
                    f"{AXES[a]} axis is not identifiable from this flight: the normalised least-squares "
                    f"problem (eq. 35) has condition number {cond:.3g} (limit {MAX_CONDITION:.0e}); "
                    f"the input is probably not excited (command std {command_std():.2g})"
                )
            sol = _solve(G, rhs / scale) / scale
            coefs[:k] = sol
            np.matmul(coefs, A2, out=d)  # p_approx - p: the fit less the projected increments
            sq = _sum_squares(d)
            err = sq / size
            history.append(err)
            if best is None or err <= best[0]:
                best = (err, sol, coef_x[nf:], G_raw, cond, sq, d2.copy())
            if not ownu or (it > 0 and (abs(history[-2] - err) <= self.tol * max(history[-2], 1e-30)
                                        or err > history[-2])):
                break  # converged, or the Picard step stopped improving: keep the best iterate
        err, sol, coef_own, G_raw, cond, sq, residual = best
        beta = np.zeros(len(keep))
        beta[order] = sol
        slow_se = None
        if per_interval:
            # the per-interval disturbance of the best iterate: polynomial fit of y - fitted on B
            coef = coef_y - sum(s * c for s, c in zip(sol, coef_x[:nf] + coef_own))
            coef = coef.T  # (o, n_int)
            T = N * dt
            offsets = np.array([T**j / (j + 1) for j in range(coef.shape[0])]) @ coef  # mean torque
            if slow:
                # between-interval regression of the mean torque on the slow features' means
                Mb = np.column_stack([np.ones(n_int)] + slow_means)
                c = np.linalg.lstsq(Mb, offsets, rcond=None)[0]
                beta[slow] = c[1:]
                r_between = offsets - Mb @ c
                s2 = float(r_between @ r_between) / max(n_int - Mb.shape[1], 1)
                slow_se = np.sqrt(np.clip(np.diag(s2 * np.linalg.pinv(Mb.T @ Mb)), 0, None))[1:]
                offsets = offsets - Mb[:, 1:] @ c[1:]
        else:
            offsets = np.zeros(0)
        dof = max(size - beta.size - (n_int * (self.disturbance_order + 1) if per_interval else 0), 1)
        sigma2 = sq / dof  # sq: squared norm of the residual b - A_x beta of the best iterate
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
            params[off_name] = float(offsets.mean())
            spread = offsets - params[off_name]
            std[off_name] = float(np.sqrt(spread @ spread / offsets.size) / np.sqrt(offsets.size))
        b = A2[k]
        centred_b = b - b.mean()
        ss_tot = _sum_squares(centred_b) or 1.0
        r2 = 1.0 - sq / ss_tot
        return AxisFit(AXES[a], params, std, 0.0, float(cond), r2, tuple(history), offsets, start_times, residual)

    # ----------------------------------------------------------------- use
    def _check_fitted(self):
        if not hasattr(self, "params_"):
            raise NotFittedError("this IntegralIdentifier is not fitted yet; call fit(flight) first")

    def predict(self, flight: Flight) -> np.ndarray:
        """Forward-simulate the identified model with the flight's sticks; rates (3, n) [rad/s]."""
        self._check_fitted()
        from heli_core.physics import forward_rates

        return forward_rates(self.params_, flight)

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
