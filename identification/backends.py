"""Compute backends under their old name: a re-export of :mod:`heli_core.backends`.

Where independent tasks run (this process, a pool of local processes, a Ray
cluster) is infrastructure of the whole package, so it lives in the base layer.
The names users import from here are the same classes and functions. New code
imports from :mod:`heli_core.backends`.
"""

from __future__ import annotations

from heli_core.backends import BACKENDS, Backend, LocalBackend, RayBackend, available_cores, make_backend

__all__ = ["BACKENDS", "Backend", "LocalBackend", "RayBackend", "available_cores", "make_backend"]
