"""Fault injection: stop a writer after its N-th file event, as a crash would.

Every file event of a model-directory write (a file written, moved or deleted by
:class:`model_store.ModelDir`'s transaction, its recovery, or the disturbance
library) calls :func:`event`. Armed, the N-th event stops the process there:

* ``HELI_FAULT_AFTER=N`` in the environment: the process kills itself with
  SIGKILL right after its N-th event (``HELI_FAULT_MODE=raise`` raises
  :class:`InjectedFault` instead). What the fault-injection script uses on real
  ``heli`` commands.
* :func:`arm` in the same process (tests): raises :class:`InjectedFault`, a
  ``BaseException`` the transaction lets through without cleaning up, so the
  folder is left exactly as a kill would leave it.

Unarmed, :func:`event` only counts (:func:`count`), so a test can learn how many
events a complete write has.
"""

from __future__ import annotations

import os
import signal

ENV_AFTER = "HELI_FAULT_AFTER"
ENV_MODE = "HELI_FAULT_MODE"

_count = 0
_armed: int | None = None


class InjectedFault(BaseException):
    """Raised at the armed file event: the simulated crash (a ``BaseException``, like ``KeyboardInterrupt``)."""


def arm(after: int | None) -> None:
    """Stop at the ``after``-th file event from now (raising :class:`InjectedFault`); None disarms."""
    global _armed, _count
    _count = 0
    _armed = None if after is None else int(after)


def count() -> int:
    """File events since the last :func:`arm` (or since the process started)."""
    return _count


def event(what: str) -> None:
    """Count a file event (``what`` says which); stop here if this is the armed one."""
    global _count
    _count += 1
    after, mode = _armed, "raise"
    if after is None and os.environ.get(ENV_AFTER):
        after, mode = int(os.environ[ENV_AFTER]), os.environ.get(ENV_MODE, "kill")
    if after is not None and _count >= after:
        if mode == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        raise InjectedFault(f"fault injected after file event {_count}: {what}")
