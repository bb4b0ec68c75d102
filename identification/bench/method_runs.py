"""One row of the method comparison: a method fitted on the flight, timed and scored (:class:`MethodRun`).

:class:`MethodRunner` runs each identifier of
:func:`~identification.bench.method_comparison.compare_methods` on the prefiltered
flight: its ``fit`` call timed with :func:`time.process_time` (CPU) and
:func:`time.perf_counter` (wall), repeated after one untimed warm-up for the
fast methods (medians kept), while BLAS is held to a number of threads
(:func:`limit_blas`); then the identified model forward-simulated over the
whole flight, and over the validation flight when there is one
(:func:`identification.baselines.simulate_rate`), and scored by mean absolute
error and 90th percentile (:func:`identification.baselines.rate_errors`).
"""

from __future__ import annotations

import contextlib
import statistics
import sys
import time
from dataclasses import dataclass

from heli_core.files import jsonable

from ..baselines.ekf import ParameterEKF
from ..baselines.nlr import NonlinearRegression
from ..baselines.paper_tables import TABLE4_M0, TABLE4_Q
from ..baselines.single_axis import axis_index, make_params, rate_errors, simulate_rate
from ..flight import Flight
from ..integral.method import IntegralIdentifier
from .comparison_config import ComparisonConfig

TABLE5_EKF = {"q": TABLE4_Q[3], "m0": TABLE4_M0["a"]}
"""EKF settings of Table 5 (``Q = 1e-2`` and ``m_o`` of case (a), Section 3.6)."""


