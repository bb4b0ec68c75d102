"""The search of one axis' likelihood: its data at a servo delay, the gust models tried, the optimum and what
it says (:class:`AxisProblem`).

The estimator (:class:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier`) fits an axis by
minimising its concentrated likelihood (:class:`~identification.likelihood.axis_likelihood.AxisLikelihood`)
over the damping, the wind model, the input's hold fraction and, when profiled, the delay, with the linear
parameters solved at every step. The servo lag's profile (:mod:`identification.likelihood.servo_lag`), the
prediction on held-out blocks (:mod:`identification.likelihood.ahead_prediction`) and the diagnosis by
likelihood (:mod:`identification.diagnosis.likelihood_diagnoser`) search the same way. What every such search
shares -- the axis, its terms, the flights, the burn-in, the hold in force, the evaluation budget, whether
the damping is searched -- is one :class:`AxisProblem`; the searches are its methods, each taking only what
changes between calls (the delay, the start, the gust models, the lag).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from scipy import optimize

from heli_core.servo import pade_filter
from heli_core.terms import AXES, FEATURES, RATE_DEPENDENCE, STICK_ROW, TERMS

from .axis_fit import MLAxisFit
from .axis_likelihood import MIN_SERVO_DELAY, AxisData, AxisLikelihood, simulation_r2
from ..validation.fit_warnings import gyro_filter
from .gyro_path import matched
from .input_hold import HOLD_START, hold_fraction
from .state_space import HOLD_INDEX, N_NONLINEAR, ZETA_BOUNDS

OWN_RATE = ("p", "q", "r")
"""The feature that is each axis' own rate: its term is the damping, a state coefficient."""

COMMAND_FEATURE = ("u_lat", "u_lon", "u_ped")
"""The feature that is each axis' own servo-side command: its term goes through the servo model exactly."""

BURN_IN = 1.0
"""Seconds at the start of each flight left out of the likelihood while the filter settles (:attr:`AxisProblem.burn`
in samples)."""

MAX_SHIFT = 0.6
"""Largest input shift (a log whose input column lags the response) searched [s]."""

MAX_DELAY = 0.6
"""Largest servo delay searched [s]."""

XTOL, FTOL = 1e-6, 1e-8
"""Stopping tolerances of the likelihood search: a relative cost change of 1e-8 is a change of the
log-likelihood of about 1e-4 on a 300 s flight, far below any difference a test looks at."""

FD_STEP = 1e-5
"""Forward-difference step of the search's Jacobian, relative to ``max(1, |x|)`` of the damping, the gust model's
log time constants and levels, the hold fraction and ζ (:func:`forward_jacobian`). scipy's own, sqrt(eps) =
1.5e-8, read the innovations' rounding as slope: the same flight fitted with the Kalman gain changed in its 13th
digit (what another BLAS kernel or Riccati solver does) ended up to 16 apart in log-likelihood (more than 1 on 19 %
of 48 axis fits) and 2 % in damping, and on the real T-REX hover one machine's BLAS wrote a model where another's
diverged. At 1e-5 two such fits agree within 0.22 in log-likelihood, 0.01 % in damping on the bench's flights
(`python scripts/search_stability.py`, docs/method.md), on the optima central differences find, in fewer
evaluations than before. The alignment keeps scipy's step in its own unit (:data:`TAU_UNIT`)."""

DAMPING_BOUNDS = (-2.0, 200.0)
"""The interval each damping is searched in [1/s]: a damping at a bound was not placed by the data
(:func:`identification.validation.model_verdict.judge_identifier` asks the estimator for it)."""

TIME_CONSTANT_BOUNDS = ((0.8, 120.0), (0.02, 0.8))
"""Bounds of the slow and the fast gust time constants [s]."""

HOLD_DISAGREEMENT = 0.25
"""Largest difference of the hold fractions two gust models' searches may end at before each is searched again
from the other's (:meth:`AxisProblem.per_kind`)."""

TAU_UNIT = 2e4
"""Unit of the alignment in a search started at no delay [s]: scipy's finite-difference step (sqrt(eps) of a
unit) is then 0.3 ms, three times the band around 0 where no delay is modelled (MIN_SERVO_DELAY), a
thirtieth of a 100 Hz sample."""


