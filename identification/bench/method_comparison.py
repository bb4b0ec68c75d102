"""The paper's method comparison on one flight: integral method, NLR and EKF (Tables 3-5).

Section 3.5 times the integral method (Fig. 5) against nonlinear regression
over forward simulations (eqs. 71-73, Table 3); Section 3.6 runs the parameter
EKF (eqs. 48-64) for six settings of ``Q`` and the initial state (Table 4) and
on three lengths of data (Table 5). :func:`compare_methods` reproduces the
three tables on any flight, with every figure measured in the same run:

* **Same data.** The flight is low-pass filtered once (Section 3.1, the 4/8 Hz
  zero-phase FIR of :func:`identification.preprocess.lowpass_flight`) and every
  method identifies the *same* decoupled single-axis model (roll: eq. 18 with
  ``k1 = k4 = 0``, parameters ``k3, k2, kd1``) on that filtered flight. The
  integral method is therefore run with ``prefilter=False``; the shared
  filtering is timed separately and counted in no method.
* **Same yardstick.** Each identified model is forward-simulated over the whole
  flight from the measured initial rate
  (:func:`identification.baselines.simulate_rate`, one physics core) and
  compared with the same filtered measured rate: mean absolute error and 90th
  percentile [deg/s] (:func:`identification.baselines.rate_errors`).
* **Held-out flight.** The in-sample error flatters NLR, which minimises that
  very error: on a windy flight it bends the parameters to absorb the
  unmodelled wind. Pass a second flight as ``validation`` and every identified
  model is also scored on it (prefiltered the same way, the same forward
  simulation, the same MAE / 90th percentile), a flight no method has seen.
  The target verdict then states both comparisons, in-sample and held-out.
* **Same clock.** Each method's ``fit`` call is timed with
  :func:`time.process_time` (CPU) and :func:`time.perf_counter` (wall); fast
  methods are repeated after one untimed warm-up and the median is kept
  (:data:`DEFAULT_REPEATS`: integral 20, EKF 3, NLR 1). The speed ratios
  NLR/integral and EKF/integral are taken between these medians. While timing,
  BLAS is held to ``blas_threads`` threads (default 1) when ``threadpoolctl``
  is installed: process time adds up the CPU of every thread, so a library
  that spins up threads for tiny matrices would otherwise be charged for it.

On a synthetic flight the true parameters are known
(:func:`identification.bench.synthetic.load_truth`); pass them as ``truth`` and the
tables also show each parameter's error and a reference row with the true
parameters simulated the same way (the wind is not modelled by any method, so
its MAE is the floor none of the three can be expected to beat by much).

Each method is fitted, timed and scored by :class:`identification.bench.method_runs.MethodRunner` with the
settings of :class:`~identification.bench.comparison_config.ComparisonConfig`; the result,
:class:`MethodComparison`, is data: ``comparison.md`` is drawn from it by
:mod:`identification.reports.method_comparison` and both files are written by
:func:`identification.workflows.method_comparison.write_comparison`.
"""

from __future__ import annotations

import math
import platform
import time
from dataclasses import dataclass, field, replace

import numpy as np

from heli_core.files import jsonable
from heli_core.params import ModelParams

from ..baselines.single_axis import make_params, parameter_names
from ..errors import FlightLogError, IdentifiabilityError
from ..flight import Flight
from ..preprocess import lowpass_flight
from .comparison_config import ComparisonConfig
from .method_runs import MethodRun, MethodRunner, limit_blas

SCHEMA = "heli-env/method-comparison/2"
"""Schema tag of :meth:`MethodComparison.to_dict` (2: held-out errors on a validation flight)."""

READABLE_SCHEMAS = (SCHEMA, "heli-env/method-comparison/1")
"""Schemas :meth:`MethodComparison.from_dict` reads (version 1 has no held-out errors)."""

SAMPLE_RATE_TOLERANCE = 1e-3
"""Relative difference allowed between the sample rates of the identification
and the validation flight (median sample intervals of logged data jitter)."""


TARGET_SPEEDUP = 1000.0
"""Issue target: the integral method at least this many times faster than NLR (CPU time)."""


