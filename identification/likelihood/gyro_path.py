"""A gyro filtered before it is logged, moved to the input side of the model the likelihood fits.

Flight controllers low-pass the gyro they fly on and log (ArduPilot's ``INS_GYRO_FILTER``, PX4's
``IMU_GYRO_CUTOFF``: a 2-pole filter, 20 Hz by default on ArduPilot's helicopters). The logged rate is then
``y = F(rate) + F(noise)``, not the ``rate + white noise`` the wind-state model measures
(:mod:`identification.likelihood.state_space`). Both halves are handled apart:

- the noise's colour by the fit rate (:mod:`identification.fit_rate`: a stated corner thins the log until the
  filtered noise is white enough);
- the filter's lag here. The model of eqs. (18)/(21) is linear in the rate, so ``F(rate)`` obeys the same
  equation with every input passed through ``F``: ``F(rate)' = -damping F(rate) + k F(u) + F(gust)``. The
  measured rates that are regressors (couplings) are logged through ``F`` already; the sticks are not. So the
  stick of each axis enters its rate through the filter and the servo of eq. (31) in series, discretised
  exactly under the stick's hold (:func:`path_increments`), and the other commands (the collective, other
  axes' sticks) through the filter discretised at the fit rate (:func:`matched`). ``F(gust)`` is a gust like
  any other (a 20 Hz corner leaves a gust's band below 3 Hz untouched).

Without it the filter's lag (``sqrt(2) / (2 pi f_c)``, 11 ms at 20 Hz) is read as the aircraft's: as a servo lag
named by the diagnosis on effect-free flights (2 of 10 a pilot's, 5 of 6 behind held sticks), as a held stick where
the pilot's was interpolated, or in the dampings (up to 9.3 % RMS where 4.1 % remains; docs/method.md, "The gyro
filter's lag on the input side"). The identified model stays the aircraft's, without the filter: it is the sensor's.
"""

from __future__ import annotations

import numpy as np
from scipy import signal
from scipy.linalg import expm

from heli_core.servo import servo_coefficients

from .input_hold import hold_fraction

def filter_block(corner_hz: float):
    """The 2-pole Butterworth low-pass of corner ``corner_hz`` as a continuous state space ``(A, B, C)``: unit gain
    at rest, ``sqrt(2) / (2 pi f_c)`` of lag at low frequency (the shape ArduPilot's and PX4's gyro filters give
    at their loop's rate, far below its Nyquist frequency)."""
    om = 2.0 * np.pi * float(corner_hz)
    A = np.array([[0.0, 1.0], [-om * om, -np.sqrt(2.0) * om]])
    return A, np.array([0.0, om * om]), np.array([1.0, 0.0])


def input_path(tau: float, lag: float, corner_hz: float | None):
    """The stick's path to the torque: the gyro filter of ``corner_hz`` (None: none) and the servo of eq. (31)
    (Padé delay ``tau``, lag ``lag``; none when both are 0) in series, as ``(A, B, C, D)``; ``A`` (n, n) with
    ``n`` from 0 to 3 states."""
    d1, n1, n2 = servo_coefficients(tau, lag)
    blocks = []
    if corner_hz is not None:
        Af, bf, cf = filter_block(corner_hz)
        blocks.append((Af, bf[:, None], cf[None, :], np.zeros((1, 1))))
    if d1 > 0.0:  # theta = f delta + g z, z' = (delta - z)/d1 (eq. 31 split into feed-through and state)
        blocks.append((np.array([[-1.0 / d1]]), np.array([[1.0 / d1]]), np.array([[n1 + n2 / d1]]),
                       np.array([[-n2 / d1]])))
    A, B, C, D = np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.ones((1, 1))
    for A2, B2, C2, D2 in blocks:  # the block after the path so far: its input is the path's output
        n, m = A.shape[0], A2.shape[0]
        A = np.block([[A, np.zeros((n, m))], [B2 @ C, A2]])
        B = np.vstack([B, B2 @ D])
        C = np.hstack([D2 @ C, C2])
        D = D2 @ D
    return A, B[:, 0], C[0], float(D[0, 0])