def forward_jacobian(residual, upper, steps) -> tuple:
    """``(fun, jac)`` for ``scipy.optimize.least_squares``: ``residual`` and its forward-difference Jacobian with the
    step ``steps[j] * max(1, |x_j|)`` per parameter (backward where the forward one would pass ``upper``), the
    residual at the point itself reused from the search's last evaluation there (:data:`FD_STEP`)."""
    last = {}

    def fun(x):
        r = residual(x)
        last["x"], last["r"] = np.array(x, dtype=float, copy=True), r
        return r

    def jac(x):
        r0 = last["r"] if "x" in last and np.array_equal(last["x"], x) else residual(x)
        J = np.empty((r0.size, x.size))
        for j in range(x.size):
            h = steps[j] * max(1.0, abs(x[j]))
            xj = np.array(x, dtype=float, copy=True)
            xj[j] = x[j] + h if x[j] + h <= upper[j] else x[j] - h
            J[:, j] = (residual(xj) - r0) / (xj[j] - x[j])
        return J

    return fun, jac


class WindFit(NamedTuple):
    """The optimum of a search with the gust model it chose."""

    cost: float
    """Half the sum of squared normalised innovations at the optimum."""
    x: np.ndarray
    """The model part of the search vector (damping, gust model, hold fraction)."""
    kind: str
    """The gust model (:data:`identification.likelihood.state_space.WIND_MODELS`)."""
    tau: float
    """The alignment [s]: the servo delay (> 0) or the shift of a late input column (< 0)."""