# ------------------------------------------------------------------ results
@dataclass(frozen=True)
class MethodComparison:
    """Tables 3, 4 and 5 measured on one flight (see :func:`compare_methods`).

    Attributes
    ----------
    axis : str
        Axis compared (``"roll"`` in the paper).
    param_names : tuple of str
        Identified parameters in the paper's order, e.g. ``("k3", "k2", "kd1")``.
    flight : dict
        Source, SHA-256 (when read from a file), samples, duration [s], sample rate [Hz].
    prefilter : dict
        The shared low-pass filter: band edges [Hz] and its CPU and wall time [s].
    integral : MethodRun
        Table 3, first row.
    nlr : tuple of MethodRun
        Table 3, one row per start point.
    ekf : tuple of MethodRun
        Table 4, one row per case.
    sample_lengths : tuple of MethodRun
        Table 5, one row per identification window.
    truth : dict of str to float or None
        True values of ``param_names`` (synthetic flights).
    truth_errors : dict or None
        ``{"mae_deg_s", "p90_deg_s"}`` of the true parameters simulated the same way.
    settings : dict
        Repeats, NLR evaluation limit, ``quick``, BLAS threading, versions.
    validation : dict or None
        The held-out flight, when one was given: ``flight`` (as ``flight``),
        ``truth`` (true values of ``param_names`` it was flown with, or None) and
        ``truth_errors`` (``{"mae_deg_s", "p90_deg_s"}`` of those true values on
        it, or None). Each run's ``heldout_mae`` / ``heldout_p90`` are on it.
    """

    axis: str
    param_names: tuple
    flight: dict
    prefilter: dict
    integral: MethodRun
    nlr: tuple = ()
    ekf: tuple = ()
    sample_lengths: tuple = ()
    truth: dict | None = None
    truth_errors: dict | None = None
    settings: dict = field(default_factory=dict)
    validation: dict | None = None

    # ---------------------------------------------------------- derived
    def speed_ratios(self) -> dict[str, dict[str, float]]:
        """CPU-time ratios against the integral method, from this run's medians.

        Returns
        -------
        dict
            ``{"nlr": {label: ratio}, "ekf": {label: ratio}}``; a ratio of 1000
            means the method took 1000 times the integral method's CPU time.
        """
        base = self.integral.cpu_time

        def ratio(run):
            return run.cpu_time / base if base > 0 else float("inf")

        return {"nlr": {r.label: ratio(r) for r in self.nlr}, "ekf": {r.label: ratio(r) for r in self.ekf}}

    def param_errors(self, run: MethodRun) -> dict[str, float] | None:
        """Relative error of each identified parameter against the truth [%], or None without truth."""
        if not self.truth:
            return None
        out = {}
        for name in self.param_names:
            t = self.truth.get(name)
            v = run.params.get(name, float("nan"))
            out[name] = 100.0 * (v - t) / abs(t) if t else float("nan")
        return out

    def target(self) -> dict:
        """The issue's target against the NLR run from eq. (73)'s start (the paper's 710x row).

        The target is "integral at least :data:`TARGET_SPEEDUP` times faster than
        NLR at equal or better MAE". It is judged twice and both verdicts are
        reported: on the identification flight itself (in-sample, where NLR
        minimises the very error it is scored by) and on the validation flight
        (held-out), when one was given.

        Returns
        -------
        dict
            ``nlr_label``, ``speedup`` (NLR CPU time / integral CPU time), ``faster``
            (speedup >= :data:`TARGET_SPEEDUP`);
            in-sample: ``mae_integral``, ``mae_nlr``, ``mae_ratio`` (integral / NLR),
            ``mae_change_pct`` (integral relative to NLR), ``as_accurate``
            (integral MAE <= NLR MAE), ``met`` (``faster`` and ``as_accurate``) and
            ``mae_truth`` (MAE of the true parameters, None without truth);
            held-out (all None without a validation flight): ``heldout_mae_integral``,
            ``heldout_mae_nlr``, ``heldout_mae_ratio``, ``heldout_mae_change_pct``,
            ``heldout_as_accurate``, ``met_heldout`` and ``heldout_mae_truth``.
            Empty without NLR rows.
        """
        if not self.nlr:
            return {}
        ref = self.nlr[0]
        speedup = self.speed_ratios()["nlr"][ref.label]
        faster = speedup >= TARGET_SPEEDUP
        ratio, change = _mae_ratio(self.integral.mae, ref.mae)
        accurate = self.integral.mae <= ref.mae
        out = {"nlr_label": ref.label, "speedup": speedup, "faster": faster,
               "mae_integral": self.integral.mae, "mae_nlr": ref.mae, "mae_ratio": ratio,
               "mae_change_pct": change, "as_accurate": accurate, "met": faster and accurate,
               "mae_truth": self.truth_errors["mae_deg_s"] if self.truth_errors else None,
               "heldout_mae_integral": None, "heldout_mae_nlr": None, "heldout_mae_ratio": None,
               "heldout_mae_change_pct": None, "heldout_as_accurate": None, "met_heldout": None,
               "heldout_mae_truth": None}
        if self.validation is not None and self.integral.heldout_mae is not None and ref.heldout_mae is not None:
            h_ratio, h_change = _mae_ratio(self.integral.heldout_mae, ref.heldout_mae)
            h_accurate = self.integral.heldout_mae <= ref.heldout_mae
            v_truth = self.validation.get("truth_errors")
            out.update({"heldout_mae_integral": self.integral.heldout_mae, "heldout_mae_nlr": ref.heldout_mae,
                        "heldout_mae_ratio": h_ratio, "heldout_mae_change_pct": h_change,
                        "heldout_as_accurate": h_accurate, "met_heldout": faster and h_accurate,
                        "heldout_mae_truth": v_truth["mae_deg_s"] if v_truth else None})
        return out

    # ---------------------------------------------------------- serialisation
    def to_dict(self) -> dict:
        """JSON-ready dictionary (non-finite floats become ``None``); inverse of :meth:`from_dict`."""
        return jsonable({
            "schema": SCHEMA,
            "axis": self.axis,
            "param_names": list(self.param_names),
            "flight": self.flight,
            "prefilter": self.prefilter,
            "settings": self.settings,
            "truth": self.truth,
            "truth_errors": self.truth_errors,
            "integral": self.integral.to_dict(),
            "nlr": [r.to_dict() for r in self.nlr],
            "ekf": [r.to_dict() for r in self.ekf],
            "sample_lengths": [r.to_dict() for r in self.sample_lengths],
            "validation": self.validation,
            "speed_ratios": self.speed_ratios(),
            "target": self.target(),
        })

    @classmethod
    def from_dict(cls, d: dict) -> "MethodComparison":
        """Rebuild a comparison from :meth:`to_dict` output (e.g. a loaded ``comparison.json``)."""
        if d.get("schema") not in READABLE_SCHEMAS:
            raise ValueError(f"expected a method comparison of schema {SCHEMA!r}, got {d.get('schema')!r}")
        return cls(
            axis=d["axis"], param_names=tuple(d["param_names"]), flight=dict(d["flight"]),
            prefilter=dict(d["prefilter"]), integral=MethodRun.from_dict(d["integral"]),
            nlr=tuple(MethodRun.from_dict(r) for r in d["nlr"]),
            ekf=tuple(MethodRun.from_dict(r) for r in d["ekf"]),
            sample_lengths=tuple(MethodRun.from_dict(r) for r in d["sample_lengths"]),
            truth=d["truth"], truth_errors=d["truth_errors"],
            settings=dict(d["settings"]), validation=d.get("validation"),
        )