@dataclass(frozen=True)
class MethodRun:
    """One row of the comparison: a method, its settings, timing and errors.

    Attributes
    ----------
    method : {"integral", "nlr", "ekf", "ekf_length"}
        Which identifier (``ekf_length`` is a Table 5 row).
    label : str
        Row label in the paper's wording, e.g. ``"NLR [5, 5, 5]"``, ``"Case 2(a)"``.
    settings : dict
        Method settings: NLR ``start``, ``max_nfev``; EKF ``q``, ``m0``, ``r``;
        Table 5 ``length_s``.
    params : dict of str to float
        Identified parameters (paper order: damping, gain, offset).
    mae : float
        Mean absolute error of the forward simulation over the whole flight [deg/s].
    p90 : float
        90th percentile of the absolute error [deg/s].
    heldout_mae, heldout_p90 : float or None
        The same errors of the same parameters on the validation flight
        [deg/s]; ``None`` without one.
    cpu_time : float
        Median CPU time of ``fit`` [s] (:func:`time.process_time`).
    wall_time : float
        Median wall time of ``fit`` [s] (:func:`time.perf_counter`).
    cpu_times, wall_times : tuple of float
        Every timed run [s].
    converged : bool or None
        NLR: ``least_squares`` stopped on a tolerance; EKF: did not diverge;
        ``None`` where it does not apply.
    note : str
        Anything a reader should know (cut short, diverged, ...).
    """

    method: str
    label: str
    settings: dict
    params: dict
    mae: float
    p90: float
    cpu_time: float
    wall_time: float
    cpu_times: tuple = ()
    wall_times: tuple = ()
    converged: bool | None = None
    note: str = ""
    heldout_mae: float | None = None
    heldout_p90: float | None = None

    @property
    def repeats(self) -> int:
        """Number of timed runs behind the medians."""
        return len(self.cpu_times)

    def to_dict(self) -> dict:
        return {
            "method": self.method, "label": self.label, "settings": jsonable(self.settings),
            "params": dict(self.params), "mae_deg_s": self.mae, "p90_deg_s": self.p90,
            "cpu_time_s": self.cpu_time, "wall_time_s": self.wall_time, "repeats": self.repeats,
            "cpu_times_s": list(self.cpu_times), "wall_times_s": list(self.wall_times),
            "converged": self.converged, "note": self.note,
            "heldout_mae_deg_s": self.heldout_mae, "heldout_p90_deg_s": self.heldout_p90,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "MethodRun":
        return cls(
            method=d["method"], label=d["label"], settings=dict(d["settings"]),
            params=dict(d["params"]), mae=_float(d["mae_deg_s"]), p90=_float(d["p90_deg_s"]),
            cpu_time=_float(d["cpu_time_s"]), wall_time=_float(d["wall_time_s"]),
            cpu_times=tuple(map(_float, d["cpu_times_s"])), wall_times=tuple(map(_float, d["wall_times_s"])),
            converged=d["converged"], note=d["note"],
            heldout_mae=_optional_float(d.get("heldout_mae_deg_s")),
            heldout_p90=_optional_float(d.get("heldout_p90_deg_s")),
        )


def _nlr_label(start) -> str:
    return f"NLR [{', '.join(f'{v:g}' for v in start)}]"


class MethodRunner:
    """Fits each method on the filtered flight, times it and scores what it identified with one yardstick.

    Parameters
    ----------
    axis : str
    names : tuple of str
        The axis' decoupled parameters (damping, gain, offset).
    data : Flight
        The prefiltered flight every method fits.
    held : Flight or None
        The prefiltered validation flight.
    config : ComparisonConfig
    stage : callable or None
        Told each method's label as it starts.
    """

    def __init__(self, axis: str, names, data: Flight, held: Flight | None, config: ComparisonConfig, stage):
        self.axis, self.names, self.data, self.held = axis, names, data, held
        self.row_index = axis_index(axis)
        self.config = config
        self.stage = stage

    # ---------------------------------------------------------- the yardstick
    def errors(self, params):
        """Forward-simulation errors of ``params`` over the whole flight (in-sample)."""
        return rate_errors(simulate_rate(params, self.data, self.axis), self.data.rates[self.row_index])

    def heldout(self, params):
        """The same errors on the validation flight, or None without one."""
        if self.held is None:
            return None
        return rate_errors(simulate_rate(params, self.held, self.axis), self.held.rates[self.row_index])

    # ---------------------------------------------------------- the methods
    def run(self, progress: bool) -> tuple:
        """Every method in turn: ``(integral, nlr_runs, ekf_runs, length_runs)`` (runs as tuples)."""
        cfg = self.config
        bar = _progress_bar(1 + len(cfg.nlr_starts) + len(cfg.ekf_cases) + len(cfg.sample_lengths), progress)

        def step(label, run, *args):
            bar.set_description(label)
            if self.stage is not None:
                self.stage(label)
            out = run(*args)
            bar.update()
            return out

        try:
            integral = step("integral method", self.integral)
            nlr = tuple(step(_nlr_label(s), self.nlr, s) for s in cfg.nlr_starts)
            ekf = tuple(step(f"EKF {label}", self.ekf, label, q, m0) for label, q, m0 in cfg.ekf_cases)
            lengths = tuple(step(f"EKF on {length:g} s", self.window, k, length)
                            for k, length in enumerate(cfg.sample_lengths, start=1))
        finally:
            bar.close()
        return integral, nlr, ekf, lengths

    def integral(self) -> MethodRun:
        """Table 3's first row: the integral method (Fig. 5) on the prefiltered flight."""
        n = self.config.repeats["integral"]
        structure = {self.row_index: self.names}
        est, cpu, wall = _timed(
            lambda: IntegralIdentifier(structure=structure, axes=(self.axis,), prefilter=False).fit(self.data),
            n, warmup=n > 1)
        return self.row("integral", "Integral method", {"structure": list(self.names), "prefilter": False},
                        est.params_, (cpu, wall))

    def nlr(self, start) -> MethodRun:
        """A Table 3 row: nonlinear regression over forward simulations from ``start`` (eqs. 71-73)."""
        cfg = self.config
        est, cpu, wall = _timed(
            lambda: NonlinearRegression(axis=self.axis, start=start, max_nfev=cfg.nlr_max_nfev).fit(self.data),
            cfg.repeats["nlr"], warmup=False)
        note = ""
        if est.diverged_:
            note = "the final simulation diverged"
        elif not est.converged_:
            note = f"stopped after {est.nfev_} evaluations (max_nfev), not converged"
        return self.row("nlr", _nlr_label(start), {"start": list(start), "max_nfev": cfg.nlr_max_nfev,
                                                   "simulations": est.n_simulations_, "nfev": est.nfev_},
                        est.params_, (cpu, wall), est.converged_, note)

    def ekf(self, label: str, q: float, m0) -> MethodRun:
        """A Table 4 row: the parameter EKF (eqs. 48-64) with ``Q = q`` from ``m0`` over the whole flight."""
        return self._ekf("ekf", label, {"q": q, "m0": list(m0)}, self.data, q, m0)

    def window(self, k: int, length: float) -> MethodRun:
        """Table 5's row ``k``: the EKF of :data:`TABLE5_EKF` on the first ``length`` s of the flight."""
        t0 = float(self.data.time[0])
        window = self.data.segment(t0, t0 + length)
        q, m0 = TABLE5_EKF["q"], TABLE5_EKF["m0"]
        return self._ekf("ekf_length", f"Case {k}", {"length_s": length, "samples": window.n, "q": q,
                                                     "m0": list(m0)}, window, q, m0)

    def _ekf(self, method: str, label: str, settings: dict, data: Flight, q, m0) -> MethodRun:
        n = self.config.repeats["ekf"]
        est, cpu, wall = _timed(lambda: ParameterEKF(axis=self.axis, q=q, m0=m0).fit(data), n, warmup=n > 1)
        return self.row(method, label, {**settings, "r": est.r_}, est.params_, (cpu, wall), not est.diverged_,
                        "the filter diverged; last finite estimate used" if est.diverged_ else "")

    def row(self, method: str, label: str, settings: dict, params, times, converged=None, note="") -> MethodRun:
        """The :class:`MethodRun` of identified ``params``: scored in-sample and held-out, timed by ``times``
        (``(cpu, wall)`` lists of every timed run)."""
        names = self.names
        cpu, wall = times
        model = make_params(names, [params.get(n) for n in names])
        e = self.errors(model)
        h = self.heldout(model)
        return MethodRun(method, label, settings, {n: float(params.get(n)) for n in names}, e.mae, e.p90,
                         statistics.median(cpu), statistics.median(wall), tuple(cpu), tuple(wall), converged, note,
                         heldout_mae=None if h is None else h.mae, heldout_p90=None if h is None else h.p90)


def _timed(fn, repeats: int, warmup: bool):
    """Run ``fn`` ``repeats`` times (after an untimed warm-up); last result and CPU/wall times."""
    if warmup:
        fn()
    cpu, wall = [], []
    result = None
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        result = fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    return result, cpu, wall


@contextlib.contextmanager
def limit_blas(threads):
    """Hold BLAS to ``threads`` threads with threadpoolctl if it is installed; yield what was done."""
    if threads is None:
        yield "not limited"
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        yield "not limited (threadpoolctl not installed)"
        return
    with threadpool_limits(limits=int(threads), user_api="blas"):
        yield int(threads)


def _progress_bar(total: int, enabled: bool):
    """A tqdm bar over the methods on stderr; disabled unless asked for and stderr is a terminal."""
    from tqdm import tqdm

    return tqdm(total=total, unit="method", leave=False, file=sys.stderr,
                disable=not (enabled and sys.stderr.isatty()))


def _float(v) -> float:
    return float("nan") if v is None else float(v)


def _optional_float(v) -> float | None:
    return None if v is None else float(v)
