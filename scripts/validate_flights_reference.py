"""What a model's scores on other flights mean: the identified model beside each synthetic flight's own truth.

``heli identify FIT.csv --validate OTHER.csv ...`` scores the identified model on flights it was not fitted on
(fit %, R², 0.5 s-ahead R², CIFER's frequency-response cost J). On windy flights even the true parameters
score a low fit and a J near 100-200, so a number alone says little. This script fits the decoupled
maximum-likelihood model on ``FIT.csv`` as ``heli identify`` does and prints, per flight and axis, the
model's scores beside those of the flight's true parameters (read from the ``<stem>.truth.json`` that
``heli simulate-flight`` writes), each flight prepared as the model prepares it
(:func:`identification.validation.other_flights.as_fitted`). The fitted flight itself is listed first, with its
frequency-response cost only (a fit on it is not a validation).

Usage::

    python scripts/validate_flights_reference.py FIT.csv OTHER.csv [OTHER2.csv ...]

The table of docs/method.md ("Checking a model") comes from
``heli simulate-flight --duration 300 --seed 1 --out a1.csv``, ``--seed 2 --out a2.csv`` and
``--seed 2 --effect servo_delay --effect cross_coupling --out b.csv``, then
``python scripts/validate_flights_reference.py a1.csv a2.csv b.csv`` (13 s on 2 shared cores).
"""

from __future__ import annotations

import argparse
from pathlib import Path


def main(argv=None) -> int:
    from identification.validation.frequency_response import compare_frequency_response
    from identification.io import read_flight
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier
    from identification.bench.synthetic import load_truth
    from identification.validation.forward_simulation import rate_fit_stats, validate_models
    from identification.validation.other_flights import as_fitted, validate_on_flight

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("fit", type=Path, help="the synthetic flight to identify from")
    ap.add_argument("others", type=Path, nargs="+", help="synthetic flights to validate on")
    args = ap.parse_args(argv)

    ident = MaximumLikelihoodIdentifier().fit(read_flight(args.fit))
    own = compare_frequency_response(ident.params_, ident.flights_)
    truth = compare_frequency_response(load_truth(args.fit)[0], ident.flights_)
    print(f"{'flight':12s} {'axis':6s} {'fit %':>7s} {'truth':>7s} {'J':>7s} {'truth J':>8s}")
    for axis in own.axes:
        print(f"{args.fit.name:12s} {axis:6s} {'':>7s} {'':>7s} {own.axes[axis].cost:7.1f} "
              f"{truth.axes[axis].cost:8.1f}")
    for path in args.others:
        flight = read_flight(path)
        params = load_truth(path)[0]
        prepared = as_fitted(ident, flight)
        result = validate_models(prepared, {"truth": params})
        true_fit = rate_fit_stats(result.measured_rates, result.simulated["truth"])
        true_cost = compare_frequency_response(params, prepared).axes
        check = validate_on_flight(ident, flight, "decoupled", path.name)
        for axis in check.axes:
            print(f"{path.name:12s} {axis:6s} {check.fit_pct[axis]:7.1f} {true_fit[axis]['fit_pct']:7.1f} "
                  f"{check.cost[axis]:7.1f} {true_cost[axis].cost:8.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
