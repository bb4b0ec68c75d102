"""Synthetic hover flights from a known truth model (the project's own test aircraft).

A flight is flown by the physics core (:mod:`heli_core.physics`) with the
paper's identified values as the default truth (eqs. 68-70), a closed-loop pilot
model, coloured wind torque, and a sensor model:

* **Pilot** (Section 2.1): holds the attitude with a PID law on the angle seen
  ``reaction_delay`` seconds ago (bandwidth ``pilot_bandwidth`` rad/s, gains
  scaled by his knowledge of the control gain), and flies frequency sweeps
  (linear chirps, 0.3-3 Hz) on one stick at a time with rests in between. The
  pilot reacts to gusts, so stick and wind are correlated, as in real flight.
* **Collective** wanders slowly around a hover trim (altitude keeping) with
  occasional climbs, so collective-dependent effects are excited.
* **Wind**: per axis, white noise through a second-order low-pass
  (``wind_corner_hz``), scaled so that the equivalent cyclic input ``u_d`` of
  eq. (42) has a 90 % interval of ``±wind_level`` (paper: about ±0.09,
  Section 3.3). The torque is ``k*u_d`` with the axis' control gain; the constant
  offsets ``kd`` are part of the truth parameters.
* **Sensors**: gyro white noise, rotor vibration (main-rotor 1/rev and 2/rev
  sinusoids, aliased by the 100 Hz sampling), attitude noise, and where
  ``gyro_filter_hz`` is set a flight controller's 2-pole gyro low-pass; sticks
  are logged as commanded (before the servo).

Optional physical effects can be switched on to hide them in the data
(:data:`identification.bench.flight_config.EFFECTS`). The truth (parameters and wind) is kept beside the
flight. What a flight is flown with, its truth and its :class:`~identification.bench.flight_config.FlightConfig`,
is :mod:`identification.bench.flight_config`; this module is the flight loop and the sensors.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from heli_core.files import atomic_path, write_text
from heli_core.params import ModelParams
from heli_core.physics import COMPILED_STEPS, compiled_rk4, initial_state, kernel
from heli_core.quaternion import euler_from_quaternion, euler_from_quaternion_scalar, euler_rates
from heli_core.terms import AXES

from ..flight import Flight, make_flight
from ..io.csv_log import write_csv_flight
from .flight_config import PAPER_PARAMS, FlightConfig, truth_params

def gust_trace(rng: np.random.Generator, n: int, fs: float, config: "FlightConfig", std: float) -> np.ndarray:
    """One axis' zero-mean gust of standard deviation ``std`` with the spectrum of ``config.wind_model``,
    plus the slow Gauss-Markov part of ``config.wind_slow_fraction`` (module docstring)."""
    from scipy import signal

    if std == 0:
        return np.zeros(n)
    if config.wind_model == "lowpass":
        fast = coloured_noise(rng, n, fs, config.wind_corner_hz, 1.0)
    elif config.wind_model == "gauss_markov":
        fast = _first_order(rng, n, fs, config.wind_fast_tau)
    else:  # lateral Dryden, discretised by the bilinear transform at the sample rate
        w = 2 * np.pi * config.wind_corner_hz
        b, a = signal.bilinear([np.sqrt(3.0) / w, 1.0], [1.0 / w ** 2, 2.0 / w, 1.0], fs)
        warm = int(10 * fs / config.wind_corner_hz)
        fast = signal.lfilter(b, a, rng.standard_normal(n + warm))[warm:]
        fast = (fast - fast.mean()) / fast.std()
    out = fast
    if config.wind_slow_fraction > 0:
        slow = _first_order(rng, n, fs, config.wind_slow_tau)
        out = np.sqrt(1 - config.wind_slow_fraction) * fast + np.sqrt(config.wind_slow_fraction) * slow
    out = out - out.mean()
    return out * (std / out.std())


def _first_order(rng, n, fs, tau):
    """Unit-variance first-order Gauss-Markov process of time constant ``tau`` (exact AR(1))."""
    from scipy import signal

    a = np.exp(-1.0 / (fs * tau))
    warm = int(5 * tau * fs)
    x = signal.lfilter([np.sqrt(1 - a * a)], [1.0, -a], rng.standard_normal(n + warm))[warm:]
    return (x - x.mean()) / x.std()


@dataclass
class SyntheticFlight:
    """A synthetic flight and its truth.

    Attributes
    ----------
    flight : Flight
        What the logger recorded (noisy rates and attitude, commanded sticks).
    truth : ModelParams
        Parameters the aircraft was flown with.
    wind : ndarray, shape (3, n)
        Equivalent cyclic wind input u_d per axis, eq. (42) (zero-mean part).
    wind_torque : ndarray, shape (3, n)
        ``k*u_d`` [rad/s^2], the disturbance fed to the physics core.
    true_rates : ndarray, shape (3, n)
        Noise-free body rates [rad/s].
    config : FlightConfig
    seed : int
    effects : tuple of str
    """

    flight: Flight
    truth: ModelParams
    wind: np.ndarray
    wind_torque: np.ndarray
    true_rates: np.ndarray
    config: FlightConfig
    seed: int
    effects: tuple = field(default=())
    effect_scale: float = 1.0

    def save(self, path) -> dict[str, Path]:
        """Write ``path`` (canonical CSV), ``<stem>.truth.json`` and ``<stem>.wind.csv`` atomically."""
        path = Path(path)
        paths = truth_paths(path)
        write_csv_flight(self.flight, path)
        truth = {
            "schema": "heli-env/synthetic-truth/1",
            "seed": self.seed,
            "effects": list(self.effects),
            "effect_scale": self.effect_scale,
            "parameters": self.truth.values() | {k: getattr(self.truth, k) for k in ("tau_roll", "tau_pitch", "tau_yaw")}
            | {f"lag_{a}": v for a, v in zip(AXES, self.truth.lags) if v},  # a servo lag only where there is one
            "config": asdict(self.config),
            "wind_file": paths["wind"].name,
        }
        write_text(paths["truth"], json.dumps(truth, indent=2) + "\n")
        cols = np.vstack([self.flight.time, self.wind, self.wind_torque]).T
        header = "time,ud_roll,ud_pitch,ud_yaw,torque_roll,torque_pitch,torque_yaw"
        with atomic_path(paths["wind"]) as tmp:
            np.savetxt(tmp, cols, delimiter=",", header=header, comments="", fmt="%.9g")
        return {"flight": path, **paths}


def truth_paths(flight_path) -> dict[str, Path]:
    """Where the truth of a synthetic flight lies beside it."""
    p = Path(flight_path)
    return {"truth": p.with_name(p.stem + ".truth.json"), "wind": p.with_name(p.stem + ".wind.csv")}


def load_truth(flight_path) -> tuple[ModelParams, np.ndarray]:
    """Read the truth parameters and the wind u_d (3, n) saved beside a synthetic flight."""
    paths = truth_paths(flight_path)
    data = json.loads(paths["truth"].read_text())
    params = dict(data["parameters"])
    base = {k: v for k, v in params.items() if not k.startswith(("nld", "gs", "ct"))}
    extra = tuple((k, v) for k, v in params.items() if k.startswith(("nld", "gs", "ct")))
    wind = np.loadtxt(paths["wind"], delimiter=",", skiprows=1, ndmin=2).T[1:4]
    return ModelParams(**base, extra=extra), wind


def coloured_noise(rng: np.random.Generator, n: int, fs: float, corner_hz: float, std: float) -> np.ndarray:
    """Zero-mean noise through a 2nd-order Butterworth low-pass, scaled to exactly ``std``."""
    from scipy import signal

    if std == 0:
        return np.zeros(n)
    b, a = signal.butter(2, corner_hz, fs=fs)
    warm = int(5 * fs / corner_hz)
    x = signal.lfilter(b, a, rng.standard_normal(n + warm))[warm:]
    x -= x.mean()
    return x * (std / x.std())


def sweep_schedule(time: np.ndarray, config: FlightConfig) -> np.ndarray:
    """Open-loop sweep part of the sticks (lat, lon, ped), shape (3, n).

    Sweeps cycle roll → pitch → yaw: a linear chirp over ``sweep_band`` of
    ``sweep_length`` seconds with a raised-cosine taper, then ``rest_length``
    seconds of hover. The first 5 s are hover. With ``sweep_mode="simultaneous"``
    every sweep moves all three sticks: roll up the band, pitch down it, yaw at
    a third of the roll frequency.
    """
    from scipy import signal

    out = np.zeros((3, time.size))
    period = config.sweep_length + config.rest_length
    t = time - 5.0
    k = np.floor(t / period).astype(int)
    tau = t - k * period
    active = (t >= 0) & (tau < config.sweep_length)
    axis = np.mod(k, 3)
    f0, f1 = config.sweep_band
    chirp = signal.chirp(tau, f0=f0, t1=config.sweep_length, f1=f1, method="linear")
    taper = np.clip(np.minimum(tau, config.sweep_length - tau) / 1.0, 0.0, 1.0)
    if config.sweep_mode == "simultaneous":
        down = signal.chirp(tau, f0=f1, t1=config.sweep_length, f1=f0, method="linear")
        slow = signal.chirp(tau, f0=f0 / 3, t1=config.sweep_length, f1=f1 / 3, method="linear", phi=90)
        for i, c in enumerate((chirp, down, slow)):
            out[i, active] = config.sweep_amplitude[i] * taper[active] * c[active]
        return out
    for i in range(3):
        m = active & (axis == i)
        out[i, m] = config.sweep_amplitude[i] * taper[m] * chirp[m]
    return out


def simulate_flight(duration: float | None = None, seed: int = 1, effects=(), config: FlightConfig | None = None,
                    truth: ModelParams | None = None, effect_scale: float = 1.0) -> SyntheticFlight:
    """Fly a synthetic hover flight.

    Parameters
    ----------
    duration : float, optional
        Flight length [s]; overrides ``config.duration`` when given (default:
        ``config.duration``, 300 s without a config).
    seed : int
        Seed of every random draw (wind, collective, pilot jitter, sensors):
        same seed, same flight.
    effects : sequence of str
        Names from :data:`EFFECTS` to switch on in the truth model.
    config : FlightConfig, optional
    truth : ModelParams, optional
        Truth parameters; default the paper's values (eqs. 68-70) with ``effects``.
    effect_scale : float
        Multiplies the parameters of ``effects`` (the diagnosis study's quadratic damping is 5).

    Returns
    -------
    SyntheticFlight
    """
    cfg = config or FlightConfig()
    if duration is not None and duration != cfg.duration:
        cfg = FlightConfig(**{**asdict(cfg), "duration": float(duration)})
    if cfg.log_every > 1:
        return _sampled(simulate_flight(seed=seed, effects=effects, truth=truth, effect_scale=effect_scale, config=replace(
            cfg, sample_rate=cfg.sample_rate * cfg.log_every, log_every=1)), cfg)
    params = truth_params(effects, truth or PAPER_PARAMS, effect_scale)
    rng = np.random.default_rng(seed)  # draws in a fixed order: wind, collective, jitter, then the sensors
    fs = cfg.sample_rate
    n = int(round(cfg.duration * fs)) + 1
    time = np.arange(n) * (1.0 / fs)
    wind = _wind(rng, n, cfg)
    torque = params.control_gains[:, None] * wind
    # Collective: slow wander plus occasional climbs, kept inside the stick range.
    col = cfg.collective_trim + coloured_noise(rng, n, fs, 0.05, cfg.collective_wander)
    col = np.clip(col, -1.0, 1.0)
    jitter = np.array([coloured_noise(rng, n, fs, 2.0, cfg.stick_noise) for _ in range(3)])
    errors = sensor_errors(rng, cfg, time)
    if cfg.command_noise > 0:  # drawn last, so that flights without it keep their draws
        jitter = jitter + rng.normal(0.0, cfg.command_noise, jitter.shape)
    states, sticks, estimated = _fly(params, cfg, sweep_schedule(time, cfg), jitter, col, torque, errors)
    true_rates = states[:, :3].T
    rates, att = _sensors(errors, true_rates, euler_from_quaternion(states[:, 6:10].T), estimated)
    if cfg.gyro_filter_hz > 0:  # the log's gyro is the flight controller's, filtered (no draw: the flight's the same)
        rates = GyroFilter(cfg.gyro_filter_hz, fs).run(rates)
    flight = _logged_flight(cfg, seed, effects, time, rates, att, sticks)
    return SyntheticFlight(flight, params, wind, torque, true_rates, cfg, int(seed), tuple(effects), float(effect_scale))


def _sampled(fast: SyntheticFlight, cfg: FlightConfig) -> SyntheticFlight:
    """``fast`` (its world stepped ``cfg.log_every`` times faster than ``cfg.sample_rate``) as the logger wrote it:
    every ``log_every``-th sample of the log, the wind and the true rates, with ``cfg`` as its config."""
    m = cfg.log_every
    f = fast.flight
    # the sticks' hold is the world's, not the log's: a link holding them at the world's rate is not held here
    meta = {**f.metadata, "log_every": m,
            "input_hold": f"{f.metadata['input_hold']} at {cfg.sample_rate * m:g} Hz, one sample in {m} logged"}
    # (an autopilot's loop_rate_hz stays the world's: it decided at every step the log skips)
    flight = make_flight(f.time[::m], f.rates[:, ::m], np.ascontiguousarray(f.sticks[:, ::m]),
                         attitude=f.attitude[:, ::m], metadata=meta)
    return replace(fast, flight=flight, wind=fast.wind[:, ::m], wind_torque=fast.wind_torque[:, ::m],
                   true_rates=fast.true_rates[:, ::m], config=cfg)


def _wind(rng: np.random.Generator, n: int, cfg: FlightConfig) -> np.ndarray:
    """The equivalent cyclic wind input u_d of eq. (42) per axis, shape (3, n), at ``cfg.wind_level``."""
    level = np.broadcast_to(np.asarray(cfg.wind_level, dtype=float), (3,))
    if cfg.wind_model == "lowpass" and cfg.wind_slow_fraction == 0:  # today's flights, draw for draw
        return np.array([coloured_noise(rng, n, cfg.sample_rate, cfg.wind_corner_hz, lv / 1.6449) for lv in level])
    return np.array([gust_trace(rng, n, cfg.sample_rate, cfg, lv / 1.6449) for lv in level])


def _fly(params: ModelParams, cfg: FlightConfig, sweeps, jitter, col, torque, errors) -> tuple:
    """Fly the truth model with the pilot in the loop: states (n, 10), the sticks he logged (n, 4) and the
    flight controller's attitude estimate (3, n; None unless ``cfg.attitude_filter_tau`` > 0).

    The pilot (module docstring) holds the attitude with a PID on the angle (``"pid"``) or a PD on angle and
    rate (``"pd"``, ``"autopilot"``) seen ``delay`` samples ago, scaled by the control gain he has learnt,
    and adds the ``sweeps`` and his ``jitter`` (3, n); ``col`` (n,) is the collective and ``torque`` (3, n)
    the wind [rad/s^2]. A human sees the aircraft; the autopilot reads its sensors, the true state plus
    ``errors`` (:func:`sensor_errors`), the gyro through its D-term low-pass (``cfg.autopilot_dterm_hz``), the
    attitude its estimator's where ``cfg.attitude_filter_tau`` > 0 (:class:`_AttitudeEstimator`).
    """
    n = col.size
    fs = cfg.sample_rate
    dt = 1.0 / fs
    gains = params.control_gains
    wn = cfg.pilot_bandwidth
    kp, kdr, ki = wn**2, 1.4 * wn, 0.3 * wn**3
    if cfg.pilot != "pid":  # PD on attitude and rate; the trim is known, not integrated
        ki = 0.0
    inv_gain = [1.0 / g for g in gains]
    trim = [-(params.kd1) / gains[0], -(params.kd2) / gains[1],
            -(params.kd3 - params.k12 * cfg.collective_trim) / gains[2]]
    delay = 1 if cfg.pilot == "autopilot" else max(1, int(round(cfg.reaction_delay * fs)))
    estimator = _AttitudeEstimator(cfg, errors, n) if cfg.attitude_filter_tau > 0 else None
    sensed = _AutopilotSensing(cfg, errors, fs, estimator) if cfg.pilot == "autopilot" else None

    # compiled: the same states bit for bit, 3-4x faster a long flight
    rk4 = (compiled_rk4(params) if n * cfg.substeps >= COMPILED_STEPS else None) or kernel(params)[0]["rk4"]
    x = tuple(float(v) for v in initial_state(sticks=trim))
    h = dt / cfg.substeps
    states = np.empty((n, 10))
    sticks = np.empty((n, 4))
    hist_ang = [[0.0, 0.0, 0.0]] * (delay + 2)
    hist_rate = [[0.0, 0.0, 0.0]] * (delay + 2)
    integ = [trim[i] / (-ki * inv_gain[i]) if ki else 0.0 for i in range(3)]
    pd_trim = [0.0, 0.0, 0.0] if ki else trim
    sweeps_l = sweeps.T.tolist()
    jitter_l = jitter.T.tolist()
    col_l = col.tolist()
    torque_l = [tuple(row) for row in torque.T.tolist()]

    def _pilot(k, ahead):
        """Sticks at sample k from what the pilot saw ``delay`` samples earlier."""
        seen_ang = hist_ang[-1 - delay + ahead]
        seen_rate = hist_rate[-1 - delay + ahead]
        u3 = []
        for i in range(3):
            integ[i] += seen_ang[i] * dt
            cmd = -inv_gain[i] * (kp * seen_ang[i] + kdr * seen_rate[i] + ki * integ[i]) + pd_trim[i]
            u3.append(max(-1.0, min(1.0, cmd + sweeps_l[k][i] + jitter_l[k][i])))
        return [u3[0], u3[1], col_l[k], u3[2]]

    # The pilot's hand moves continuously: the aircraft sees the logged sticks
    # linearly interpolated between samples (first-order hold, sampled at every
    # sub-step). A zero-order hold at the log rate would be a digital autopilot,
    # not a pilot, and would look like a half-sample lead to any identifier.
    u_next = None
    hold = cfg.pilot == "autopilot" or cfg.held_sticks  # a flight controller or a digital link holds the sample
    for k in range(n):
        if estimator is not None:
            estimator.update(k, euler_from_quaternion_scalar(x[6], x[7], x[8], x[9]), x[0:3])
        if sensed is None:
            hist_ang.append(euler_from_quaternion_scalar(x[6], x[7], x[8], x[9]))
            hist_rate.append(x[0:3])
        else:
            hist_ang.append(sensed.attitude(k, euler_from_quaternion_scalar(x[6], x[7], x[8], x[9])))
            hist_rate.append(sensed.rate(k, x[0:3]))
        states[k] = x
        u = u_next if u_next is not None else _pilot(k, 0)
        sticks[k] = u
        if k == n - 1:
            break
        u_next = _pilot(k + 1, 1)
        for j in range(cfg.substeps):
            w = 0.0 if hold else (j + 0.5) / cfg.substeps
            uj = tuple([a + w * (b - a) for a, b in zip(u, u_next)])
            x = rk4(x, uj, torque_l[k], h)
        if len(hist_ang) > 4 * (delay + 2):
            del hist_ang[: -(delay + 2)], hist_rate[: -(delay + 2)]
    return states, sticks, None if estimator is None else estimator.estimates


class _AutopilotSensing:
    """What a flight controller flies on: the attitude its estimator reads (truth plus the attitude noise)
    and the gyro it logs (truth plus noise and vibration) through a first-order D-term low-pass. Feeding
    back the true state instead would put in the logged commands information about the gust that no sensor
    has, which no model of the measured rates can use (an idealised loop; on the bench cell it made a
    sub-sample input delay and a gain scheduling look likely, statistic 10-77)."""

    def __init__(self, cfg: FlightConfig, errors: tuple, fs: float, estimator: "_AttitudeEstimator | None" = None):
        self._gyro, self._att = _per_sample(errors)
        self._a = float(np.exp(-2.0 * np.pi * cfg.autopilot_dterm_hz / fs))
        self._state = None
        self._estimator = estimator
        self._filter = GyroFilter(cfg.gyro_filter_hz, fs) if cfg.gyro_filter_hz > 0 else None

    def attitude(self, k: int, true_att) -> list:
        if self._estimator is not None:  # updated at sample k already
            return self._estimator.estimates[:, k].tolist()
        return [t + e for t, e in zip(true_att, self._att[k])]

    def rate(self, k: int, true_rate) -> list:
        raw = [t + e for t, e in zip(true_rate, self._gyro[k])]
        if self._filter is not None:  # the gyro the log carries: the D-term filter comes after it
            raw = self._filter.step(raw)
        if self._state is None:
            self._state = raw
        else:
            self._state = [self._a * s + (1.0 - self._a) * r for s, r in zip(self._state, raw)]
        return list(self._state)


class GyroFilter:
    """A flight controller's gyro low-pass (``FlightConfig.gyro_filter_hz``): a 2-pole Butterworth at ``hz`` on
    each axis, sampled at ``fs`` (scipy's bilinear design, as ArduPilot's ``LowPassFilter2p``), started in its
    steady state at the first reading. :meth:`step` filters one reading of the three axes (the autopilot's loop),
    :meth:`run` a whole series (the log): the same filter, the same values but for rounding."""

    def __init__(self, hz: float, fs: float):
        from scipy.signal import butter

        self._b, self._a = (tuple(float(v) for v in c) for c in butter(2, hz, fs=fs))
        self._z = None

    def run(self, rates: np.ndarray) -> np.ndarray:
        """``rates`` (3, n) filtered along time."""
        from scipy.signal import lfilter, lfilter_zi

        zi = lfilter_zi(self._b, self._a)
        return np.array([lfilter(self._b, self._a, row, zi=zi * row[0])[0] for row in np.asarray(rates, float)])

    def step(self, raw) -> list:
        """One reading (3 floats) filtered (transposed direct form II, as ``lfilter``)."""
        (b0, b1, b2), (_, a1, a2) = self._b, self._a
        if self._z is None:  # the steady state at the first reading: the output equals it
            self._z = [[x * (1.0 - b0), x * (b2 - a2)] for x in raw]  # unit gain at 0 Hz: b0+b1+b2 = 1+a1+a2
        out = []
        for i, x in enumerate(raw):
            z0, z1 = self._z[i]
            y = b0 * x + z0
            self._z[i] = [b1 * x - a1 * y + z1, b2 * x - a2 * y]
            out.append(y)
        return out


def _per_sample(errors: tuple) -> tuple[list, list]:
    """:func:`sensor_errors`' gyro terms summed and the attitude noise, as per-sample rows of Python floats (what
    the flight loop's sensors add at each sample)."""
    gyro, att = errors
    return sum(gyro[1:], gyro[0]).T.tolist(), att.T.tolist()


class _AttitudeEstimator:
    """A flight controller's attitude estimate (``cfg.attitude_filter_tau`` > 0): a complementary filter that
    integrates the gyro as logged (truth plus noise and vibration) through the Euler kinematics and pulls the
    result towards a tilt reading (the truth plus the attitude noise) with the time constant ``tau``. Its
    errors are the gyro's, integrated, plus the tilt noise's low-passed: not white, and not independent of
    the gyro the log carries (what separates a log's attitude from an independent attitude sensor)."""

    def __init__(self, cfg: FlightConfig, errors: tuple, n: int):
        self._gyro, self._att = _per_sample(errors)
        self._dt = 1.0 / cfg.sample_rate
        self._pull = 1.0 - float(np.exp(-self._dt / cfg.attitude_filter_tau))
        self.estimates = np.empty((3, n))

    def update(self, k: int, true_att, true_rate) -> None:
        """The estimate at sample ``k`` from the one before, the gyro read at ``k - 1`` and the tilt at ``k``."""
        tilt = [t + e for t, e in zip(true_att, self._att[k])]
        if k == 0:
            self.estimates[:, 0] = tilt
            self._last_rate = [r + e for r, e in zip(true_rate, self._gyro[0])]
            return
        last = self.estimates[:, k - 1]
        ahead = (last + self._dt * euler_rates(last[0], last[1], *self._last_rate)).tolist()
        gap = [t - a for t, a in zip(tilt, ahead)]
        gap[2] = float(np.angle(np.exp(1j * gap[2])))  # heading: the short way round
        self.estimates[:, k] = [a + self._pull * g for a, g in zip(ahead, gap)]
        self._last_rate = [r + e for r, e in zip(true_rate, self._gyro[k])]


def sensor_errors(rng: np.random.Generator, cfg: FlightConfig, time) -> tuple[list, np.ndarray]:
    """What the gyro and the attitude sensor add to the truth, drawn before the flight (a flight controller
    flies on what its sensors read): the gyro's terms (noise, rotor vibration, ``cfg.vibration_lines``),
    each (3, n), in the order they are added, and the attitude noise (3, n). The flight tests of
    :mod:`controllers.flight_test` draw their sensors with it too."""
    n = time.size
    phase = rng.uniform(0, 2 * np.pi, size=(3, 2))
    vib = sum(
        cfg.vibration / (j + 1) * np.sin(2 * np.pi * (j + 1) * cfg.rotor_hz * time[None, :] + phase[:, j : j + 1])
        for j in range(2)
    )
    gyro = [cfg.gyro_noise * rng.standard_normal((3, n)), vib]
    att = cfg.attitude_noise * rng.standard_normal((3, n))
    for hz, amp in cfg.vibration_lines:  # drawn after today's sensor noise: default flights unchanged
        gyro.append(amp * np.sin(2 * np.pi * float(hz) * time[None, :] + rng.uniform(0, 2 * np.pi, (3, 1))))
    return gyro, att


def _sensors(errors: tuple, true_rates, true_att, estimated=None):
    """What the gyro and the attitude sensor log: the truth plus :func:`sensor_errors` (the attitude the
    flight controller's ``estimated`` one where given), yaw wrapped to (-pi, pi]. Returns (rates, attitude),
    each (3, n)."""
    gyro, att_noise = errors
    rates = true_rates
    for term in gyro:
        rates = rates + term
    att = true_att + att_noise if estimated is None else estimated.copy()
    att[2] = np.angle(np.exp(1j * att[2]))
    return rates, att


def _logged_flight(cfg: FlightConfig, seed, effects, time, rates, att, sticks) -> Flight:
    """The :class:`Flight` the logger wrote: sticks (n, 4) shifted by ``cfg.input_shift``, provenance."""
    meta = {
        "source": f"synthetic seed={seed}",
        "format": "synthetic",
        "seed": int(seed),
        "effects": list(effects),
        "input_source": "flight controller commands" if cfg.pilot == "autopilot" else "pilot sticks",
        "input_hold": "zoh" if cfg.pilot == "autopilot" or cfg.held_sticks else "linear",
        **({"loop_rate_hz": float(cfg.sample_rate)} if cfg.pilot == "autopilot" else {}),  # it decides every step
        **({"gyro_filter_hz": float(cfg.gyro_filter_hz)} if cfg.gyro_filter_hz > 0 else {}),  # as its parameters
    }
    logged = np.ascontiguousarray(sticks.T)
    n = time.size
    shift = int(round(cfg.input_shift * cfg.sample_rate))
    if shift:  # the log's stick column recorded late (> 0) or early (< 0), edges held
        idx = np.clip(np.arange(n) - shift, 0, n - 1)
        logged = np.ascontiguousarray(logged[:, idx])
        meta["input_shift_s"] = shift / cfg.sample_rate
    return make_flight(time, rates, logged, attitude=att, metadata=meta)