def path_step(damping: float, dt: float, hold, tau: float = 0.0, lag: float = 0.0, corner_hz: float | None = None):
    """One sample of :func:`input_path` driving a rate of ``damping``, discretised exactly with the stick held,
    linearly interpolated or a fraction between (``hold``, :func:`~.input_hold.hold_fraction`).

    Returns ``(e_rz, E_zz, h0, h1)``: the command's increment of the rate from ``k`` to ``k+1`` (per unit
    control gain, from a rate of zero) is ``e_rz @ z[k] + h0[0]*u[k] + h1[0]*u[k+1]``, and the path's next state
    ``E_zz @ z[k] + h0[1:]*u[k] + h1[1:]*u[k+1]``.
    """
    Ap, bp, cp, dp = input_path(tau, lag, corner_hz)
    n = Ap.shape[0]
    M = np.zeros((n + 3, n + 3))
    M[0, 0], M[0, 1:n + 1], M[1:n + 1, 1:n + 1] = -damping, cp, Ap
    M[:n + 1, n + 1] = np.concatenate([[dp], bp])
    M *= dt
    M[n + 1, n + 2] = 1.0
    E = expm(M)
    ga, gb = E[:n + 1, n + 1], E[:n + 1, n + 2]
    frac = hold_fraction(hold)
    return E[0, 1:n + 1], E[1:n + 1, 1:n + 1], ga - frac * gb, frac * gb


def path_increments(sticks, damping: float, tau: float, dt: float, hold, lag: float = 0.0,
                    corner_hz: float | None = None) -> np.ndarray:
    """The command's exact contribution to the rate over each sample through :func:`input_path`: ``v[k]``, the
    rate's increment from ``k`` to ``k+1`` (per unit control gain), the path settled on the first stick.
    :func:`~.state_space.servo_increments` for a path that holds the gyro filter."""
    e_rz, E_zz, h0, h1 = path_step(damping, dt, hold, tau, lag, corner_hz)
    u = np.asarray(sticks, dtype=float)
    u_next = np.append(u[1:], u[-1])
    v = h0[0] * u + h1[0] * u_next
    n = E_zz.shape[0]
    if n == 0:
        return v
    # z[k+1] = E z[k] + h0z u[k] + h1z u[k+1], settled on u[0] (z_ss) and driven from there by u - u[0]
    z_ss = np.linalg.solve(np.eye(n) - E_zz, h0[1:] + h1[1:]) * u[0]
    du, du_next = u - u[0], u_next - u[0]
    for col, drive in ((h0[1:], du), (h1[1:], du_next)):
        num, den = signal.ss2tf(E_zz, col[:, None], e_rz[None, :], np.zeros((1, 1)))
        v += signal.lfilter(num[0], den, drive)
    return v + float(e_rz @ z_ss)


def matched(values, corner_hz: float | None, fs: float) -> np.ndarray:
    """``values`` sampled at ``fs`` passed through the gyro filter of ``corner_hz`` (discretised with the signal
    interpolated between samples), settled on the first sample; unchanged where ``corner_hz`` is None. The other
    commands than an axis' own stick enter its rate this way (module docstring)."""
    x = np.asarray(values, dtype=float)
    if corner_hz is None:
        return x
    om = 2.0 * np.pi * float(corner_hz)  # filter_block's transfer function
    num, den, _ = signal.cont2discrete(([om * om], [1.0, np.sqrt(2.0) * om, om * om]), 1.0 / fs, method="foh")
    num = np.atleast_2d(num)[0]
    zi = signal.lfilter_zi(num, den) * x[0]
    return signal.lfilter(num, den, x, zi=zi)[0]
