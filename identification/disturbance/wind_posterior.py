"""Draws of the wind from the smoother's posterior: gusts with the identified wind's full power.

The Rauch-Tung-Striebel smoother of the maximum-likelihood model
(:func:`identification.likelihood.state_space.rts_smooth`,
:meth:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier.wind_torque`) returns the
*conditional mean* ``E[w | y]`` of the wind torque of eqs. (41)-(42) given the flight's rates. A
conditional mean is smoother than any wind that blew: where the gyro cannot tell a gust from its
noise (above the aircraft's bandwidth, a few Hz) it returns the prior's zero, so on the bench it
keeps about 0.93 of the true wind's standard deviation and little of its power above 1 Hz. A gain
sweep or an environment that replays it flies gentler gusts than the aircraft met, and predicts
attitude errors that are too small.

A draw from the posterior ``p(w | y)`` has the wind's full power and still follows the flight's
gusts where the data see them. It is made by the simulation smoother of Durbin & Koopman (2002,
"A simple and efficient simulation smoother for state space time series analysis", Biometrika
89(3)): for the fitted linear Gaussian model of one axis (the body rate and its gust states,
:func:`~identification.likelihood.state_space.discrete_model`),

1. simulate the model with its process and measurement noise: states ``x+`` and rates ``y+``;
2. run the same smoother on ``y+``: ``E[x+ | y+]``;
3. ``draw = E[x | y] + (x+ - E[x+ | y+])``.

The smoother is linear, so ``x+ - E[x+ | y+]`` has the posterior's covariance and is independent
of ``y``; the flight's known inputs (sticks, couplings, offsets) drop out of the difference, and
``y+`` is simulated without them (every hold of the inputs gives the same draw; the hold is passed
on unchanged all the same). The model is fitted with the gyro noise variance ``R`` concentrated
out (the gust variances are ratios to it), so the simulation runs at ``R = 1`` and its difference
is scaled by the fitted noise standard deviation.

Deterministic: draw ``d`` of axis ``a`` comes from ``numpy.random.default_rng([seed, d, a])`` (the same
whatever else is drawn or identified); :func:`flight_seed` derives
the seed from a flight's SHA-256, so the same flight gives the same draw on every run and machine
(to floating-point rounding).

The simulated initial state is drawn from ``N(0, P)``, ``P`` the filter's steady-state predicted
covariance, the prior the steady-state smoother assumes for its first state (it starts the rate at
the first measurement, which differs from the simulation's zero-mean prior by one sample's noise:
a transient of a few of the rate's time constants at the flight's start).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from heli_core.terms import AXES

from ..likelihood.state_space import covariance_root, discrete_model, kalman, lti_apply, rts_smooth, wind_block

METHOD = "simulation smoother (Durbin & Koopman 2002) of the maximum-likelihood model's RTS smoother"
"""What a draw is, in the words the library's manifest records."""


def flight_seed(sha256: str) -> int:
    """The seed of a flight's posterior draw: the first 16 hex digits of its SHA-256 as an integer.

    Parameters
    ----------
    sha256 : str
        Hex digest of the flight (its file's, or its arrays', as
        :func:`identification.disturbance.equivalent_input.source_of` records it).

    Raises
    ------
    ValueError
        Not a hex string of at least 16 digits.
    """
    text = str(sha256)
    try:
        if len(text) < 16:
            raise ValueError
        return int(text[:16], 16)
    except ValueError:
        raise ValueError(f"a flight's seed comes from its SHA-256 hex digest (>= 16 hex digits), got {sha256!r}") \
            from None


