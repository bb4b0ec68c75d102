"""The disturbance library: identified wind traces on disk, versioned, for the environment to replay.

Each flight identified with :func:`identification.disturbance.equivalent_input.identify_disturbance`
contributes one *trace*: the equivalent wind inputs u_d of eq. (42) on roll,
pitch and yaw (zero-mean, stick units) and the collective the yaw model needs
(``-k12*col`` in eq. 21), at the flight's sample rate. Several flights append
to one library; the environment replays its traces through the physics core
as the disturbance torque ``k*u_d`` (the offsets ``kd`` belong to the model).

The format on disk — the folder's layout, the trace files, the manifest's fields and what reading checks — is
specified in ``docs/file-formats.md`` ("The disturbance library"). Guarantees: every file is written through
:func:`heli_core.files.atomic_path` (temporary file, fsync, atomic rename), trace files first and the new manifest
last, so a crash leaves every earlier version readable; appending never rewrites a manifest (the next version is
written beside, under an advisory lock); reading checks everything and raises
:class:`~model_store.errors.LibraryError` naming the file, what was expected and what came.

One concept, the library and the trace it keeps (:class:`Trace`, its checks and its file's bytes): the trace is
kept here rather than in a module of its own because a trace module would sit between the library and the
store's errors and lengthen every import chain through the model folder by one (``scripts/structure_report.py``).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import io
import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

import model_store.faults as faults
from heli_core.files import atomic_path, jsonable, sha256_of, write_text
from heli_core.sampling import is_uniform
from heli_core.terms import AXES

from .errors import LibraryError

LIBRARY_DIRNAME = "disturbances"
TRACES_DIRNAME = "traces"
SCHEMA = "heli-env/disturbance-library"
SCHEMA_VERSION = 1
COLUMNS = ("time", "ud_roll", "ud_pitch", "ud_yaw", "collective")
UNITS = {"time": "s", "ud_roll": "stick (lateral cyclic)", "ud_pitch": "stick (longitudinal cyclic)",
         "ud_yaw": "stick (pedal)", "collective": "stick [-1, 1]"}
SAMPLE_RATE_RTOL = 1e-6
"""Relative tolerance between a trace's measured sample rate and its manifest's."""

_MANIFEST_RE = re.compile(r"^manifest-v(\d{4,})\.json$")
_TRACE_FILE_RE = re.compile(r"^traces/[0-9a-f]{64}\.npy$")
_RESERVED = ("id", "file", "sha256", "n_samples", "sample_rate_hz", "duration_s", "added_in_version")
_REQUIRED = ("file", "sha256", "n_samples", "sample_rate_hz")


def manifest_name(version: int) -> str:
    """File name of a manifest version, e.g. ``manifest-v0003.json``."""
    return f"manifest-v{int(version):04d}.json"


def _heli_version() -> str:
    try:
        from importlib.metadata import version

        return version("heli-env")
    except Exception:  # pragma: no cover - not installed
        return "unknown"


# ---------------------------------------------------------------------- traces
@dataclass(frozen=True, eq=False)
class Trace:
    """One disturbance trace: u_d on roll, pitch, yaw and the collective, at one sample rate.

    Attributes
    ----------
    time : ndarray, shape (n,)
        Sample times [s], uniformly spaced.
    ud : ndarray, shape (3, n)
        Equivalent wind inputs u_d of roll, pitch, yaw, eq. (42) [stick units].
    collective : ndarray, shape (n,)
        Collective stick recorded with the trace [-1, 1].
    metadata : mapping
        For a trace read from a library, its manifest entry; for a new trace,
        what the manifest should record about it (``source``, ``interval_s``,
        ``smoothing``, ``kd``, ``control_gains``, ``model``, ...).
    """

    time: np.ndarray
    ud: np.ndarray
    collective: np.ndarray
    metadata: Mapping = field(default_factory=lambda: MappingProxyType({}))

    def __post_init__(self):
        time = np.array(self.time, dtype=float)
        ud = np.array(self.ud, dtype=float)
        col = np.array(self.collective, dtype=float)
        n = time.size
        if time.ndim != 1 or n < 2:
            raise LibraryError(f"trace time must be 1-D with at least 2 samples, got shape {time.shape}")
        if ud.shape != (3, n):
            raise LibraryError(f"trace ud must have shape (3, {n}) (roll, pitch, yaw by sample), got {ud.shape}")
        if col.shape != (n,):
            raise LibraryError(f"trace collective must have shape ({n},), got {col.shape}")
        for name, a in (("time", time), ("ud", ud), ("collective", col)):
            if not np.all(np.isfinite(a)):
                raise LibraryError(f"trace {name} has {int(np.sum(~np.isfinite(a)))} non-finite values")
        if not is_uniform(time):
            dt = np.diff(time)
            raise LibraryError(
                f"trace time must be uniformly sampled; steps range {dt.min():.6g}..{dt.max():.6g} s"
            )
        for a in (time, ud, col):
            a.setflags(write=False)
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "ud", ud)
        object.__setattr__(self, "collective", col)
        object.__setattr__(self, "metadata", MappingProxyType(dict(self.metadata)))

    @property
    def n(self) -> int:
        """Number of samples."""
        return self.time.size

    @property
    def sample_rate(self) -> float:
        """Sample rate [Hz]."""
        return _sample_rate(self.time)

    @property
    def duration(self) -> float:
        """Time span [s]."""
        return float(self.time[-1] - self.time[0])

    def to_array(self) -> np.ndarray:
        """The stored array, shape (5, n): rows :data:`COLUMNS`."""
        return np.ascontiguousarray(np.vstack([self.time, self.ud, self.collective]), dtype="<f8")

    def to_bytes(self) -> bytes:
        """The trace file's bytes (``.npy``, deterministic)."""
        buf = io.BytesIO()
        np.save(buf, self.to_array(), allow_pickle=False)
        return buf.getvalue()

    @classmethod
    def from_profile(cls, profile, **metadata) -> "Trace":
        """The trace of a :class:`~identification.disturbance.profile.DisturbanceProfile`, with its metadata.

        Keyword arguments are recorded under the entry's ``metadata``. The profile is read by its attributes
        (the store imports nothing of ``identification``); its ``smoothing_window`` names the smoother's
        window (eq. 46).
        """
        p = profile
        params = p.params
        ident = {
            a: {k: p.statistics[a][k] for k in ("auto_passes", "ks_statistic", "ks_pvalue", "stick_interval90",
                                                 "ud_raw_std")}
            for a in p.axes
        }
        values = params.values()
        meta = {
            "source": dict(p.source),
            "interval_s": float(p.interval),
            "samples_per_interval": int(p.samples_per_interval),
            "smoothing": {"mode": "auto" if p.smoothing == "auto" else "fixed", "window": int(profile.smoothing_window),
                          "passes": {a: int(p.passes[AXES.index(a)]) for a in p.axes}},
            "prefilter": p.prefilter,
            "kd": {a: float(p.kd[AXES.index(a)]) for a in p.axes},
            "control_gains": {a: float(p.control_gains[AXES.index(a)]) for a in p.axes},
            "model": {
                "sha256": None,
                "parameters": {k: v for k, v in values.items() if k not in dict(params.extra)},
                "added_terms": dict(params.extra),
                "servo_delay_s": {a: params.taus[i] for i, a in enumerate(AXES)},
                **({"servo_lag_s": {a: params.lags[i] for i, a in enumerate(AXES)}} if any(params.lags) else {}),
            },
            "axes": list(p.axes),
            "trace_source": p.trace_source,
            "identification": ident,
        }
        draw = getattr(p, "trace_draw", None)
        if draw is not None:  # a posterior draw: how it was drawn, and the spread of the mean it was drawn about
            mean = np.asarray(p.trace_mean)
            meta["trace_draw"] = dict(draw)
            meta["mean_std"] = {a: float(mean[AXES.index(a)].std()) for a in p.axes}
        if metadata:
            meta["metadata"] = dict(metadata)
        return cls(p.time, p.trace, p.collective, meta)