# ------------------------------------------------------------------ running
def compare_methods(flight: Flight, axis: str = "roll", *, config: ComparisonConfig | None = None,
                    truth: ModelParams | None = None, validation: Flight | None = None,
                    validation_truth: ModelParams | None = None, progress: bool = True, stage=None,
                    **settings) -> MethodComparison:
    """Run the integral method, NLR and the EKF on one flight and tabulate them (Tables 3-5).

    With ``validation``, every identified model is also scored on that second
    flight (held-out): prefiltered the same way, forward-simulated the same
    way, the same MAE and 90th percentile. No method sees it while fitting, and
    its evaluation is outside every timing.

    Parameters
    ----------
    flight : Flight
        The measured flight (rates [rad/s], sticks); filtered here once unless
        ``prefilter=False``.
    axis : {"roll", "pitch", "yaw"}
        Axis whose decoupled model is identified (paper: roll).
    config : ComparisonConfig, optional
        The methods' settings and the timing; default :class:`ComparisonConfig`'s.
    truth : ModelParams, optional
        True parameters of a synthetic flight: adds parameter errors and a reference row.
    validation : Flight, optional
        A second flight of the same aircraft, at the same sample rate, for the
        held-out errors (``MethodRun.heldout_mae`` / ``heldout_p90``).
    validation_truth : ModelParams, optional
        True parameters the validation flight was flown with (a synthetic
        flight): adds the held-out errors of the reference row. Needs ``validation``.
    progress : bool
        Show a tqdm progress bar over the methods (only when stderr is a terminal).
    stage : callable, optional
        Called with each method's label as it starts (e.g. one line per method in a log).
    **settings
        Fields of :class:`ComparisonConfig` (``nlr_starts``, ``ekf_cases``,
        ``sample_lengths``, ``repeats``, ``nlr_max_nfev``, ``prefilter``,
        ``pass_hz``, ``stop_hz``, ``blas_threads``, ``quick``), replacing those of ``config``.

    Returns
    -------
    MethodComparison

    Raises
    ------
    IdentifiabilityError
        A Table 5 window is longer than the flight, or the integral method
        cannot identify the axis.
    FlightLogError
        The validation flight has another sample rate than the flight, or is
        the flight itself.
    ValueError
        Unknown axis, bad start points, EKF settings or repeat counts.
    """
    names = parameter_names(axis)
    config = ComparisonConfig(**settings) if config is None else replace(config, **settings)
    _check_flights(flight, config, validation, validation_truth)
    with limit_blas(config.blas_threads) as threads:
        data, pre = _prefiltered(flight, config)
        held = None
        if validation is not None:  # filtered outside every timing, as the flight itself
            held = lowpass_flight(validation, config.pass_hz, config.stop_hz) if config.prefilter else validation
        runner = MethodRunner(axis, names, data, held, config, stage)
        integral, nlr_runs, ekf_runs, length_runs = runner.run(progress)

    truth_values, truth_errors = _reference(truth, names, runner.errors)
    validation_info = None
    if validation is not None:
        v_truth, v_errors = _reference(validation_truth, names, runner.heldout)
        validation_info = {"flight": _flight_info(validation), "truth": v_truth, "truth_errors": v_errors}
    recorded = {"repeats": config.repeats, "nlr_max_nfev": config.nlr_max_nfev, "quick": bool(config.quick),
                "blas_threads": threads, "clock": "time.process_time (CPU), time.perf_counter (wall); medians",
                "python": platform.python_version(), "numpy": np.__version__, "machine": platform.machine()}
    return MethodComparison(axis, tuple(names), _flight_info(flight), pre, integral, nlr_runs, ekf_runs,
                            length_runs, truth_values, truth_errors, recorded, validation=validation_info)


