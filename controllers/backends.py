"""Compute backends for sweeps and RL seeds: :mod:`identification.backends`, re-exported here.

The backends are defined in :mod:`identification`, the lowest layer, because
identifying many flights uses them and ``identification`` never imports
``controllers``. This module only gives the controllers' users the name the
package layout promises::

    from controllers.backends import LocalBackend, RayBackend
    sweep_gains(None, kp, kd, backend=LocalBackend(workers=2))
"""

from identification.backends import BACKENDS, Backend, LocalBackend, RayBackend, available_cores, make_backend

__all__ = ["BACKENDS", "Backend", "LocalBackend", "RayBackend", "available_cores", "make_backend"]