def axis_posterior_noise(model: tuple, dt: float, hold, wind_model: str, noise_std: float, n: int,
                         rng: np.random.Generator, n_draws: int = 1) -> np.ndarray:
    """The simulation smoother's differences ``x+ - E[x+ | y+]`` of one axis' gust torque.

    Parameters
    ----------
    model : tuple of 6 float
        ``(damping, T_slow, T_fast, var_slow/R, var_fast/R, zeta)`` of the fitted axis
        (:meth:`identification.likelihood.axis_likelihood.AxisLikelihood.unpack`) [1/s, s, s, -, -, -].
    dt : float
        Sample period [s].
    hold : str or float
        The inputs' hold, passed on to the state-space pieces unchanged.
    wind_model : {"gm2", "gm_so"}
    noise_std : float
        Fitted gyro noise standard deviation sqrt(R) [rad/s].
    n : int
        Samples.
    rng : numpy.random.Generator
    n_draws : int

    Returns
    -------
    ndarray, shape (n_draws, n)
        Zero-mean draws of the posterior error of the gust torque [rad/s^2]; added to the smoother's
        mean, each is a draw of the wind given the flight.
    """
    Ad, _, _, Qd = discrete_model(*model, dt, hold, wind_model)
    P, _, _ = kalman(Ad, Qd)
    m = Ad.shape[0]
    _, cw, _ = wind_block(wind_model, 1.0, 1.0)  # the sum of the gust states, the same for every T, zeta
    noise_root = covariance_root(Qd)
    start_root = covariance_root(P)
    eye = np.eye(m)
    out = np.empty((n_draws, n))
    for d in range(n_draws):
        kicks = np.zeros((m, n + 1))  # column 0 enters as the initial state, column j + 1 as w_j
        kicks[:, 0] = start_root @ rng.standard_normal(m)
        kicks[:, 1:n] = noise_root @ rng.standard_normal((m, n - 1))
        x = lti_apply(Ad, eye, eye, np.zeros((m, m)), kicks)[:, 1:]
        y = x[0] + rng.standard_normal(n)
        smoothed = rts_smooth(y, np.zeros(n), *model, dt, hold, wind_model)
        out[d] = cw @ (x[1:] - smoothed[1:])
    return noise_std * out


@dataclass(frozen=True, eq=False)
class WindPosterior:
    """The wind torque of one flight given its rates: the smoother's mean and draws from its posterior.

    Attributes
    ----------
    mean : ndarray, shape (3, n)
        ``E[w | y]``, the smoother's estimate about the model's offsets
        (:meth:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier.wind_torque`) [rad/s^2].
    draws : ndarray, shape (n_draws, 3, n)
        Draws of ``w | y`` (same offsets) [rad/s^2]; rows of axes not identified are zero.
    seed : int
        Seed of ``numpy.random.default_rng`` the draws came from.
    """

    mean: np.ndarray
    draws: np.ndarray
    seed: int

    @property
    def draw(self) -> np.ndarray:
        """The first draw, shape (3, n) [rad/s^2]: the one a flight's library trace stores."""
        return self.draws[0]

    def describe(self) -> dict:
        """What a library trace made of :attr:`draw` records about it (JSON-ready)."""
        return {"method": METHOD, "seed": int(self.seed), "draw": 0, "n_draws": int(self.draws.shape[0])}


def wind_posterior(ident, flight=0, seed: int = 0, n_draws: int = 1) -> WindPosterior:
    """The smoother's wind and ``n_draws`` draws from its posterior for one flight of a fitted model.

    Parameters
    ----------
    ident : MaximumLikelihoodIdentifier
        Fitted.
    flight : int or Flight
        An index into the fitted flights, or a new flight (as
        :meth:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier.wind_torque` takes it).
    seed : int
        Seed of the draws (e.g. :func:`flight_seed` of the flight's SHA-256): same seed, same draws.
    n_draws : int
        Draws, >= 1.

    Returns
    -------
    WindPosterior
    """
    if int(n_draws) < 1:
        raise ValueError(f"n_draws must be >= 1, got {n_draws!r}")
    from ..likelihood.axis_likelihood import AxisLikelihood

    mean = ident.wind_torque(flight)
    n = mean.shape[1]
    one = ident.flights_[0] if not hasattr(flight, "rates") else flight
    draws = np.repeat(mean[None], int(n_draws), axis=0)
    for axis_name, fit in ident.axes_.items():
        a = AXES.index(axis_name)
        data = ident._fitted_data(a, fit, [one], 0)
        hold = fit.input_hold
        model = AxisLikelihood(data).unpack(fit.state)
        for d in range(int(n_draws)):  # a stream per draw and axis: a draw is the same whatever else is drawn
            rng = np.random.default_rng([int(seed), d, a])
            draws[d, a] += axis_posterior_noise(model, data.dt, hold, fit.wind["model"], fit.noise_std, n, rng)[0]
    return WindPosterior(mean, draws, int(seed))
