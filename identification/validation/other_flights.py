"""The identified model checked on flights it was not fitted on (``heli identify --validate``).

As MATLAB's ``compare``: the model is simulated from each other flight's sticks alone, from the flight's
measured first state (eqs. 18, 21, 31 and the kinematics 25-26, by
:func:`identification.validation.forward_simulation.validate_models`, the same simulation as the fitted flight's
validation), and the simulated rates are scored per axis by the normalised root-mean-square fit and R²
(:func:`identification.validation.forward_simulation.rate_fit_stats`). A flight in gusts holds rate the sticks cannot
explain, so a correct model in strong wind scores low there; the maximum-likelihood model's prediction 0.5 s ahead from
its Kalman-filtered state (:func:`identification.likelihood.ahead_prediction.flight_ahead_r2`) says whether it predicts
the rate when the wind is estimated from the past, as the project's other held-out scores do; and CIFER's
frequency-response cost over the flight's coherent band
(:func:`identification.validation.frequency_response.compare_frequency_response`) whether its dynamics are the flight's
where the sticks drive the rate.

Each flight is prepared as the fit prepared its own (:func:`as_fitted`): the maximum-likelihood fit's input
shifts and vibration-line removal, the integral method's prefilter. Its offset ``kd`` is the model's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from heli_core.files import jsonable
from heli_core.terms import AXES

from ..errors import FlightLogError, SimulationDivergedError
from ..flight import Flight
from .forward_simulation import rate_fit_stats, validate_models
from .result import ValidationResult

MIN_DURATION_S = 5.0
"""The shortest flight validated on [s]: the prediction's filter settles over its first second, and the
0.5 s-ahead prediction needs rate after that."""


@dataclass(eq=False)
class FlightValidation:
    """The model on one flight it was not fitted on.

    Attributes
    ----------
    name : str
        The flight's file name (or ``"flight N"``).
    sha256 : str or None
        The flight file's SHA-256, when read from a file.
    duration_s : float
        [s].
    model : str
        Label of the model validated (``"decoupled"`` or ``"coupled"``).
    fit_pct : dict of str to float
        Per axis, the normalised root-mean-square fit of the simulation [%] (MATLAB's ``compare``); NaN when
        the simulation diverged.
    r2 : dict of str to float
        Per axis, the simulation's R²; NaN when it diverged.
    ahead_r2 : dict of str to float or None
        Per axis, the R² of the prediction 0.5 s ahead (NaN: diverged); None for a model without a wind state
        (the integral method).
    cost : dict of str to float or None
        Per axis, CIFER's frequency-response cost J of the model over the flight's coherent band (NaN: no
        coherent band); None when the flight is too short for the spectra.
    validation : ValidationResult or None
        The simulation against the flight (its figure); None when it diverged.
    diverged : str or None
        Why the simulation diverged (the message of
        :class:`~identification.errors.SimulationDivergedError`), else None.
    path : str or None
        Where the flight file was read (absolute), so that ``heli refresh`` can validate the refreshed model on
        it again; None when not read from a file, or for an entry written before paths were recorded.
    computed_on : dict or None
        None for a result of the model it is stored with; for one carried over from an earlier model (``heli
        refresh`` found the flight file no more), ``{"model_sha256", "reason"}``: which model's numbers they are
        and why they were not computed again.
    """

    name: str
    sha256: str | None
    duration_s: float
    model: str
    fit_pct: dict
    r2: dict
    ahead_r2: dict | None
    cost: dict | None
    validation: ValidationResult | None
    diverged: str | None = None
    path: str | None = None
    computed_on: dict | None = None

    @property
    def axes(self) -> list[str]:
        """The axes scored, in :data:`~heli_core.terms.AXES` order."""
        return list(self.fit_pct)

    def to_dict(self) -> dict:
        """Plain JSON-ready values (non-finite numbers become None; the histories are left out)."""
        return jsonable({"file": self.name, "sha256": self.sha256, "duration_s": self.duration_s,
                         "model": self.model, "fit_pct": self.fit_pct, "r2": self.r2, "ahead_r2": self.ahead_r2,
                         "frequency_response_cost": self.cost, "diverged": self.diverged,
                         **({"path": self.path} if self.path else {}),
                         **({"computed_on": self.computed_on} if self.computed_on else {})})

    @classmethod
    def from_dict(cls, entry: dict, computed_on: dict | None = None) -> "FlightValidation":
        """The result as :meth:`to_dict` stored it (None back to NaN; no simulation, so no figure), with
        ``computed_on`` when it is carried over from another model (an entry's own ``computed_on`` wins: it
        says where the numbers were first computed)."""
        def numbers(values):
            return None if values is None else {a: math.nan if v is None else float(v) for a, v in values.items()}

        return cls(str(entry.get("file")), entry.get("sha256"), float(entry.get("duration_s") or math.nan),
                   str(entry.get("model")), numbers(entry.get("fit_pct")) or {}, numbers(entry.get("r2")) or {},
                   numbers(entry.get("ahead_r2")), numbers(entry.get("frequency_response_cost")), None,
                   entry.get("diverged"), entry.get("path"), entry.get("computed_on") or computed_on)


def check_validation_flights(flights, others, names=None) -> None:
    """Refuse flights that cannot validate a model fitted on ``flights``, before anything is fitted.

    Parameters
    ----------
    flights : sequence of Flight
        The flights the model is fitted on.
    others : sequence of Flight
        The validation flights.
    names : sequence of str, optional
        How to call ``others`` in a message (default their metadata's ``source``).

    Raises
    ------
    FlightLogError
        A validation flight that is one of the fitted flights (same SHA-256, or the same samples), that is
        sampled at another rate (the model's discrete simulation and prediction are those of the fitted rate),
        or that is shorter than :data:`MIN_DURATION_S`.
    """
    fs = flights[0].sample_rate
    names = list(names) if names is not None else [str(o.metadata.get("source", f"flight {i + 1}"))
                                                   for i, o in enumerate(others)]
    for name, other in zip(names, others):
        twin = next((str(f.metadata.get("source", "a fitted flight")) for f in flights if _same_flight(f, other)),
                    None)
        if twin is not None:
            raise FlightLogError(f"--validate {name}: the same flight as {twin}, which the model is fitted on; "
                                 "validation needs a flight the fit did not see")
        if not math.isclose(other.sample_rate, fs, rel_tol=1e-3):
            raise FlightLogError(f"--validate {name}: sampled at {other.sample_rate:g} Hz, the fitted flights at "
                                 f"{fs:g} Hz; expected a flight logged at {fs:g} Hz")
        if other.duration < MIN_DURATION_S:
            raise FlightLogError(f"--validate {name}: lasts {other.duration:.2f} s; expected at least "
                                 f"{MIN_DURATION_S:g} s (the prediction's filter settles over the first second)")


def _same_flight(a: Flight, b: Flight) -> bool:
    sha = a.metadata.get("sha256")
    if sha is not None and sha == b.metadata.get("sha256"):
        return True
    return a.n == b.n and np.array_equal(a.time, b.time) and np.array_equal(a.rates, b.rates) and np.array_equal(
        a.sticks, b.sticks)


def as_fitted(identifier, flight: Flight) -> Flight:
    """``flight`` prepared as ``identifier`` (fitted) prepared the flights it was fitted on: a
    maximum-likelihood fit's sticks advanced by its input shifts and its vibration lines removed, the integral
    method's folded lines removed and its zero-phase prefilter (Section 3.1)."""
    if hasattr(identifier, "wind_torque"):  # the maximum-likelihood estimator
        return identifier._clean(identifier.aligned(flight))[0]
    prepared = getattr(identifier, "prepared", None)  # the integral method's
    return flight if prepared is None else prepared(flight)


def validate_on_flight(identifier, flight: Flight, label: str, name: str | None = None,
                       path: str | None = None) -> FlightValidation:
    """Simulate ``identifier``'s model on ``flight`` (one it was not fitted on) and score it per axis.

    Parameters
    ----------
    identifier : MaximumLikelihoodIdentifier or IntegralIdentifier
        Fitted.
    flight : Flight
        The validation flight, as read (:func:`check_validation_flights` passed).
    label : str
        The model's label (``"decoupled"``, ``"coupled"``).
    name : str, optional
        The flight's name in reports (default its metadata's ``source``).
    path : str, optional
        The flight file's path, recorded for ``heli refresh`` (:attr:`FlightValidation.path`).

    Returns
    -------
    FlightValidation
        A diverging simulation is a result (its ``diverged`` says why), not an error: the model is already
        fitted, and a flight it cannot follow is what the validation is for.
    """
    from ..likelihood.ahead_prediction import flight_ahead_r2

    prepared = as_fitted(identifier, flight)
    axes = [a for a in AXES if a in identifier.axes_]
    name = name or str(flight.metadata.get("source", "flight"))
    sha = flight.metadata.get("sha256")
    ahead = flight_ahead_r2(identifier, prepared) if hasattr(identifier, "wind_torque") else None
    cost = _frequency_cost(identifier.params_, prepared, axes)
    try:
        result = validate_models(prepared, {label: identifier.params_})
    except SimulationDivergedError as e:
        nan = {a: math.nan for a in axes}
        return FlightValidation(name, sha, flight.duration, label, nan, dict(nan), ahead, cost, None, str(e), path)
    stats = rate_fit_stats(result.measured_rates, result.simulated[label])
    return FlightValidation(name, sha, flight.duration, label, {a: stats[a]["fit_pct"] for a in axes},
                            {a: stats[a]["r2"] for a in axes}, ahead, cost, result, path=path)


def _frequency_cost(params, flight: Flight, axes) -> dict | None:
    """Per axis, CIFER's cost J of ``params`` on ``flight``'s coherent band, or None for a flight too short."""
    from ..errors import IdentifiabilityError
    from .frequency_response import compare_frequency_response

    try:
        result = compare_frequency_response(params, flight, axes=axes)
    except IdentifiabilityError:
        return None
    return {a: r.cost for a, r in result.axes.items()}


def validate_on_flights(identifier, flights, label: str, names=None, paths=None) -> list[FlightValidation]:
    """:func:`validate_on_flight` on each of ``flights`` (named by ``names``, read from ``paths``), in order."""
    names = list(names) if names is not None else [None] * len(flights)
    paths = list(paths) if paths is not None else [None] * len(flights)
    return [validate_on_flight(identifier, f, label, n, p) for f, n, p in zip(flights, names, paths)]
