"""The closed-loop checks in the order they build on each other, for
:meth:`~identification.likelihood.estimator.MaximumLikelihoodIdentifier.closed_loop_check`:

1. a servo delay the search found is tested in the delay-free loop (:mod:`.delay_check`): a delay that loop makes
   too is the loop's, and removed (a delay that stands is flown by step 2 through the servo); a delay or lag within
   :func:`~.delay_check.loop_timing` of a flight controller's loop faster than its log is the loop's, and removed
   likewise;
2. the bias of each axis is measured in its loop (:mod:`.closed_loop`);
3. where a bias the loop's way was found, the log's hold is decided again in the loop's world
   (:mod:`.hold_check`), and when it changes, step 2 runs again at the new hold.

In mode "report" every step measures and none changes the fit.
"""

from __future__ import annotations

import time
from dataclasses import replace

from .closed_loop import CLOSED_LOOP_MODES, ClosedLoopCheck, check_closed_loop, check_settings
from .delay_check import check_delay, delay_candidates, remove_delay
from .hold_check import decide_hold_in_loop, needs_hold_check, switch_hold


def run_checks(ident, mode: str, n_flights: int, min_lr_delay: float, workers=None) -> ClosedLoopCheck:
    """The three steps of the module docstring on the fitted estimator ``ident`` (changed in mode "auto" where
    a delay is the loop's or the hold's world says so; the biases themselves are applied by the caller with
    :func:`~identification.likelihood.closed_loop.apply_check`). ``min_lr_delay`` is the likelihood ratio at
    which the estimator keeps a delay.

    Raises
    ------
    ValueError
        ``mode`` not in :data:`~identification.likelihood.closed_loop.CLOSED_LOOP_MODES` or ``n_flights`` below 2.
    """
    if mode is None:
        raise ValueError(f"closed_loop must be one of {CLOSED_LOOP_MODES} to run the check, got None")
    check_settings(mode, n_flights)
    t0 = time.perf_counter()
    delays = {axis: check_delay(ident, axis, min_lr_delay, workers=workers) for axis in delay_candidates(ident)}
    if mode == "auto":
        delays = {axis: remove_delay(ident, tested) for axis, tested in delays.items()}
    check = check_closed_loop(ident, n_flights, mode=mode, workers=workers)
    if not needs_hold_check(ident, check):
        hold = decide_hold_in_loop(ident, check, n_flights, workers=workers)
        if hold.switched and mode == "auto":
            hold = switch_hold(ident, hold)
            check = check_closed_loop(ident, n_flights, mode=mode, workers=workers)
        check = replace(check, hold=hold)
    return replace(check, delays=delays, time=time.perf_counter() - t0)
