"""What a synthetic flight is flown with: the truth model and its hidden effects, and the conditions of the
flight (:class:`FlightConfig`: duration, pilot, wind, sweeps, sensors).

:func:`identification.bench.synthetic.simulate_flight` flies a configuration; the bench's named cells
(:mod:`identification.bench.cells`) are configurations. The paper's identified values (eqs. 68-70) are the
default truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from heli_core.params import ModelParams

PAPER_PARAMS = ModelParams(
    k2=1.3475, k3=2.4208, kd1=0.0399,
    k6=-0.8903, k7=2.5188, kd2=0.0115,
    k10=13.4702, k11=3.4342, k12=-0.5623, kd3=0.0964,
)
"""The paper's identified decoupled values, eqs. (68)-(70)."""

EFFECTS: dict[str, dict[str, float]] = {
    "servo_delay": {"tau_roll": 0.08, "tau_pitch": 0.08, "tau_yaw": 0.05},
    "cross_coupling": {"k4": 0.8, "k8": 0.7},
    "gyroscopic": {"k1": 0.8, "k5": 0.9, "k9": -0.95},
    "nonlinear_damping": {"nld1": 2.0, "nld2": 2.0, "nld3": 0.6},
    "gain_scheduling": {"gs1": -0.6 * 1.3475, "gs2": -0.6 * -0.8903, "gs3": -0.6 * 13.4702},
    "collective_torque": {"ct1": 0.25, "ct2": -0.2},
    "servo_lag": {"lag_roll": 0.04, "lag_pitch": 0.04, "lag_yaw": 0.03},
}
"""Physical effects that can be hidden in a synthetic flight, with their truth values.

``servo_delay`` is a transport delay (Padé, eq. 31); ``cross_coupling`` the
flybar terms k4, k8 (eq. 19, 22); ``gyroscopic`` the inertia ratios k1, k5, k9
(inertias of a slender fuselage); ``nonlinear_damping`` a quadratic damping;
``gain_scheduling`` control effectiveness falling by 60 % per unit collective;
``collective_torque`` collective driving roll and pitch; ``servo_lag`` servos that lag their command by a
first-order time constant (eq. 31's ``d1``).
"""
EFFECT_ALIASES = {"flybar": "cross_coupling", "quadratic_damping": "nonlinear_damping",
                  "collective_effectiveness": "gain_scheduling"}


def truth_params(effects=(), base: ModelParams = PAPER_PARAMS, scale: float = 1.0) -> ModelParams:
    """Truth parameters: ``base`` with the named :data:`EFFECTS` switched on, their parameters times ``scale``."""
    values = {}
    for name in effects:
        key = EFFECT_ALIASES.get(name, name)
        if key not in EFFECTS:
            raise ValueError(f"unknown effect {name!r}; known: {', '.join(list(EFFECTS) + list(EFFECT_ALIASES))}")
        values.update({k: scale * v for k, v in EFFECTS[key].items()})
    return base.with_values(**values)


