"""Atomic file writing under its old name: a re-export of :mod:`heli_core.files`.

Every output of the package is written to a temporary file, flushed and moved
over the destination. The helpers live in the base layer; the names users
import from here are the same functions. New code imports from :mod:`heli_core.files`.
"""

from __future__ import annotations

from heli_core.files import atomic_path, jsonable, keep_copy, save_figure, sha256_of, write_bytes, write_text

__all__ = ["atomic_path", "jsonable", "keep_copy", "save_figure", "sha256_of", "write_bytes", "write_text"]
