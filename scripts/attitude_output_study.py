"""Does the measured attitude, as a second output of the likelihood, remove the closed-loop damping bias?

docs/method.md ("Where it does not hold") measures dampings biased high where the pilot sees the aircraft
and the gyro is noisy: the sticks carry information about past gusts that a likelihood of the gyro alone
cannot use. The filter-error method's answer is to give the likelihood what the loop saw. This study fits one
axis of held-stick flights (sticks held over each sample: a zero-order hold is then exact) two ways with one
maximum-likelihood code, and beside them the package's estimator (rate only, hold 0):

* **rate**: states (rate, slow gust, fast gust), the gyro the only output — the package's model;
* **rate + attitude**: the angle added as a state (its rate the body rate: hover, small angles) and the measured
  attitude as a second output with its own noise.

Both: the rate equation of eq. 18/21 (damping, control gain, offset) driven by two first-order Gauss-Markov
gusts (eqs. 41-42's wind as the package models it), discretised exactly (``scipy.linalg.expm``, Van Loan for
the noise), the steady-state Kalman filter (``scipy.linalg.solve_discrete_are``) and the exact Gaussian
likelihood of its innovations, every parameter searched (Nelder-Mead, then Powell). A study, not the package's
estimator: it shows whether the second output is the fix, before the estimator is changed.

Usage::

    python scripts/attitude_output_study.py --aircraft sluggish --gyro 0.03 --axis roll --seeds 12 [--workers 2]
"""

from __future__ import annotations

import argparse
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numba
import numpy as np
from scipy import linalg, optimize

from identification.bench.aircraft import AIRCRAFT, aircraft_truth

AXES = {"roll": ("k3", "k2"), "pitch": ("k7", "k6")}
BURN = 200
"""Samples left out of the likelihood while the filter settles."""


@numba.njit  # (not cached: a cache entry written by a test that loads this file by path breaks a run)
def innovations_nll(Ad, Bd, C, K, S_inv, log_det, y, u, burn):
    """Negative log-likelihood (without the constant) of the steady-state filter's innovations: outputs ``y``
    (ny, n), inputs ``u`` (nu, n) held over each sample, from a zero state."""
    nx, ny, n = Ad.shape[0], C.shape[0], y.shape[1]
    x = np.zeros(nx)
    e = np.zeros(ny)
    total = 0.0
    for k in range(n):
        for i in range(ny):
            s = y[i, k]
            for j in range(nx):
                s -= C[i, j] * x[j]
            e[i] = s
        if k >= burn:
            q = 0.0
            for i in range(ny):
                for j in range(ny):
                    q += e[i] * S_inv[i, j] * e[j]
            total += 0.5 * (q + log_det)
        updated = x.copy()
        for i in range(nx):
            for j in range(ny):
                updated[i] += K[i, j] * e[j]
        for i in range(nx):
            s = 0.0
            for j in range(nx):
                s += Ad[i, j] * updated[j]
            for j in range(Bd.shape[1]):
                s += Bd[i, j] * u[j, k]
            x[i] = s
    return total