@dataclass(frozen=True)
class FlightConfig:
    """Settings of a synthetic flight.

    Attributes
    ----------
    duration : float
        Flight length [s].
    sample_rate : float
        Logging rate [Hz] (paper: 100 Hz).
    wind_level : float or tuple of 3 float
        Half-width of the 90 % interval of the equivalent cyclic (or pedal) wind
        input u_d of eq. (42) per axis [stick units]. Paper: about 0.09 in roll
        (Section 3.3). Yaw defaults to 0.03: the tail rotor's control power k10
        is ten times the cyclic's, so the same gust torque is a smaller pedal.
    wind_corner_hz : float
        Corner frequency of the wind's second-order low-pass shaping [Hz].
    pilot_bandwidth : float
        Natural frequency of the pilot's attitude-hold loop [rad/s].
    reaction_delay : float
        Pilot reaction delay [s].
    sweep_amplitude : tuple of 3 float
        Stick amplitude of the frequency sweeps on lat, lon, ped.
    sweep_band : tuple of 2 float
        Start and end frequency of each sweep [Hz] (Section 2.1: about 1-3 Hz;
        we start lower, 0.3 Hz, to excite the damping).
    sweep_length, rest_length : float
        Length of one sweep and of the hover rest after it [s].
    sweep_mode : {"sequential", "simultaneous"}
        One stick at a time (roll → pitch → yaw, the paper's Section 2.1), or
        all three sticks at once as an aggressive multi-axis manoeuvre (pitch
        sweeping the band downwards, yaw at a third of the roll frequency), so
        that products of rates (gyroscopic terms) are excited.
    stick_noise : float
        Standard deviation of the pilot's own stick jitter [stick units].
    collective_trim, collective_wander : float
        Hover collective and the std of its slow wander [stick units].
    gyro_noise : float
        Gyro white-noise standard deviation [rad/s].
    vibration : float
        Amplitude of rotor vibration on each gyro axis [rad/s].
    rotor_hz : float
        Main-rotor rotation frequency [Hz].
    attitude_noise : float
        Attitude-sensor noise standard deviation [rad].
    attitude_filter_tau : float
        0 (default): the logged attitude, and the autopilot's, is an attitude sensor's: the truth plus
        ``attitude_noise``, independent of the gyro. > 0: a flight controller's estimator, as real logs
        carry: the logged gyro (noise and vibration included) integrated through the Euler kinematics and
        pulled towards a tilt reading (truth plus ``attitude_noise``) with this time constant [s]; the log
        and the autopilot get that estimate, whose errors are the gyro's own, integrated.
    substeps : int
        RK4 sub-steps of the truth simulation per sample.
    wind_model : {"lowpass", "gauss_markov", "dryden"}
        Shape of the gust spectrum: ``"lowpass"`` white noise through a second-order Butterworth at
        ``wind_corner_hz`` (falls as 1/f^4); ``"gauss_markov"`` a first-order Gauss-Markov process of time
        constant ``wind_fast_tau`` (falls as 1/f^2, broadband); ``"dryden"`` the lateral Dryden form
        ``(1 + sqrt(3) s/w)/(1 + s/w)^2`` with ``w = 2 pi wind_corner_hz`` (a zero and a double pole).
        Whatever the model, the total u_d is scaled to ``wind_level``.
    wind_fast_tau : float
        Time constant of the ``"gauss_markov"`` gusts [s].
    wind_slow_fraction : float
        Share of the wind's variance in a slow first-order Gauss-Markov part added to the model's (0..1).
    wind_slow_tau : float
        Its time constant [s].
    pilot : {"pid", "pd", "autopilot"}
        ``"pid"`` the human pilot above; ``"pd"`` a pilot who fights gusts with a PD on the attitude and the
        rate seen ``reaction_delay`` ago (no integral; he knows the trim); ``"autopilot"`` a digital flight
        controller: PD on attitude and rate one sample old, as its sensors read them (the gyro's noise and
        vibration, through its D-term low-pass), the commands held between samples.
    vibration_lines : tuple of (float, float)
        Extra sinusoidal lines on every gyro axis: (frequency [Hz], amplitude [rad/s]).
    input_shift : float
        The logged sticks are shifted by this many seconds (whole samples): > 0 the log's input column lags
        the true input (recorded late), < 0 it leads.
    autopilot_dterm_hz : float
        Corner of the autopilot's first-order low-pass on the gyro it flies on [Hz].
    held_sticks : bool
        The aircraft sees each logged stick held over its sample (a digital radio link or a flight
        controller delivering the pilot's sticks at the log rate), not interpolated; the autopilot always
        holds its commands.
    command_noise : float
        Standard deviation of white noise added to every logged command, sample by sample [stick units]
        (a digital link's quantisation and the hand's tremor: what makes a held stick differ most from an
        interpolated one).
    gyro_filter_hz : float
        0 (default): the log carries the gyro as sampled. > 0: a flight controller's gyro low-pass, a 2-pole
        Butterworth at this corner [Hz] run at the world's rate (ArduPilot's ``INS_GYRO_FILTER``, 20 Hz by default;
        ``docs/method.md``, "A filtered gyro"): the log's rates and the gyro the autopilot flies on are the filtered
        ones, late by about ``sqrt(2) / (2 pi f)`` (11 ms at 20 Hz) against the sticks.
    log_every : int
        1 (default): the aircraft's world (pilot, gusts, sensors) steps at ``sample_rate``, the log's rate. > 1:
        it steps ``log_every`` times faster and the log keeps every ``log_every``-th sample, as a logger
        sampling a faster loop writes it: a pilot who decides, a link that delivers and gusts that change
        between the log's samples, none of which the log shows (docs/method.md, "A world faster than its log").
    """

    duration: float = 300.0
    sample_rate: float = 100.0
    wind_level: tuple = (0.09, 0.09, 0.03)
    wind_corner_hz: float = 0.5
    pilot_bandwidth: float = 2.0
    reaction_delay: float = 0.2
    sweep_amplitude: tuple = (0.5, 0.5, 0.08)
    sweep_band: tuple = (0.3, 3.0)
    sweep_length: float = 20.0
    rest_length: float = 8.0
    sweep_mode: str = "sequential"
    stick_noise: float = 0.01
    collective_trim: float = 0.2
    collective_wander: float = 0.12
    gyro_noise: float = 0.01
    vibration: float = 0.04
    rotor_hz: float = 30.0
    attitude_noise: float = 0.003
    attitude_filter_tau: float = 0.0
    substeps: int = 4
    wind_model: str = "lowpass"
    wind_fast_tau: float = 0.35
    wind_slow_fraction: float = 0.0
    wind_slow_tau: float = 4.0
    pilot: str = "pid"
    vibration_lines: tuple = ()
    input_shift: float = 0.0
    autopilot_dterm_hz: float = 20.0
    held_sticks: bool = False
    command_noise: float = 0.0
    log_every: int = 1
    gyro_filter_hz: float = 0.0

    def __post_init__(self):
        wind = np.asarray(self.wind_level, dtype=float)
        checks = {
            "duration": 0 < self.duration < math.inf, "sample_rate": 0 < self.sample_rate < math.inf,
            "wind_level": wind.ndim <= 1 and wind.size in (1, 3) and bool(np.all((wind >= 0) & np.isfinite(wind))),
            "wind_corner_hz": self.wind_corner_hz > 0,
            "pilot_bandwidth": self.pilot_bandwidth > 0, "reaction_delay": self.reaction_delay >= 0,
            "substeps": isinstance(self.substeps, (int, np.integer)) and self.substeps >= 1,
            "log_every": isinstance(self.log_every, (int, np.integer)) and self.log_every >= 1,
            "gyro_filter_hz": self.gyro_filter_hz == 0.0 or 0.0 < self.gyro_filter_hz < self.sample_rate * self.log_every / 2,
            "sweep_mode": self.sweep_mode in ("sequential", "simultaneous"),
            "wind_model": self.wind_model in WIND_MODELS,
            "wind_fast_tau": 0 < self.wind_fast_tau < math.inf,
            "wind_slow_fraction": 0.0 <= self.wind_slow_fraction <= 1.0,
            "wind_slow_tau": 0 < self.wind_slow_tau < math.inf,
            "pilot": self.pilot in PILOTS,
            "vibration_lines": all(len(line) == 2 and 0 < float(line[0]) < math.inf and float(line[1]) >= 0
                                   for line in self.vibration_lines),
            "input_shift": abs(self.input_shift) < self.duration / 2,
            "autopilot_dterm_hz": 0 < self.autopilot_dterm_hz < math.inf,
        }
        for name in ("stick_noise", "collective_wander", "gyro_noise", "vibration", "attitude_noise", "command_noise",
                     "attitude_filter_tau"):
            checks[name] = getattr(self, name) >= 0
        expected = {"wind_model": f"one of {WIND_MODELS}", "pilot": f"one of {PILOTS}",
                    "wind_slow_fraction": "a fraction in [0, 1]", "input_shift": "|shift| < half the duration",
                    "vibration_lines": "(frequency Hz > 0, amplitude rad/s >= 0) pairs",
                    "log_every": "a whole number >= 1",
                    "gyro_filter_hz": "0 (none) or a corner in Hz below the world's Nyquist rate"}
        for name, ok in checks.items():
            if not ok:
                hint = f"; expected {expected[name]}" if name in expected else ""
                raise ValueError(f"FlightConfig.{name} out of range: {getattr(self, name)!r}{hint}")

    def inert(self, names) -> dict:
        """Which of the fields ``names`` this flight does not read, each with the reason: a changed value there
        would leave the flight as it was (``wind_corner_hz`` shapes the lowpass and Dryden gusts only,
        ``wind_fast_tau`` the Gauss-Markov ones, ``wind_slow_tau`` the slow part when it has a share,
        ``autopilot_dterm_hz`` the autopilot pilot)."""
        reasons = {
            "wind_corner_hz": (self.wind_model == "gauss_markov",
                               "the gusts are gauss_markov (their time constant is wind_fast_tau)"),
            "wind_fast_tau": (self.wind_model != "gauss_markov",
                              f"the gusts are {self.wind_model} (their corner is wind_corner_hz)"),
            "wind_slow_tau": (self.wind_slow_fraction == 0, "the slow gusts have no share (wind_slow_fraction 0)"),
            "autopilot_dterm_hz": (self.pilot != "autopilot", f"the pilot is {self.pilot!r}, not the autopilot"),
        }
        return {name: reasons[name][1] for name in names if name in reasons and reasons[name][0]}


WIND_MODELS = ("lowpass", "gauss_markov", "dryden")
"""Gust spectra of :class:`FlightConfig` (``wind_model``)."""
PILOTS = ("pid", "pd", "autopilot")
"""Pilots of :class:`FlightConfig` (``pilot``)."""


MANOEUVRE_CONFIG = FlightConfig(sweep_amplitude=(0.8, 0.8, 0.25), sweep_mode="simultaneous")
"""An aggressive pilot: large sweeps on all three sticks at once (rates to about 60 deg/s in roll and
150 deg/s in yaw). Effects that scale with products or powers of the rates (gyroscopic, non-linear
damping) are invisible under the gentle one-stick sweeps of the default flight."""
