"""The test bench: named conditions a user flies in, to judge estimators beyond the default flight.

Each cell of :data:`BENCH_CELLS` is a :class:`~identification.bench.flight_config.FlightConfig` that changes
the wind (spectrum, level, slow gusts), the pilot (human PID or PD with a reaction delay, a digital
autopilot holding its commands) or the sensors (vibration lines, gyro noise) of the default synthetic
flight. :data:`PAPER_LEVEL_CLOSED_LOOP_BROADBAND` names the cells of the headline target: a pilot
who fights broadband gusts at the paper's level (u_d 90 % half-width 0.09 in roll and pitch).
The cell ``"independent"`` mimics the independent simulator of the turbulence issue: a PD pilot
with a 0.18 s reaction, one-stick 0.3-3 Hz sweeps, gusts with a slow part (4 s) and a broadband
part (0.35 s) at the paper's level, gyro noise and a 27 Hz vibration line. The cell ``"held-sticks-pd"``
is the same pilot (reacting to what he saw 0.18 s earlier) whose sticks reach the aircraft held over each
10 ms sample, as a digital radio link or a flight controller delivers them, with a little white noise on the
commands: the log does not say how its sticks move between samples, and an estimator that assumes either
hold is biased on the other kind.

``heli simulate-flight --cell NAME`` writes a flight of a cell; ``scripts/identification_bias.py``
identifies every cell over many seeds.
"""

from __future__ import annotations

from dataclasses import replace

from .flight_config import FlightConfig
from .synthetic import SyntheticFlight, simulate_flight

PAPER_WIND = (0.09, 0.09, 0.03)
"""The paper's gust level: 90 % half-width of u_d on roll, pitch, yaw (Section 3.3)."""


def _wind(scale: float) -> tuple:
    return tuple(scale * w for w in PAPER_WIND)


_BROADBAND = dict(wind_model="gauss_markov", wind_fast_tau=0.35, wind_slow_fraction=0.5, wind_slow_tau=4.0,
                  vibration_lines=((27.0, 0.03),))
_PD = dict(pilot="pd", reaction_delay=0.18)

BENCH_CELLS: dict[str, FlightConfig] = {
    "default": FlightConfig(),
    "independent": FlightConfig(**_PD, **_BROADBAND),
    "broadband-pd-half": FlightConfig(**_PD, **_BROADBAND, wind_level=_wind(0.5)),
    "broadband-pd-2x": FlightConfig(**_PD, **_BROADBAND, wind_level=_wind(2.0)),
    "broadband-pd-delay0.1": FlightConfig(**{**_PD, "reaction_delay": 0.1}, **_BROADBAND),
    "broadband-pd-delay0.25": FlightConfig(**{**_PD, "reaction_delay": 0.25}, **_BROADBAND),
    "dryden-0.2Hz-pid": FlightConfig(wind_model="dryden", wind_corner_hz=0.2),
    "dryden-2Hz-pd": FlightConfig(**_PD, wind_model="dryden", wind_corner_hz=2.0),
    "broadband-autopilot": FlightConfig(pilot="autopilot", pilot_bandwidth=4.0, **_BROADBAND),
    "held-sticks-pd": FlightConfig(**_PD, **_BROADBAND, held_sticks=True, command_noise=0.01),
    "broadband-pd-noisy-gyro": FlightConfig(**_PD, **{**_BROADBAND, "vibration_lines": ((27.0, 0.06), (41.5, 0.04))},
                                            gyro_noise=0.03),
}
"""Named conditions (module docstring)."""

PAPER_LEVEL_CLOSED_LOOP_BROADBAND = ("independent", "broadband-pd-delay0.1", "broadband-pd-delay0.25",
                                     "dryden-2Hz-pd", "broadband-pd-noisy-gyro")
"""The cells of the headline target: a closed-loop pilot, broadband gusts, the paper's level."""


def bench_flight(cell: str, seed: int, duration: float = 300.0, effects=()) -> SyntheticFlight:
    """A flight of bench cell ``cell`` (same seed, same flight).

    Raises
    ------
    ValueError
        An unknown cell (the message lists the known ones).
    """
    if cell not in BENCH_CELLS:
        raise ValueError(f"unknown bench cell {cell!r}; known: {', '.join(BENCH_CELLS)}")
    return simulate_flight(duration, seed=seed, effects=effects, config=replace(BENCH_CELLS[cell], duration=duration))
