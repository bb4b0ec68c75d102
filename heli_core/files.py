"""Atomic file writing: nothing is ever left half-written.

Every output of the package goes through these helpers: the content is written
to a temporary file in the destination folder, flushed to disk, then moved over
the destination with :func:`os.replace` (atomic on POSIX and Windows). A crash
mid-write leaves the previous file intact and at most a stray ``.tmp`` file.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path, suffix: str = ""):
    """Yield a temporary path beside ``path``; on success move it over ``path``.

    Parameters
    ----------
    path : str or Path
        Final destination. Its folder is created if missing.
    suffix : str
        Suffix for the temporary file (some writers, e.g. matplotlib, choose the
        format from it). Defaults to the destination's suffix.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=(suffix or path.suffix) + ".tmp", dir=path.parent)
    except OSError as err:
        raise _naming(err, path) from err
    os.close(fd)
    tmp_path = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp makes 0600; outputs follow the umask like open() would
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp_path, path)
    except BaseException as err:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        if isinstance(err, OSError) and err.filename == str(tmp_path):
            raise _naming(err, path) from err
        raise


def _naming(err: OSError, path: Path) -> OSError:
    """``err`` (same class and errno) naming ``path``, the file the user asked for, not the temporary beside it.

    A full disk or a folder that refuses new files fails on the temporary file first ("Permission denied",
    "No space left on device"); the user never saw its name.
    """
    return type(err)(err.errno, err.strerror, str(path))


def write_text(path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def keep_copy(path) -> Path:
    """Copy the file at ``path`` to ``history/<stem>-<sha256[:12]><suffix>`` beside it; returns the copy's path.

    The copy is named by the file's content, so keeping the same content twice writes it once; an
    existing copy is left as it is. Outputs about to be replaced go through here, so that nothing the
    user had is lost.
    """
    path = Path(path)
    data = path.read_bytes()
    backup = path.parent / "history" / f"{path.stem}-{hashlib.sha256(data).hexdigest()[:12]}{path.suffix}"
    if not backup.exists():
        write_bytes(backup, data)
    return backup


def save_figure(fig, path, **kwargs) -> Path:
    """Save a matplotlib figure atomically and close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    with atomic_path(path, suffix=path.suffix) as tmp:
        fig.savefig(tmp, format=path.suffix.lstrip(".") or "png", **kwargs)
    plt.close(fig)
    return path


def jsonable(obj):
    """``obj`` ready for :func:`json.dumps` with ``allow_nan=False``.

    Mappings become dicts with string keys, sequences and arrays lists, numpy
    scalars plain Python numbers, and non-finite floats (an undefined standard
    error, say) ``None``: JSON has no NaN.
    """
    import math
    from collections.abc import Mapping

    import numpy as np

    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def sha256_of(path) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()