def _sample_rate(time: np.ndarray) -> float:
    return float(1.0 / np.median(np.diff(time)))


def _statistics(trace: Trace) -> dict:
    lo, hi = np.percentile(trace.ud, [5.0, 95.0], axis=1)
    return {a: {"mean": float(trace.ud[i].mean()), "std": float(trace.ud[i].std()),
                "interval90": [float(lo[i]), float(hi[i])]} for i, a in enumerate(AXES)}


# --------------------------------------------------------------------- library
class DisturbanceLibrary:
    """A versioned on-disk library of disturbance traces (format in the module docstring).

    Use :meth:`create` for a new library and :meth:`open` for an existing one.

    Attributes
    ----------
    root : Path
        The folder given (``DIR``).
    path : Path
        The library folder, ``DIR/disturbances``.
    """

    def __init__(self, root):
        self.root = Path(root)
        self.path = self.root / LIBRARY_DIRNAME

    def __repr__(self) -> str:
        return f"DisturbanceLibrary({str(self.root)!r}, versions={self.versions()})"

    # -------------------------------------------------------------- opening
    @classmethod
    def create(cls, root) -> "DisturbanceLibrary":
        """Make an empty library in ``root/disturbances``.

        Raises
        ------
        LibraryError
            A library with at least one version is already there (open it and
            append instead: nothing is ever overwritten).
        """
        lib = cls(root)
        if lib.path.is_dir() and lib.versions():
            raise LibraryError(
                f"{lib.path} already holds a disturbance library (versions {lib.versions()}); "
                "open it with DisturbanceLibrary.open and append: an existing library is never overwritten"
            )
        (lib.path / TRACES_DIRNAME).mkdir(parents=True, exist_ok=True)
        return lib

    @classmethod
    def open(cls, root, create: bool = False) -> "DisturbanceLibrary":
        """Open the library in ``root/disturbances`` (with ``create=True``, make it if missing).

        Raises
        ------
        LibraryError
            No library folder there (and ``create`` is false).
        """
        lib = cls(root)
        if not lib.path.is_dir():
            if create:
                return cls.create(root)
            raise LibraryError(
                f"no disturbance library at {lib.path}: expected a folder with manifest-vNNNN.json files "
                "(make one with DisturbanceLibrary.create or 'heli identify --out DIR')"
            )
        return lib

    # -------------------------------------------------------------- reading
    def versions(self) -> list[int]:
        """Versions present, ascending (from the manifest file names)."""
        if not self.path.is_dir():
            return []
        out = []
        for p in self.path.iterdir():
            m = _MANIFEST_RE.match(p.name)
            if m:
                out.append(int(m.group(1)))
        return sorted(out)

    @property
    def latest_version(self) -> int | None:
        """Highest version, or None for an empty library."""
        v = self.versions()
        return v[-1] if v else None

    def _resolve(self, version) -> int:
        versions = self.versions()
        if not versions:
            raise LibraryError(f"the disturbance library at {self.path} is empty: no manifest-vNNNN.json yet")
        if version is None:
            return versions[-1]
        if int(version) not in versions:
            raise LibraryError(f"{self.path} has no version {version}; versions present: {versions}")
        return int(version)

    def manifest(self, version: int | None = None) -> dict:
        """The checked manifest document of ``version`` (latest by default)."""
        version = self._resolve(version)
        path = self.path / manifest_name(version)
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise LibraryError(f"{path}: expected a JSON manifest, could not read it: {e}") from e
        if not isinstance(doc, dict):
            raise LibraryError(f"{path}: expected a JSON object, got {type(doc).__name__}")
        if doc.get("schema") != SCHEMA:
            raise LibraryError(f"{path}: expected schema {SCHEMA!r}, got {doc.get('schema')!r}")
        if doc.get("schema_version") != SCHEMA_VERSION:
            raise LibraryError(
                f"{path}: schema_version {doc.get('schema_version')!r} is not supported; this heli-env reads "
                f"version {SCHEMA_VERSION}"
            )
        if doc.get("version") != version:
            raise LibraryError(f"{path}: expected \"version\": {version} (from the file name), got {doc.get('version')!r}")
        if doc.get("columns") != list(COLUMNS):
            raise LibraryError(f"{path}: expected columns {list(COLUMNS)}, got {doc.get('columns')!r}")
        traces = doc.get("traces")
        if not isinstance(traces, list):
            raise LibraryError(f"{path}: expected a list under \"traces\", got {type(traces).__name__}")
        for k, entry in enumerate(traces):
            if not isinstance(entry, dict):
                raise LibraryError(f"{path}: trace {k} must be an object, got {type(entry).__name__}")
            missing = [key for key in _REQUIRED if key not in entry]
            if missing:
                raise LibraryError(f"{path}: trace {k} lacks {missing}; every trace needs {list(_REQUIRED)}")
            if not isinstance(entry["file"], str) or not _TRACE_FILE_RE.match(entry["file"]):
                raise LibraryError(f"{path}: trace {k} file must be 'traces/<sha256>.npy', got {entry['file']!r}")
            if entry["file"] != f"{TRACES_DIRNAME}/{entry['sha256']}.npy":
                raise LibraryError(f"{path}: trace {k} file {entry['file']!r} is not named by its sha256 {entry['sha256']!r}")
            if not isinstance(entry["n_samples"], int) or entry["n_samples"] < 2:
                raise LibraryError(f"{path}: trace {k} n_samples must be an integer >= 2, got {entry['n_samples']!r}")
            if not isinstance(entry["sample_rate_hz"], (int, float)) or not entry["sample_rate_hz"] > 0:
                raise LibraryError(f"{path}: trace {k} sample_rate_hz must be positive, got {entry['sample_rate_hz']!r}")
        return doc

    def load(self, version: int | None = None) -> list[Trace]:
        """All traces of ``version`` (latest by default), each checked against the manifest.

        Raises
        ------
        LibraryError
            An empty library, an unknown version, a corrupt manifest, or a
            trace file that is missing, unreadable, or whose shape, length,
            sample rate or SHA-256 is not what the manifest says.
        """
        version = self._resolve(version)
        doc = self.manifest(version)
        where = manifest_name(version)
        return [self._read_trace(entry, where) for entry in doc["traces"]]

    def _read_trace(self, entry: dict, where: str) -> Trace:
        path = self.path / entry["file"]
        if not path.is_file():
            raise LibraryError(f"{path}: trace file listed in {where} is missing (expected SHA-256 {entry['sha256']})")
        data = path.read_bytes()
        try:
            arr = np.load(io.BytesIO(data), allow_pickle=False)
        except (ValueError, OSError, EOFError) as e:
            raise LibraryError(f"{path}: expected a .npy trace file, could not read it: {e}") from e
        n = entry["n_samples"]
        if arr.ndim != 2 or arr.shape[0] != len(COLUMNS) or arr.dtype != np.float64:
            raise LibraryError(
                f"{path}: expected a float64 array of shape ({len(COLUMNS)}, {n}) (rows {', '.join(COLUMNS)}), "
                f"got {arr.dtype} {arr.shape}"
            )
        if arr.shape[1] != n:
            raise LibraryError(f"{path}: trace has {arr.shape[1]} samples, {where} expects {n}")
        fs = _sample_rate(arr[0]) if n > 1 else float("nan")
        want = float(entry["sample_rate_hz"])
        if not abs(fs - want) <= SAMPLE_RATE_RTOL * want:
            raise LibraryError(f"{path}: trace is sampled at {fs:.6g} Hz, {where} expects {want:.6g} Hz")
        digest = hashlib.sha256(data).hexdigest()
        if digest != entry["sha256"]:
            raise LibraryError(f"{path}: SHA-256 is {digest}, {where} expects {entry['sha256']} (file changed or corrupt)")
        try:
            return Trace(arr[0], arr[1:4], arr[4], entry)
        except LibraryError as e:
            raise LibraryError(f"{path}: {e}") from e

    def orphans(self) -> list[Path]:
        """Trace files no manifest lists (left by an append that did not finish); safe to delete."""
        listed = set()
        for v in self.versions():
            listed.update(e["file"] for e in self.manifest(v)["traces"])
        folder = self.path / TRACES_DIRNAME
        if not folder.is_dir():
            return []
        return sorted(p for p in folder.glob("*.npy") if f"{TRACES_DIRNAME}/{p.name}" not in listed)

    # -------------------------------------------------------------- writing
    @contextlib.contextmanager
    def _lock(self):
        """Advisory exclusive lock on the library folder (POSIX ``flock``; released if the writer dies)."""
        self.path.mkdir(parents=True, exist_ok=True)
        try:
            import fcntl
        except ImportError:  # pragma: no cover - Windows: no advisory lock
            yield
            return
        with open(self.path / ".lock", "a") as fh:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(fh.fileno(), fcntl.LOCK_UN)

    def append(self, items, metadata: Mapping | None = None, model_sha256: str | None = None, *,
               base_version: int | None = None) -> int:
        """Add traces as a new version; the previous versions stay as they are.

        Parameters
        ----------
        items : DisturbanceProfile, Trace, or an iterable of them
            What to add. A profile becomes a trace with
            :meth:`Trace.from_profile`.
        metadata : mapping, optional
            Recorded under each new entry's ``metadata`` (e.g. the flight's path).
        model_sha256 : str, optional
            SHA-256 of the ``model.json`` the traces were identified with.
        base_version : int, optional
            The version the new one extends (its traces are kept, the new ones follow); default the
            latest. A model directory's transaction (:class:`model_store.ModelDir`) passes the version
            its folder is committed at, which an interrupted transaction may have outgrown.

        Returns
        -------
        int
            The new version; the base one when every trace is already in
            the library (nothing is written then).

        Raises
        ------
        LibraryError
            The base manifest is corrupt (nothing is written on top of it),
            a trace file of the same name exists with other content, or an
            item is not a trace or profile.
        """
        traces = self._as_traces(items)
        with self._lock():
            return self._append(traces, metadata, model_sha256, base_version)

    def planned(self, items, base_version: int | None = None) -> tuple[int | None, list[str]]:
        """What :meth:`append` would write: the new version (None if nothing is new) and the new trace files.

        Paths are relative to the library folder (``manifest-vNNNN.json``, ``traces/<sha256>.npy``); a
        transaction records them in its journal before writing, to delete them if it is rolled back.
        """
        traces = self._as_traces(items)
        entries = [] if base_version is None else self.manifest(base_version)["traces"]
        known = {e["sha256"] for e in entries}
        files = []
        for trace in traces:
            digest = hashlib.sha256(trace.to_bytes()).hexdigest()
            if digest not in known:
                known.add(digest)
                if not (self.path / TRACES_DIRNAME / f"{digest}.npy").exists():
                    files.append(f"{TRACES_DIRNAME}/{digest}.npy")
        if len(known) == len({e["sha256"] for e in entries}):
            return None, []
        version = (self.latest_version or 0) + 1
        return version, files + [manifest_name(version)]

    def _append(self, traces, metadata, model_sha256, base_version) -> int | None:
        latest = self.latest_version
        current = latest if base_version is None else int(base_version)
        if current is None:
            previous, entries = None, []
        else:
            doc = self.manifest(current)
            entries = list(doc["traces"])
            prev_path = self.path / manifest_name(current)
            previous = {"file": prev_path.name, "sha256": sha256_of(prev_path)}
        version = (latest or 0) + 1
        known = {e["sha256"] for e in entries}
        new = []
        for trace in traces:
            data = trace.to_bytes()
            digest = hashlib.sha256(data).hexdigest()
            if digest in known:
                continue
            known.add(digest)
            self._write_trace_file(digest, data)
            new.append(self._entry(trace, digest, version, metadata, model_sha256))
        if not new:
            return current
        doc = {
            "schema": SCHEMA,
            "schema_version": SCHEMA_VERSION,
            "version": version,
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "heli_env": _heli_version(),
            "previous": previous,
            "columns": list(COLUMNS),
            "units": UNITS,
            "traces": entries + new,
        }
        target = self.path / manifest_name(version)
        if target.exists():  # another writer without the lock (e.g. on Windows)
            raise LibraryError(f"{target} appeared while appending; not overwriting it, append again")
        write_text(target, json.dumps(jsonable(doc), indent=2, allow_nan=False) + "\n")
        faults.event(f"wrote {target}")
        return version

    def _write_trace_file(self, digest: str, data: bytes) -> None:
        path = self.path / TRACES_DIRNAME / f"{digest}.npy"
        if path.exists():
            if sha256_of(path) != digest:
                raise LibraryError(
                    f"{path}: exists with SHA-256 {sha256_of(path)}, expected {digest} from its name "
                    "(corrupt trace file; delete it and append again)"
                )
            return
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)
        faults.event(f"wrote {path}")

    @staticmethod
    def _as_traces(items) -> list[Trace]:
        """Traces, or disturbance profiles (anything with ``to_trace()``), as a list of :class:`Trace`."""
        if isinstance(items, Trace) or hasattr(items, "to_trace"):
            items = [items]
        elif not isinstance(items, Iterable):
            raise LibraryError(f"append takes a Trace, a DisturbanceProfile or a list of them, got {type(items).__name__}")
        out = []
        for k, item in enumerate(items):
            if isinstance(item, Trace):
                out.append(item)
            elif hasattr(item, "to_trace"):
                out.append(item.to_trace())
            else:
                raise LibraryError(f"item {k}: expected a Trace or a DisturbanceProfile, got {type(item).__name__}")
        if not out:
            raise LibraryError("append needs at least one trace, got none")
        return out

    @staticmethod
    def _entry(trace: Trace, digest: str, version: int, metadata, model_sha256) -> dict:
        meta = dict(trace.metadata)
        clash = [k for k in _RESERVED if k in meta]
        for k in clash:  # a trace read from another library: the new library recomputes these
            meta.pop(k)
        entry = {
            "id": digest[:16],
            "file": f"{TRACES_DIRNAME}/{digest}.npy",
            "sha256": digest,
            "n_samples": trace.n,
            "sample_rate_hz": trace.sample_rate,
            "duration_s": trace.duration,
            "added_in_version": version,
            "source": None, "interval_s": None, "samples_per_interval": None, "smoothing": None,
            "statistics": _statistics(trace),
            "kd": None, "control_gains": None, "model": None, "axes": list(AXES),
        }
        entry.update({k: v for k, v in meta.items() if k != "statistics"})
        if model_sha256 is not None:
            entry["model"] = {**(entry.get("model") or {}), "sha256": str(model_sha256)}
        if metadata:
            entry["metadata"] = {**(entry.get("metadata") or {}), **dict(metadata)}
        return entry
