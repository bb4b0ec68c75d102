"""What the method comparison runs and how it times it: :class:`ComparisonConfig` (Tables 3-5's settings).

:func:`identification.bench.method_comparison.compare_methods` takes it and
:class:`identification.bench.method_runs.MethodRunner` runs each method by it; it stands apart from both
so that the runner does not import the comparison that runs it.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..baselines.paper_tables import TABLE3_STARTS, TABLE4_M0, TABLE4_Q, TABLE5_LENGTHS
from ..preprocess import DEFAULT_PASS_HZ, DEFAULT_STOP_HZ

TABLE4_CASES: tuple[tuple[str, float, tuple[float, ...]], ...] = tuple(
    (f"Case {c}({m})", TABLE4_Q[c], TABLE4_M0[m]) for c in (1, 2, 3) for m in ("a", "b")
)
"""Table 4's six EKF settings ``(label, Q [(rad/s)^2], m_o = [p0, k_damp, k_gain, kd])``."""

DEFAULT_REPEATS = {"integral": 20, "ekf": 3, "nlr": 1}
"""Timed runs per method; the median CPU and wall time are reported."""

QUICK_NLR_MAX_NFEV = 10
"""Objective evaluations allowed per NLR start with ``--quick`` (a converged
roll fit from eq. (73)'s start takes about 8-9; far starts are cut short)."""


@dataclass(frozen=True)
class ComparisonConfig:
    """What :func:`compare_methods` runs and how it times it.

    Attributes
    ----------
    nlr_starts : tuple of tuple of float, shape (n_starts, 3)
        NLR start points ``(k_damp, k_gain, kd)``; default Table 3's.
    ekf_cases : tuple of (label, q, m0)
        EKF settings; default Table 4's six cases (:data:`TABLE4_CASES`).
    sample_lengths : tuple of float
        Table 5 identification windows [s], each at most the flight's duration.
        The EKF settings are :data:`TABLE5_EKF`.
    repeats : dict, optional
        Timed runs per method, merged into :data:`DEFAULT_REPEATS` (keys
        ``"integral"``, ``"ekf"``, ``"nlr"``); Table 5 uses the EKF's. Once
        built, the merged counts.
    nlr_max_nfev : int, optional
        Objective evaluations allowed per NLR start (``None``: scipy's default).
    prefilter : bool
        Low-pass filter the flight first (Section 3.1); off when it already is.
    pass_hz, stop_hz : float
        Band edges of the prefilter [Hz].
    blas_threads : int or None
        BLAS threads while timing (needs ``threadpoolctl``; ``None`` leaves them).
    quick : bool
        Recorded in the result (and the Markdown) to flag a shortened run.

    Raises
    ------
    ValueError
        Unknown repeat keys or counts that are not positive integers, bad start
        points or EKF settings.
    """

    nlr_starts: tuple = TABLE3_STARTS
    ekf_cases: tuple = TABLE4_CASES
    sample_lengths: tuple = TABLE5_LENGTHS
    repeats: dict | None = None
    nlr_max_nfev: int | None = None
    prefilter: bool = True
    pass_hz: float = DEFAULT_PASS_HZ
    stop_hz: float = DEFAULT_STOP_HZ
    blas_threads: int | None = 1
    quick: bool = False

    def __post_init__(self):
        reps = dict(DEFAULT_REPEATS)
        if self.repeats:
            unknown = set(self.repeats) - set(reps)
            if unknown:
                raise ValueError(f"repeats keys must be among {sorted(reps)}, got {sorted(unknown)}")
            reps.update(self.repeats)
        for k, v in reps.items():
            if int(v) != v or v < 1:
                raise ValueError(f"repeats[{k!r}] must be a positive integer, got {v!r}")
        object.__setattr__(self, "repeats", reps)
        object.__setattr__(self, "sample_lengths", tuple(float(v) for v in self.sample_lengths))
        object.__setattr__(self, "nlr_starts", tuple(tuple(float(v) for v in s) for s in self.nlr_starts))
        object.__setattr__(self, "ekf_cases", tuple((str(label), float(q), tuple(float(v) for v in m0))
                                                    for label, q, m0 in self.ekf_cases))
