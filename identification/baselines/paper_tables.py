"""The settings of the paper's baseline tables: Table 3's NLR start points, Table 4's EKF cases and Table 5's
window lengths.

They are the paper's numbers, not part of either algorithm: :mod:`identification.baselines.nlr` and
:mod:`identification.baselines.ekf` take them as defaults, and the method comparison
(:mod:`identification.bench.comparison_config`) runs the tables from them without importing the estimators.
"""

from __future__ import annotations

TABLE3_STARTS: tuple[tuple[float, float, float], ...] = ((5.0, 5.0, 5.0), (50.0, 50.0, 50.0), (100.0, 100.0, 100.0))
"""Start points of eq. (73) and Table 3, each ``(k_damp, k_gain, kd)``."""

TABLE4_M0 = {"a": (0.0, 0.1, 10.0, 0.1), "b": (0.0, 2.0, 3.0, 0.0)}
"""Initial states ``m_o = [p0, k_damp, k_gain, kd]`` of Table 4, cases (a) and (b)."""

TABLE4_Q = {1: 1.0, 2: 1e-8, 3: 1e-2}
"""Process-noise variances ``Q`` [(rad/s)^2] of Table 4, cases 1-3."""

TABLE5_LENGTHS = (4.84, 11.0, 22.0)
"""Identification-window lengths of Table 5 [s]."""