def axis_model(theta, dt: float, with_attitude: bool):
    """The discretised axis model and its steady-state filter at ``theta`` = (damping, gain, offset, log T_slow,
    log T_fast, log q_slow, log q_fast, log gyro variance, log attitude variance): ``(Ad, Bd, C, K, S^-1, log
    det S)``. Raises ``numpy.linalg.LinAlgError`` where the filter has no stabilising solution."""
    damping, gain, offset, lts, ltf, lqs, lqf, lr_rate, lr_att = theta
    A = np.array([[-damping, 0.0, 1.0, 1.0], [1.0, 0.0, 0.0, 0.0],
                  [0.0, 0.0, -np.exp(-lts), 0.0], [0.0, 0.0, 0.0, -np.exp(-ltf)]])
    B = np.array([[gain, offset], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    G = np.diag([0.0, 0.0, np.exp(lqs), np.exp(lqf)])  # the gusts' white-noise intensities
    if not with_attitude:  # the angle is neither observed nor needed
        keep = [0, 2, 3]
        A, B, G = A[np.ix_(keep, keep)], B[keep], G[np.ix_(keep, keep)]
    n = A.shape[0]
    M = np.zeros((n + 2, n + 2))
    M[:n, :n], M[:n, n:] = A, B
    E = linalg.expm(M * dt)
    Ad, Bd = E[:n, :n], E[:n, n:]
    V = np.zeros((2 * n, 2 * n))  # Van Loan: the discrete process noise
    V[:n, :n], V[:n, n:], V[n:, n:] = -A, G, A.T
    F = linalg.expm(V * dt)
    Qd = F[n:, n:].T @ F[:n, n:]
    Qd = 0.5 * (Qd + Qd.T) + 1e-14 * np.eye(n)
    C = np.eye(2, n) if with_attitude else np.eye(1, n)
    R = np.diag([np.exp(lr_rate), np.exp(lr_att)][:C.shape[0]])
    P = linalg.solve_discrete_are(Ad.T, C.T, Qd, R)
    S = C @ P @ C.T + R
    sign, log_det = np.linalg.slogdet(S)
    if not (sign > 0 and np.isfinite(log_det) and np.all(np.isfinite(P))):
        raise np.linalg.LinAlgError("the innovations' covariance is not positive definite")
    S_inv = np.linalg.inv(S)
    return Ad, Bd, C, P @ C.T @ S_inv, S_inv, float(log_det)


def nll(theta, y, u, dt: float, with_attitude: bool) -> float:
    """The negative log-likelihood of ``y`` = (rate, attitude) (the rate alone without ``with_attitude``)."""
    if theta[0] <= 0.0:
        return 1e12
    try:
        model = axis_model(theta, dt, with_attitude)
    except (np.linalg.LinAlgError, ValueError):
        return 1e12
    value = innovations_nll(*model, np.ascontiguousarray(y[:2 if with_attitude else 1]), u, BURN)
    return value if np.isfinite(value) else 1e12


def fit_axis(y, u, dt: float, with_attitude: bool, theta0) -> np.ndarray:
    """Maximum-likelihood parameters from ``theta0`` (the searches' trial points far from a model that fits
    overflow quietly: :func:`nll` rates them 1e12)."""
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        res = optimize.minimize(nll, theta0, args=(y, u, dt, with_attitude), method="Nelder-Mead",
                                options={"maxiter": 6000, "maxfev": 6000, "xatol": 1e-5, "fatol": 1e-4})
        res = optimize.minimize(nll, res.x, args=(y, u, dt, with_attitude), method="Powell",
                                options={"maxiter": 20000, "xtol": 1e-6, "ftol": 1e-8})
    return res.x


def estimated_attitude(gyro_rate, true_angle, dt: float, tau: float, tilt_noise: float, rng) -> np.ndarray:
    """The angle a flight controller's estimator reports: a complementary filter that integrates the logged gyro
    and pulls, with time constant ``tau`` [s], towards an accelerometer's tilt (the true angle plus white noise
    of ``tilt_noise`` [rad]). Its errors are the gyro's noise integrated and the tilt's, low-passed: neither
    white nor independent of the gyro's."""
    from scipy import signal

    a = np.exp(-dt / tau)
    tilt = true_angle + tilt_noise * rng.standard_normal(true_angle.size)
    drive = a * gyro_rate * dt + (1.0 - a) * tilt  # angle[k] = a (angle[k-1] + gyro[k] dt) + (1 - a) tilt[k]
    return signal.lfilter([1.0], [1.0, -a], drive, zi=[a * true_angle[0]])[0]


def flight_signals(flight, axis: int, attitude=None):
    """One axis' outputs (rate, attitude: the log's, or ``attitude``) and inputs (stick, 1) of a flight."""
    from heli_core.terms import STICK_ROW

    angle = flight.attitude[axis] if attitude is None else attitude
    y = np.vstack([flight.rates[axis], angle]).astype(float)
    u = np.vstack([flight.sticks[STICK_ROW[axis]], np.ones(flight.n)]).astype(float)
    return y, u


def _one(job) -> dict:
    """Relative errors [%] of one flight's damping and gain by the package and the two fits."""
    from threadpoolctl import threadpool_limits

    from identification.bench.cells import BENCH_CELLS
    from identification.bench.synthetic import simulate_flight
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier

    aircraft, cell, gyro, axis_name, duration, seed, estimator = job
    axis = list(AXES).index(axis_name)
    damping, gain = AXES[axis_name]
    with threadpool_limits(limits=1, user_api="blas"):
        config = replace(BENCH_CELLS[cell], duration=duration, gyro_noise=gyro, vibration_lines=(), vibration=0.0)
        sim = simulate_flight(duration, seed=seed, config=config, truth=aircraft_truth(aircraft))
        truth = sim.truth.values()
        package = MaximumLikelihoodIdentifier(input_hold=0.0).fit(sim.flight).params_.values()
        attitude, attitude_noise = None, config.attitude_noise
        if estimator is not None:  # (tau, tilt noise): the angle as a flight controller's estimator reports it
            tau, tilt_noise = estimator
            attitude = estimated_attitude(sim.flight.rates[axis], sim.flight.attitude[axis], sim.flight.dt, tau,
                                          tilt_noise, np.random.default_rng([seed, 7]))
            attitude_noise = tilt_noise
        y, u = flight_signals(sim.flight, axis, attitude)
        theta0 = np.array([truth[damping], truth[gain], 0.0, np.log(4.0), np.log(0.35), np.log(1e-3), np.log(1e-2),
                           np.log(gyro ** 2), np.log(attitude_noise ** 2)])
        out = {"package": (package[damping], package[gain])}
        for label, with_attitude in (("rate", False), ("rate + attitude", True)):
            theta = fit_axis(y, u, sim.flight.dt, with_attitude, theta0)
            out[label] = (theta[0], theta[1])
    return {k: (100.0 * (d / truth[damping] - 1.0), 100.0 * (g / truth[gain] - 1.0)) for k, (d, g) in out.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--aircraft", default="sluggish", choices=["paper", *AIRCRAFT])
    ap.add_argument("--cell", default="held-sticks-pd", help="a bench cell whose sticks are held over the sample")
    ap.add_argument("--gyro", type=float, default=0.03, help="gyro noise [rad/s] (default 0.03)")
    ap.add_argument("--axis", choices=list(AXES), default="roll")
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--first-seed", type=int, default=301)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--estimated-attitude", type=float, nargs=2, metavar=("TAU", "TILT_NOISE"), default=None,
                    help="fit the angle a complementary filter of the logged gyro reports (time constant TAU s, "
                         "towards a tilt of white noise TILT_NOISE rad) instead of an independent sensor's")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    from identification.bench.cells import BENCH_CELLS

    cell = BENCH_CELLS.get(args.cell)
    if cell is None or not (cell.held_sticks or cell.pilot == "autopilot"):
        held = [name for name, c in BENCH_CELLS.items() if c.held_sticks or c.pilot == "autopilot"]
        ap.error(f"--cell must hold its sticks over the sample (one of {', '.join(held)}), got {args.cell!r}")
    estimator = None if args.estimated_attitude is None else tuple(args.estimated_attitude)
    jobs = [(args.aircraft, args.cell, args.gyro, args.axis, args.duration, s, estimator)
            for s in range(args.first_seed, args.first_seed + args.seeds)]
    if args.workers == 1:
        rows = [_one(job) for job in jobs]
    else:
        with ProcessPoolExecutor(args.workers) as pool:
            rows = list(pool.map(_one, jobs))
    damping, gain = AXES[args.axis]
    source = ("the log's attitude" if estimator is None else
              f"an estimated attitude (complementary filter, {estimator[0]:g} s, tilt noise {estimator[1]:g} rad)")
    print(f"{args.aircraft}, cell {args.cell}, gyro {args.gyro:g} rad/s, {args.axis}, {source}; {len(rows)} flights "
          f"of {args.duration:g} s: relative error, mean (standard error) [RMS]")
    for label in rows[0]:
        e = np.array([r[label] for r in rows])
        mean, se = e.mean(axis=0), e.std(axis=0, ddof=1) / np.sqrt(len(e)) if len(e) > 1 else np.zeros(2)
        rms = np.sqrt((e ** 2).mean(axis=0))
        print(f"- {label}: {damping} {mean[0]:+.1f} % ({se[0]:.1f}) [{rms[0]:.1f}], "
              f"{gain} {mean[1]:+.1f} % ({se[1]:.1f}) [{rms[1]:.1f}]")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
