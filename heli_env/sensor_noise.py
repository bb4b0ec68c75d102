"""Counter-based standard normals: the sensor noise of an episode as a function of (key, step, channel).

The white noise of the sensors (:class:`heli_core.sensors.SensorModel`: attitude estimate and gyros, 6
channels) is drawn per episode from one 64-bit ``key`` that the environment's ``np_random`` draws at reset
(:func:`draw_noise_key`). Sample ``c`` of step ``k`` is then

    ``z = standard_normal(key, 6 * k + c)``

a pure function of its arguments: nothing is consumed, so a vector env computes every copy's noise inside
its compiled observation loop (on any thread, in any order) and a single env seeded alike reads the same
values, block by block (:func:`noise_block`). Before, each copy drew its noise from its own numpy generator,
which at 4096 copies cost three times the rest of the step.

The uniform bits are the SplitMix64 stream seeded with the key (Steele, Lea & Flood 2014: the state after
``n`` outputs is ``key + n * GAMMA``, whose mix passes BigCrush). Word ``m`` of it serves samples ``2 m``
(its low 32 bits) and ``2 m + 1`` (its high 32 bits); a sample's further draws, rarely needed, are the
words at ``s + d * 2**40``, far beyond any episode's first tries. The normals come from the ziggurat
method with 256 layers in Doornik's form (ZIGNOR, "An improved ziggurat method to generate normal random
samples", 2005): 8 bits pick a layer and 24 bits give ``u``, and a comparison accepts about 99 % of
samples; the wedges and the tail (beyond 3.654) are exact by rejection. The 24-bit ``u`` sets the
resolution: a sample is a multiple of 2**-23 of its layer's width, finer than the float32 observation
can show of noise added to an angle.
"""

from __future__ import annotations

import math

import numba
import numpy as np

CHANNELS = 6
"""Noise samples per step: attitude roll, pitch, yaw, then gyro p, q, r."""

_LAYERS = 256
_R = 3.6541528853610088
"""Start of the tail: the right edge of the ziggurat's base layer."""
_V = 0.00492867323399
"""Area of each of the 256 layers (the base layer includes the tail)."""


def _tables() -> tuple[np.ndarray, np.ndarray]:
    """ZIGNOR's layer edges ``x`` (257, x[0] the base layer's virtual width) and ratios ``x[i+1] / x[i]``."""
    x = np.zeros(_LAYERS + 1)
    f = math.exp(-0.5 * _R * _R)
    x[0] = _V / f
    x[1] = _R
    for i in range(2, _LAYERS):
        x[i] = math.sqrt(-2.0 * math.log(_V / x[i - 1] + f))
        f = math.exp(-0.5 * x[i] * x[i])
    return x, x[1:] / x[:-1]


_X, _RATIO = _tables()

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_AGAIN = np.uint64(1 << 40)
_LOW = np.uint64(0xFFFFFFFF)
_TO_UNIT = 2.0 ** -53
_TO_UNIT_24 = 2.0 ** -24


@numba.njit(inline="always")
def _bits(key, position):
    """Output ``position`` of the SplitMix64 stream seeded ``key`` (uint64 arithmetic, wrapping)."""
    z = key + position * _GAMMA
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


@numba.njit(inline="always")
def _open_unit(b):
    """A uniform in (0, 1) from the top 53 bits of ``b``."""
    return (float(b >> np.uint64(11)) + 0.5) * _TO_UNIT


@numba.njit(error_model="numpy", cache=True)
def _slow(key, sample, i, u):
    """The ~1 % of samples the rectangles reject (layer ``i``, ``u`` in (-1, 1)): ZIGNOR's wedge test and
    tail, drawing further 64-bit words at positions ``sample + d * 2**40``."""
    x_tab, ratio = _X, _RATIO
    position = np.uint64(sample)
    d = np.uint64(0)
    while True:
        if abs(u) < ratio[i]:
            return u * x_tab[i]
        if i == 0:  # the base layer beyond the rectangle: the tail, by Marsaglia's method
            while True:
                d += np.uint64(1)
                t = math.log(_open_unit(_bits(key, position + d * _AGAIN))) / _R
                d += np.uint64(1)
                y = math.log(_open_unit(_bits(key, position + d * _AGAIN)))
                if -2.0 * y >= t * t:
                    return t - _R if u < 0.0 else _R - t
        x = u * x_tab[i]
        f0 = math.exp(-0.5 * (x_tab[i] * x_tab[i] - x * x))
        f1 = math.exp(-0.5 * (x_tab[i + np.uint64(1)] * x_tab[i + np.uint64(1)] - x * x))
        d += np.uint64(1)
        if f1 + _open_unit(_bits(key, position + d * _AGAIN)) * (f0 - f1) < 1.0:
            return x
        d += np.uint64(1)
        b = _bits(key, position + d * _AGAIN)
        i = b & np.uint64(0xFF)
        u = 2.0 * _open_unit(b) - 1.0


@numba.njit(inline="always")
def _from_word(key, sample, w):
    """The normal of 32-bit word ``w``: layer from its low 8 bits, ``u`` in (-1, 1) from its top 24."""
    i = w & np.uint64(0xFF)
    u = (float(w >> np.uint64(8)) + 0.5) * _TO_UNIT_24 * 2.0 - 1.0
    if abs(u) < _RATIO[i]:
        return u * _X[i]
    return _slow(key, sample, i, u)


LOW32 = _LOW
"""The low 32 bits of a word."""

stream_bits = _bits


@numba.njit(inline="always")
def fast_normal(w):
    """The ziggurat's rectangle test alone on 32-bit word ``w``: ``(z, again)``, ``z`` the normal of
    :func:`standard_normal` when ``again`` is False; when True (about 1 % of words) the sample needs the
    slow path, :func:`standard_normal`. Branch-free, so that a loop over copies runs 8 of them an instruction."""
    i = w & np.uint64(0xFF)
    u = (float(w >> np.uint64(8)) + 0.5) * _TO_UNIT_24 * 2.0 - 1.0
    return u * _X[i], not abs(u) < _RATIO[i]


@numba.njit(inline="always")
def normal_pair(key, pair):
    """Standard normals ``2 pair`` and ``2 pair + 1`` of the stream of ``key`` (uint64): the low and the
    high half of one 64-bit word."""
    b = _bits(key, np.uint64(pair))
    return (_from_word(key, 2 * pair, b & _LOW), _from_word(key, 2 * pair + 1, b >> np.uint64(32)))


@numba.njit(inline="always")
def standard_normal(key, sample):
    """Standard normal number ``sample`` (an integer >= 0) of the stream of ``key`` (uint64)."""
    b = _bits(key, np.uint64(sample >> 1))
    w = b >> np.uint64(32) if sample & 1 else b & _LOW
    return _from_word(key, sample, w)


@numba.njit(error_model="numpy", cache=True)
def noise_block(key, first_step, steps):
    """The ``(steps, CHANNELS)`` standard normals of steps ``first_step .. first_step + steps - 1``."""
    out = np.empty((steps, CHANNELS))
    for k in range(steps):
        for c in range(0, CHANNELS, 2):
            out[k, c], out[k, c + 1] = normal_pair(key, ((first_step + k) * CHANNELS + c) >> 1)
    return out


def draw_noise_key(rng: np.random.Generator) -> np.uint64:
    """An episode's noise key: one 64-bit draw from the environment's ``np_random`` (both envs, at reset)."""
    return rng.integers(0, 2**64, dtype=np.uint64)
