"""Many flights at once: one task per flight on a backend (this machine's cores or a Ray cluster).

A season of flights is identified flight by flight wherever the flights are
independent of each other:

* :func:`identify_each` fits the integral method (Fig. 5) to each flight *alone*
  (the per-flight parameters, e.g. to look for drift between flights);
* :func:`disturbances_of` identifies each flight's wind (eqs. 41-47) with one
  set of intrinsic parameters, the step :func:`identification.workflows.identify.identify_and_report`
  repeats for every flight it appends to the disturbance library.

A fit that *pools* flights (eq. 35 over the intervals of all of them) is one
least-squares problem and stays one task, in the caller's process.

Each flight is the item of its own task, so it moves to a worker once; what every
task shares (the parameters, the settings) is the backend's shared data, put in
Ray's object store once. Every task is a pure function of its flight and the
shared data, so the results are the same, bit for bit, on every backend and
worker count (the tests check it), and a task rerun after a dead worker gives the
result it would have given. Backends: :mod:`heli_core.backends`.
"""

from __future__ import annotations

from heli_core.backends import make_backend

from ..flight import Flight


def _flights(flights) -> list:
    flights = [flights] if isinstance(flights, Flight) else list(flights)
    if not flights:
        raise ValueError("no flights given")
    for i, f in enumerate(flights):
        if not isinstance(f, Flight):
            raise TypeError(f"flight #{i} is a {type(f).__name__}, expected a Flight (read it with "
                            "identification.io.read_flight)")
    return flights


def _map(backend, fn, items, shared, progress, desc):
    be = make_backend(backend)
    try:
        return be.map(fn, items, shared, progress=progress, desc=desc)
    finally:
        if be is not backend:  # made here from a name: release it
            be.close()


def _identify_task(flight, shared):
    from ..integral.method import IntegralIdentifier

    return IntegralIdentifier(**shared).fit(flight)


def identify_each(flights, backend=None, progress: bool = False, **identifier_kwargs) -> list:
    """Identify each flight alone with the integral method, one task per flight.

    Parameters
    ----------
    flights : Flight or sequence of Flight
    backend : None, {"local", "ray"} or Backend
        Where the tasks run (:func:`heli_core.backends.make_backend`; None: the
        local cores).
    progress : bool
        Progress bar of finished flights.
    **identifier_kwargs
        :class:`~identification.integral.method.IntegralIdentifier` settings
        (``structure``, ``interval``, ``delay``, ...), the same for every flight.

    Returns
    -------
    list of IntegralIdentifier
        Fitted, in the order of ``flights``.

    Raises
    ------
    IdentifiabilityError, FlightLogError
        As :meth:`IntegralIdentifier.fit` on the first flight that fails.
    """
    return _map(backend, _identify_task, _flights(flights), dict(identifier_kwargs), progress, "identify flights")


def _disturbance_task(item, shared):
    from ..disturbance.equivalent_input import identify_disturbance

    params, kwargs = shared
    flight, wind = item
    return identify_disturbance(flight, params, wind_torque=wind, **kwargs)


def disturbances_of(flights, params, backend=None, progress: bool = False, wind_torques=None,
                    **disturbance_kwargs) -> list:
    """Each flight's wind disturbance (eqs. 41-47) with fixed intrinsic parameters, one task per flight.

    Parameters
    ----------
    flights : Flight or sequence of Flight
    params : ModelParams
        Identified intrinsic parameters, shared by every task.
    backend : None, {"local", "ray"} or Backend
        Where the tasks run (None: the local cores).
    progress : bool
        Progress bar of finished flights.
    wind_torques : sequence of ndarray (3, n), optional
        Per flight, the smoother's wind torque to store as the trace (the
        ``wind_torque`` of :func:`~identification.disturbance.equivalent_input.identify_disturbance`).
    **disturbance_kwargs
        :func:`~identification.disturbance.equivalent_input.identify_disturbance` settings (``interval``,
        ``smoothing``, ``simulate``, ...).

    Returns
    -------
    list of DisturbanceProfile
        In the order of ``flights``.
    """
    flights = _flights(flights)
    winds = [None] * len(flights) if wind_torques is None else list(wind_torques)
    if len(winds) != len(flights):
        raise ValueError(f"wind_torques holds {len(winds)} traces for {len(flights)} flights")
    return _map(backend, _disturbance_task, list(zip(flights, winds)), (params, dict(disturbance_kwargs)),
                progress, "disturbance profiles")