def _prefiltered(flight: Flight, config: ComparisonConfig) -> tuple[Flight, dict]:
    """The flight low-pass filtered once for every method (Section 3.1), and the filter's record and time."""
    c0, w0 = time.process_time(), time.perf_counter()
    data = lowpass_flight(flight, config.pass_hz, config.stop_hz) if config.prefilter else flight
    pre = {"applied": bool(config.prefilter), "pass_hz": config.pass_hz, "stop_hz": config.stop_hz,
           "cpu_time_s": time.process_time() - c0 if config.prefilter else 0.0,
           "wall_time_s": time.perf_counter() - w0 if config.prefilter else 0.0}
    return data, pre


def _reference(params: ModelParams | None, names, score) -> tuple[dict | None, dict | None]:
    """The true values of ``names`` and their errors by ``score`` (``{"mae_deg_s", "p90_deg_s"}``), or Nones."""
    if params is None:
        return None, None
    values = {n: float(params.get(n)) for n in names}
    e = score(make_params(names, [values[n] for n in names]))
    return values, {"mae_deg_s": e.mae, "p90_deg_s": e.p90}


def _flight_info(flight: Flight) -> dict:
    meta = flight.metadata
    return {"source": str(meta.get("source", "in memory")), "sha256": meta.get("sha256"),
            "samples": int(flight.n), "duration_s": float(flight.duration),
            "sample_rate_hz": float(flight.sample_rate)}


def _check_flights(flight: Flight, config: ComparisonConfig, validation, validation_truth) -> None:
    """Table 5's windows must fit the flight; a validation flight, when given, must be another flight at
    the same sample rate, and its truth needs it."""
    for length in config.sample_lengths:
        if not 0.0 < length <= flight.duration + 1e-9:
            raise IdentifiabilityError(
                f"Table 5 window of {length:g} s does not fit the flight of {flight.duration:.2f} s; "
                f"pass sample_lengths within (0, {flight.duration:.2f}] s"
            )
    if validation is not None:
        _check_validation(flight, validation)
    elif validation_truth is not None:
        raise ValueError("validation_truth is the truth of a validation flight; pass validation too")


def _check_validation(flight: Flight, validation: Flight) -> None:
    """The validation flight must be another flight at the same sample rate."""
    if not isinstance(validation, Flight):
        raise TypeError(f"validation must be a Flight, got {type(validation).__name__}")
    fs, vs = float(flight.sample_rate), float(validation.sample_rate)
    if not math.isclose(fs, vs, rel_tol=SAMPLE_RATE_TOLERANCE):
        raise FlightLogError(
            f"the validation flight ({validation.metadata.get('source', 'in memory')}) is sampled at {vs:g} Hz, "
            f"the identification flight at {fs:g} Hz; the held-out errors need the same sample rate "
            "(the same prefilter and simulation step): resample it or pick a flight logged at "
            f"{fs:g} Hz")
    sha = flight.metadata.get("sha256")
    same = (sha is not None and sha == validation.metadata.get("sha256")) or (
        flight.n == validation.n and np.array_equal(flight.time, validation.time)
        and np.array_equal(flight.rates, validation.rates) and np.array_equal(flight.sticks, validation.sticks))
    if same:
        raise FlightLogError("the validation flight is the identification flight itself; held-out errors need a "
                             "flight the methods did not see")


# ------------------------------------------------------------------ numbers
def _mae_ratio(mae_integral: float, mae_nlr: float) -> tuple[float, float]:
    """``(integral / NLR, 100 * (integral - NLR) / NLR)``; NaN when NLR's MAE is 0."""
    if not mae_nlr > 0:
        return float("nan"), float("nan")
    return mae_integral / mae_nlr, 100.0 * (mae_integral - mae_nlr) / mae_nlr