@dataclass(frozen=True)
class AxisProblem:
    """One axis' likelihood to search: the axis, its terms, the flights, and how the search runs.

    Attributes
    ----------
    axis : int
        0 roll, 1 pitch, 2 yaw.
    names : tuple of str
        The parameters fitted on the axis (terms of :data:`heli_core.terms.TERMS`).
    flights : sequence of Flight
        The flights, aligned and cleaned as the fit takes them; several share the parameters and keep their
        own offset.
    burn : int
        Samples at the start of each flight left out of the likelihood while the filter settles.
    hold : "auto", str or float
        The input's hold in force (:func:`identification.likelihood.input_hold.hold_fraction`): ``"auto"``
        searches the fraction with the rest, anything else holds it.
    max_nfev : int
        Likelihood evaluations per search unless a search asks for another number.
    free_damping : bool or None
        Whether the damping is searched; None (default): when the axis has a damping term.
    """

    axis: int
    names: tuple
    flights: object
    burn: int
    hold: object = "auto"
    max_nfev: int = 100
    free_damping: bool | None = None

    @property
    def damping_name(self) -> str | None:
        """The axis' damping term among :attr:`names` (its feature is the axis' own rate), or None."""
        return next((p for p in self.names if TERMS[p].feature == OWN_RATE[self.axis]), None)

    @property
    def searches_damping(self) -> bool:
        """:attr:`free_damping`, or whether there is a damping term when it is None."""
        return self.damping_name is not None if self.free_damping is None else bool(self.free_damping)

    def on(self, flights) -> AxisProblem:
        """The same problem over other flights."""
        return replace(self, flights=flights)

    def hold_start(self) -> float:
        """The hold fraction a search starts from (searched) or keeps (held)."""
        # searched: from the middle, not from a bound where the trust region crawls (one in three fewer
        # likelihood evaluations on bench flights, the same optimum)
        return HOLD_START if self.hold == "auto" else hold_fraction(self.hold)

    def fixed(self, free_damping: bool = True) -> dict:
        """Entries of the search vector that are not searched, with their values."""
        fixed = {} if free_damping else {0: 0.0}
        if self.hold != "auto":
            fixed[HOLD_INDEX] = hold_fraction(self.hold)
        return fixed

    # ------------------------------------------------------------------ the data
    def data(self, tau: float, wind_model: str = "gm2", lag: float = 0.0) -> AxisData:
        """The likelihood's data at servo delay ``tau`` (> 0, Padé; < 0 the stick advanced) and lag ``lag``."""
        a, flights, lag = self.axis, self.flights, lag
        damping_name = self.damping_name
        linear = [p for p in self.names if p != damping_name and TERMS[p].feature != "1"]
        offset = next((p for p in self.names if TERMS[p].feature == "1"), None)

        corners = tuple(gyro_filter(f.metadata) for f in flights)

        def regressors(tau_or_shift):
            """Every flight's regressors with the axis' command delayed (> 0, Padé) or advanced (< 0), the
            commands through the gyro filter its log states (:mod:`.gyro_path`; the rates are logged through it)."""
            out = []
            for i, f in enumerate(flights):
                cmd = np.array([f.sticks[r] for r in STICK_ROW])
                if tau_or_shift > 0 or (lag > 0 and tau_or_shift == 0):
                    cmd[a] = pade_filter(f.sticks[STICK_ROW[a]], tau_or_shift, f.sample_rate, lag)
                elif tau_or_shift < 0:
                    cmd[a] = np.interp(f.time - tau_or_shift, f.time, f.sticks[STICK_ROW[a]])
                col = f.sticks[2]
                if corners[i] is not None:
                    cmd = np.array([matched(c, corners[i], f.sample_rate) for c in cmd])
                    col = matched(col, corners[i], f.sample_rate)
                rows = [TERMS[p].sign * np.broadcast_to(FEATURES[TERMS[p].feature](f.rates, cmd, col),
                                                        (f.n,)) for p in linear]
                if offset is not None:
                    rows += [np.full(f.n, float(j == i)) for j in range(len(flights))]
                out.append(np.array(rows, dtype=float).reshape(len(rows), f.n))
            return out

        ys = [np.asarray(f.rates[a], dtype=float) for f in flights]
        Xs = regressors(tau)
        reg_names = tuple(linear) + (tuple(f"{offset}@{j}" for j in range(len(flights))) if offset else ())
        command = next((j for j, p in enumerate(linear) if TERMS[p].feature == COMMAND_FEATURE[a]), None)
        servo_sticks = None
        if command is not None:
            sign = TERMS[linear[command]].sign
            servo_sticks = [sign * np.asarray(f.sticks[STICK_ROW[a]], dtype=float) for f in flights]
        causal = tuple(j for j, p in enumerate(linear) if TERMS[p].feature in RATE_DEPENDENCE)
        return AxisData(ys, Xs, reg_names, flights[0].dt, self.hold_start(), self.burn, wind_model, command,
                        servo_sticks, float(tau), causal, regressors, float(lag), corners)

    # ------------------------------------------------------------------ searches
    def search(self, like: AxisLikelihood, x0, max_nfev=None, tau0: float = 0.0):
        """Search the damping, the wind model and the input's hold fraction (and the delay when
        ``like.free_tau``) from ``x0``, the model part of a search vector (of either wind model) and ``tau0``.
        The damping stays at 0 unless :attr:`searches_damping`; the hold at :attr:`hold` unless "auto".
        Returns scipy's result, its ``x`` the whole search vector."""
        lo = np.array([DAMPING_BOUNDS[0], np.log(TIME_CONSTANT_BOUNDS[0][0]), np.log(TIME_CONSTANT_BOUNDS[1][0]),
                       np.log(1e-4), np.log(1e-4), 0.0, np.log(ZETA_BOUNDS[0])])
        hi = np.array([DAMPING_BOUNDS[1], np.log(TIME_CONSTANT_BOUNDS[0][1]), np.log(TIME_CONSTANT_BOUNDS[1][1]),
                       np.log(1e9), np.log(1e9), 1.0, np.log(ZETA_BOUNDS[1])])
        x0 = np.asarray(x0, dtype=float)
        start = list(x0[:HOLD_INDEX]) + [x0[HOLD_INDEX] if x0.size > HOLD_INDEX else self.hold_start()]
        if like.nw > HOLD_INDEX + 1:
            start.append(x0[HOLD_INDEX + 1] if x0.size > HOLD_INDEX + 1 else np.log(0.8))
        lo, hi = list(lo[:like.nw]), list(hi[:like.nw])
        if like.free_tau:
            start.append(tau0)
            lo.append(-MAX_SHIFT)
            hi.append(MAX_DELAY)
        lo, hi = np.array(lo), np.array(hi)
        fixed = self.fixed(self.searches_damping)
        full = np.array(start)
        for i, v in fixed.items():
            full[i] = v
        free = np.array([i not in fixed for i in range(full.size)])
        # an alignment search started in the band where no delay is modelled (|tau| <= MIN_SERVO_DELAY, where
        # the likelihood is flat) runs in units of TAU_UNIT: with x_scale="jac" the search is the same in any
        # units but for its finite-difference step, which then reaches past the band; scipy's step in seconds
        # (1.5e-8 s) saw no slope at 0 and the search never left it (a 20 ms tail delay identified as none,
        # damping 3.3 for 6.0). Started elsewhere, the search keeps scipy's step: the larger one let a weakly
        # excited axis leap 0.9 s into an unstable fit (the T-REX hover's yaw)
        unit = np.ones(full.size)
        if like.free_tau and abs(tau0) <= MIN_SERVO_DELAY:
            unit[-1] = TAU_UNIT
        lo, hi = lo / unit, hi / unit
        z0 = np.clip(full[free] / unit[free], lo[free] + 1e-9 / unit[free], hi[free] - 1e-9 / unit[free])

        def residual(z):
            x = full.copy()
            x[free] = z * unit[free]
            return like.residual(x)

        steps = np.full(z0.size, FD_STEP)
        if like.free_tau:
            steps[-1] = np.sqrt(np.finfo(float).eps)  # scipy's own step, in the alignment's unit (above)
        fun, jac = forward_jacobian(residual, hi[free], steps)
        res = optimize.least_squares(fun, z0, jac=jac, bounds=(lo[free], hi[free]), x_scale="jac",
                                     max_nfev=max_nfev or self.max_nfev, xtol=XTOL, ftol=FTOL)
        full[free] = res.x * unit[free]
        res.x = full
        return res

    def per_kind(self, tau: float, x0, models, max_nfev=None, free_tau: bool = False, lag: float = 0.0) -> dict:
        """Search each gust model of ``models`` from delay ``tau`` (held, or searched too with ``free_tau``) and
        from ``x0`` (one start for all, or a dict of starts by gust model), at servo lag ``lag``.

        Returns ``{model: (cost, x, tau, aic)}``, ``x`` the damping-and-wind part of the search vector.
        """
        out, likes = {}, {}
        for kind in models:
            likes[kind] = like = AxisLikelihood(self.data(tau, kind, lag), free_tau)
            res = self.search(like, x0[kind] if isinstance(x0, dict) else x0, max_nfev, tau)
            out[kind] = self._scored(like, kind, res)
        if self.hold == "auto" and not free_tau:
            self._reconcile_holds(out, likes, max_nfev)
        return out

    @staticmethod
    def _scored(like: AxisLikelihood, kind: str, res) -> tuple:
        """``(cost, x, tau, aic)`` of a search's result ``res`` on ``like`` (gust model ``kind``)."""
        n = sum(len(y) - like.data.burn for y in like.data.y)
        # Akaike: the concentrated NLL is n/2 log(2 cost / n) + const; one parameter more costs 1
        aic = 0.5 * n * np.log(2.0 * res.cost / n) + N_NONLINEAR[kind]
        return float(res.cost), res.x[:like.nw], like.tau_of(res.x), aic

    def _reconcile_holds(self, out: dict, likes: dict, max_nfev) -> None:
        """Where the gust models' searches end at holds more than :data:`HOLD_DISAGREEMENT` apart, search each
        model again from the other's damping and hold (its own gust model and alignment kept), and keep the
        likelier optimum of the two (``out`` updated in place). The hold and the damping mean the same in every
        gust model; their searches from one start can still end in different basins -- on the Dryden cell's
        seed 1 yaw the second-order model ran to the hold's lower bound in one arithmetic and to 0.84 in
        another, where it was likelier by 1.6 in log-likelihood (docs/method.md, the stability table). Not where
        the alignment is searched too: the hold moves the input by up to half a sample, so the two models'
        optima differ in hold and alignment together (servo-delayed bench flights: hold 0 against 1, 72 against
        80 ms), and searching again there found nothing likelier in 12 of 12 cases and cost a quarter of
        the alignment profile's time."""
        for kind, other in [(k, o) for k in out for o in out if o != k]:
            x, x_other = out[kind][1], out[other][1]
            if abs(x[HOLD_INDEX] - x_other[HOLD_INDEX]) <= HOLD_DISAGREEMENT:
                continue
            start = np.array(x, dtype=float, copy=True)
            start[0], start[HOLD_INDEX] = x_other[0], x_other[HOLD_INDEX]
            like = likes[kind]
            again = self._scored(like, kind, self.search(like, start, max_nfev, out[kind][2]))
            if again[0] < out[kind][0]:
                out[kind] = again

    def best(self, tau: float, x0, models, max_nfev=None, free_tau: bool = False, lag: float = 0.0) -> WindFit:
        """The gust model of :meth:`per_kind` with the lowest Akaike criterion, and its optimum."""
        fits = self.per_kind(tau, x0, models, max_nfev, free_tau, lag)
        kind = min(fits, key=lambda k: fits[k][3])
        cost, x, tau, _ = fits[kind]
        return WindFit(cost, x, kind, tau)

    # ------------------------------------------------------------------ the optimum
    def result(self, like: AxisLikelihood, x, solution: tuple, tau: float, kind: str, profile=()) -> MLAxisFit:
        """Standard errors, wind levels and fit statistics at the optimum ``x`` (the whole search vector of
        ``like``), ``solution`` being ``like.solve_linear(x)``: (innovations, linear parameters, scale)."""
        e, theta, S = solution
        a, data, damping_name = self.axis, like.data, self.damping_name
        n = e.size
        mse = float(np.mean(e ** 2))
        nx = len(x)
        se, cond = like.fisher(x, theta, mse, free_damping=damping_name is not None, fixed=self.fixed())
        damping, ts, tf, qs, qf, zeta = like.unpack(x)
        R = mse / S
        params, std = {}, {}
        if like.free_tau:
            std[f"tau_{AXES[a]}"] = float(se[like.nw])
        if damping_name is not None:
            params[damping_name] = float(-damping / TERMS[damping_name].sign)
            std[damping_name] = float(se[0])
        k_off = [i for i, nm in enumerate(data.names) if "@" in nm]
        for i, nm in enumerate(data.names):
            if "@" not in nm:
                params[nm] = float(theta[i])
                std[nm] = float(se[nx + i])
        offs = ()
        if k_off:
            off_name = data.names[k_off[0]].split("@")[0]
            offs = tuple(float(theta[i]) for i in k_off)
            weights = np.array([len(y) - data.burn for y in data.y], dtype=float)
            weights /= weights.sum()
            params[off_name] = float(weights @ np.array(offs))
            within = float(np.sqrt(np.sum(weights ** 2 * se[[nx + i for i in k_off]] ** 2)))
            spread = float(np.std(offs, ddof=1) / np.sqrt(len(offs))) if len(offs) > 1 else 0.0
            std[off_name] = float(np.hypot(within, spread))
        gain_name = next((p for p in self.names if TERMS[p].effect == "control"), None)
        gain = abs(params.get(gain_name, 0.0)) if gain_name else 0.0
        sd = np.sqrt([qs * R, qf * R])
        wind = {
            "model": kind,
            "time_constants_s": [ts, tf],
            "time_constants_se_s": [float(ts * se[1]), float(tf * se[2])],
            "damping_ratio": zeta if kind == "gm_so" else None,
            "torque_std": [float(sd[0]), float(sd[1])],
            "torque_std_se": [float(0.5 * sd[0] * se[3]), float(0.5 * sd[1] * se[4])],
            "ud_std": [float(s / gain) if gain else None for s in sd],
            "total_torque_std": float(np.hypot(*sd)),
        }
        yall = np.concatenate([y[data.burn:] for y in data.y])
        ss = float(np.sum((yall - yall.mean()) ** 2)) or 1.0
        hold = like.hold_at(x)
        return MLAxisFit(
            AXES[a], params, std, tau, cond, simulation_r2(data, damping, theta, hold),
            (float(np.mean(like.residual(np.asarray(x)) ** 2)), mse), wind, float(np.sqrt(R)),
            float(0.5 * n * (np.log(2 * np.pi * mse) + 1.0)), int(n), offs, 1.0 - float(e @ e) / ss,
            profile, state=np.asarray(x[:like.nw], dtype=float), input_hold=hold,
            input_hold_se=float(se[HOLD_INDEX]) if HOLD_INDEX not in self.fixed() else None)
