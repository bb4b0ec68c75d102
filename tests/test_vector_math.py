"""The branch-free atan2 and asin of the vector env's step (heli_env.vector_math) against the C library's."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from heli_core.quaternion import euler_arguments
from heli_env.vector_math import asinv, atan2v


@numba.njit
def _atan2_all(y, x):
    out = np.empty_like(y)
    for i in range(y.shape[0]):
        out[i] = atan2v(y[i], x[i])
    return out


@numba.njit
def _asin_all(s):
    out = np.empty_like(s)
    for i in range(s.shape[0]):
        out[i] = asinv(s[i])
    return out


def _ulps(values, reference):
    return np.abs(values - reference) / np.spacing(np.abs(reference))


@pytest.mark.parametrize("tilt", [1.0, 1e-3, 1e-9])
def test_euler_angles_within_an_ulp_or_two_of_the_c_library(tilt):
    """On the arguments the env computes (unit quaternions, from large attitudes to level): atan2 within 1 ulp
    and asin within 2 ulp of math.atan2 / math.asin."""
    rng = np.random.default_rng(0)
    q = rng.normal(size=(4, 20000))
    q[1:] *= tilt
    q /= np.linalg.norm(q, axis=0)
    a0, a1, a2, a3, a4 = euler_arguments(*q)
    a2 = np.clip(a2, -1.0, 1.0)
    for y, x in ((a0, a1), (a3, a4)):
        reference = np.array([math.atan2(u, v) for u, v in zip(y, x)])
        assert _ulps(_atan2_all(y, x), reference).max() <= 1.0
    reference = np.array([math.asin(v) for v in a2])
    assert _ulps(_asin_all(a2), reference).max() <= 2.0


def test_special_values_follow_the_c_library():
    cases = [(0.0, 0.0), (-0.0, 0.0), (0.0, -0.0), (-0.0, -0.0), (0.0, -1.0), (-0.0, -1.0), (1.0, 0.0),
             (-1.0, 0.0), (1.0, 1.0), (-1.0, -1.0), (1e-300, 1.0), (1.0, -1e-300), (3.0, -4.0), (-5e-324, 1.0)]
    y, x = np.array(cases).T
    got = _atan2_all(y, x)
    for g, (u, v) in zip(got, cases):
        want = math.atan2(u, v)
        assert g == want and math.copysign(1.0, g) == math.copysign(1.0, want), (u, v)
    s = np.array([1.0, -1.0, 0.0, -0.0, 0.5, 1 - 2**-52])
    assert np.array_equal(_asin_all(s), [math.asin(v) for v in s])
    assert math.copysign(1.0, _asin_all(np.array([-0.0]))[0]) == -1.0
    assert np.isnan(_atan2_all(np.array([np.nan]), np.array([1.0]))[0])
