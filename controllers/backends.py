"""Compute backends for sweeps and RL seeds: :mod:`heli_core.backends`, re-exported here.

The backends are defined in :mod:`heli_core`, the base layer, because
identifying many flights uses them too. This module only gives the controllers'
users the name the package layout promises::

    from controllers.backends import LocalBackend, RayBackend
    sweep_gains(None, kp, kd, backend=LocalBackend(workers=2))
"""

from heli_core.backends import BACKENDS, Backend, LocalBackend, RayBackend, available_cores, make_backend

__all__ = ["BACKENDS", "Backend", "LocalBackend", "RayBackend", "available_cores", "make_backend"]
