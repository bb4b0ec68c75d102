"""The one owner of a model directory: ``model.json``, the disturbance library and ``history/``, read as one
state and written as one transaction.

Layout (``DIR`` is what ``heli identify --out`` names)::

    DIR/model.json                  the model (:mod:`model_store.model_file`)
    DIR/disturbances/               the disturbance library (:mod:`model_store.disturbance_library`)
    DIR/history/                    every model the folder replaced (model-<sha256[:12]>.json), and the reports
                                    a refresh replaced (report-<sha256[:12]>.md, ...)
    DIR/report.md, refresh.*, diagnosis.*   reports written with the model
    DIR/.heli-lock                  writers' lock (flock), held for a command's whole read-compute-commit
    DIR/.heli-commit-lock           held exclusively while files move, shared by readers
    DIR/.heli-journal.json          only while a write is under way, or after one was interrupted
    DIR/.heli-staging/<id>/         the new model and reports of that write

The steady state is the format every earlier version wrote: ``model.json`` and the library's latest version.
A write (:meth:`ModelDir.transaction`) keeps its new files out of that state until one atomic step:

1. keep a copy of the ``model.json`` about to be replaced in ``history/``;
2. write the journal, state ``"prepared"``: the base (model SHA-256, library version), the target and the files
   the write will create;
3. write the new model and reports to ``.heli-staging/<id>/``, the traces and the next library manifest;
4. **commit**: replace the journal by the same with state ``"committed"`` (``os.replace``): it names the new
   ``model.json``'s SHA-256 and the library version together;
5. move the staged files into place, then remove the staging folder and the journal.

A reader takes the state the journal names: none, the steady state; ``"prepared"``, the base (``model.json`` is
untouched until the commit, the library's base version); ``"committed"``, the target (``model.json`` once
moved, its staged copy until then; the target library version). So after a kill at any instant the folder reads as the old or the
new state. The next writer (or ``heli check``) finishes a committed write or rolls back a prepared one (deleting
the files it created) and says so. Writers take an exclusive ``flock`` for their whole read-compute-commit, so
two refreshes serialise and neither is lost; with ``wait=False`` a busy folder is refused with
:class:`~identification.errors.ModelDirBusyError`. Before a write the library is read and checked in full: a
corrupt or incomplete library is refused with the :class:`~identification.errors.LibraryError` a reader gets.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import json
import os
import shutil
import sys
import uuid
from dataclasses import dataclass
from pathlib import Path

import model_store.faults as faults
from heli_core.files import keep_copy, write_bytes, write_text

from .disturbance_library import LIBRARY_DIRNAME, DisturbanceLibrary, Trace
from .errors import LibraryError, ModelDirBusyError, ModelDirError, ModelFileError
from .model_file import MODEL_FILENAME, ModelDocument, decode_model, encode_model, model_document, read_model_bytes

LOCK_NAME = ".heli-lock"
COMMIT_LOCK_NAME = ".heli-commit-lock"
JOURNAL_NAME = ".heli-journal.json"
STAGING_NAME = ".heli-staging"
HISTORY_NAME = "history"
JOURNAL_SCHEMA = "heli-env/model-dir-transaction"
JOURNAL_SCHEMA_VERSION = 1


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _history_name(name: str, digest: str) -> str:
    """``history/<stem>-<sha256[:12]><suffix>``, the name :func:`heli_core.files.keep_copy` gives."""
    p = Path(name)
    return f"{HISTORY_NAME}/{p.stem}-{digest[:12]}{p.suffix}"


def _notice(message: str) -> None:
    print(f"heli: {message}", file=sys.stderr, flush=True)


@dataclass(frozen=True, eq=False)
class ModelState:
    """What a model directory holds, read and checked as one state.

    Attributes
    ----------
    root : Path
        The model directory.
    document : ModelDocument or None
        ``model.json``'s whole document, checked (None when the folder has no model yet).
    model_sha256 : str or None
        SHA-256 of ``model.json``'s bytes.
    library_version : int or None
        The library version of this state (None: no library yet).
    traces : tuple of Trace
        Every trace of that version, each checked against its manifest.
    manifest : dict or None
        That version's manifest.
    pending : str or None
        ``"prepared"`` or ``"committed"`` when an interrupted write is waiting for the next writer
        (the state read is the one it names); None otherwise.
    """

    root: Path
    document: ModelDocument | None
    model_sha256: str | None
    library_version: int | None
    traces: tuple = ()
    manifest: dict | None = None
    pending: str | None = None

    @property
    def params(self):
        """The model's :class:`~heli_core.params.ModelParams` (None when the folder has none yet)."""
        return None if self.document is None else self.document.params

    @property
    def entries(self) -> list:
        """The library manifest's trace entries (empty without a library)."""
        return list((self.manifest or {}).get("traces") or [])


class ModelDir:
    """A model directory: read it with :meth:`load`, change it with :meth:`transaction` (module docstring).

    Parameters
    ----------
    path : str or Path
        The directory (or its ``model.json``).
    notify : callable, optional
        Called with one line for what the user should know (waiting for another writer, an interrupted write
        finished or rolled back). Default: printed to standard error.
    """

    def __init__(self, path, notify=None):
        path = Path(path)
        self.root = path.parent if path.suffix == ".json" else path
        self.notify = notify or _notice
        self.library = DisturbanceLibrary(self.root)

    def __repr__(self) -> str:
        return f"ModelDir({str(self.root)!r})"

    @property
    def model_path(self) -> Path:
        return self.root / MODEL_FILENAME

    @property
    def journal_path(self) -> Path:
        return self.root / JOURNAL_NAME

    # ------------------------------------------------------------------ locks
    @contextlib.contextmanager
    def _flock(self, name: str, exclusive: bool, wait: bool = True, what: str = ""):
        """``flock`` on ``DIR/name``; a reader on a folder it cannot write (shipped data) goes without."""
        try:
            import fcntl
        except ImportError:  # pragma: no cover - Windows: no advisory lock
            yield
            return
        path = self.root / name
        try:
            # a reader never creates the file: a folder no writer of this version has touched (the model shipped
            # in the package) has nothing to wait for, and a writer makes it as its transaction begins
            fh = open(path, "a+") if exclusive else open(path)
        except OSError:
            if exclusive:
                raise
            yield
            return
        with fh:
            mode = fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH
            try:
                fcntl.flock(fh.fileno(), mode | fcntl.LOCK_NB)
            except BlockingIOError:
                fh.seek(0)
                holder = fh.read().strip() or "another command"
                if not wait:
                    raise ModelDirBusyError(
                        f"{self.root} is being written by {holder}; expected a free model directory "
                        "(run again when it is done, or without --no-wait to wait for it)") from None
                if what:
                    self.notify(f"{self.root} is being written by {holder}; waiting for it to finish")
                fcntl.flock(fh.fileno(), mode)
            if exclusive and what:
                fh.seek(0)
                fh.truncate()
                fh.write(f"pid {os.getpid()} ({what}, since "
                         f"{_dt.datetime.now().astimezone().isoformat(timespec='seconds')})\n")
                fh.flush()
                try:
                    yield
                finally:
                    fh.truncate(0)  # the holder's line goes with the holder: a refused command leaves no trace
                return
            yield

    # ------------------------------------------------------------------ reading
    def _journal(self) -> dict | None:
        try:
            text = self.journal_path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return None
        try:
            doc = json.loads(text)
            if doc.get("schema") != JOURNAL_SCHEMA or doc.get("state") not in ("prepared", "committed"):
                raise ValueError(f"schema {doc.get('schema')!r}, state {doc.get('state')!r}")
            doc["base"]["library_version"], doc["target"]["model_file"]  # noqa: B018 - keys checked
        except (ValueError, KeyError, TypeError, AttributeError) as e:
            raise ModelDirError(
                f"{self.journal_path}: expected the journal of an interrupted write, could not read it ({e}); "
                "'heli check' shows what the folder holds") from e
        return doc

    def load(self, library_version: int | None = None, *, library: bool = True) -> ModelState:
        """The directory's model and library as one checked state (module docstring).

        Parameters
        ----------
        library_version : int, optional
            Library version to read instead of the state's own.
        library : bool
            Read the library's traces and manifest (False: the model alone; the state's ``library_version``
            is still the version it names, its ``traces`` empty).

        Raises
        ------
        ModelFileError
            No ``model.json``, or a corrupt one (or, :class:`ModelDirError`, a committed model that is gone).
        LibraryError
            The library is corrupt: a manifest or trace that is unreadable or disagrees with its manifest.
        """
        if not self.root.is_dir():
            raise ModelFileError(f"model directory {str(self.root)!r} does not exist (write one with 'heli identify')")
        with self._flock(COMMIT_LOCK_NAME, exclusive=False):
            return self._read_state(library_version, strict_model=True, library=library)

    def _read_state(self, library_version=None, strict_model=True, library=True) -> ModelState:
        journal = self._journal()
        model_file = self.model_path
        want_sha = None
        if journal is None:
            version = self.library.latest_version
        elif journal["state"] == "committed":
            version = journal["target"]["library_version"]
            if journal["target"]["model_file"] and not self._holds(self.model_path, journal["target"]["model_sha256"]):
                model_file, want_sha = self.root / journal["target"]["model_file"], journal["target"]["model_sha256"]
        else:
            version = journal["base"]["library_version"]
        if library_version is not None:
            version = int(library_version)
        doc = digest = None
        try:
            doc, digest = self._read_model(model_file, want_sha)
        except ModelFileError:
            if strict_model:
                raise
        traces, manifest = (), None
        if version is not None and library:
            traces = tuple(self.library.load(version))
            manifest = self.library.manifest(version)
        return ModelState(self.root, doc, digest, version, traces, manifest,
                          journal["state"] if journal else None)

    @staticmethod
    def _holds(path: Path, digest: str | None) -> bool:
        """Whether the file at ``path`` exists with SHA-256 ``digest``."""
        try:
            return digest is not None and _sha(path.read_bytes()) == digest
        except OSError:
            return False

    def _read_model(self, path: Path, want_sha: str | None = None):
        if not path.exists():
            if want_sha is not None:
                raise ModelDirError(f"{path}: the committed model (SHA-256 {want_sha[:12]}…) is missing; "
                                    "'heli check' shows what the folder holds")
        data = read_model_bytes(path)
        digest = _sha(data)
        if want_sha is not None and digest != want_sha:
            raise ModelDirError(f"{path}: SHA-256 is {digest}, the committed model's is {want_sha} (file changed)")
        return decode_model(data, str(path)), digest

    # ------------------------------------------------------------------ writing
    @contextlib.contextmanager
    def transaction(self, *, wait: bool = True, what: str = "write"):
        """Change the directory as one step: ``with ModelDir(d).transaction() as tx: tx.write_model(...)``.

        Takes the writers' lock (waiting with a message, or :class:`ModelDirBusyError` with ``wait=False``),
        finishes or rolls back an interrupted write, reads the current state (:attr:`Transaction.base`; the
        library checked in full) and yields a :class:`Transaction` that stages the new files in memory. Leaving
        the block commits them (module docstring); an exception in the block writes nothing.

        Parameters
        ----------
        wait : bool
            Wait for another writer (default) or refuse at once.
        what : str
            The command, for the lock's holder line and the journal (``"refresh"``).

        Raises
        ------
        LibraryError
            The library is corrupt or incomplete (nothing is written on top of it).
        ModelDirBusyError
            Another writer holds the folder and ``wait`` is false.
        """
        self.root.mkdir(parents=True, exist_ok=True)
        with self._flock(LOCK_NAME, exclusive=True, wait=wait, what=what):
            self.recover()
            tx = Transaction(self, self._read_state(strict_model=False), what)
            yield tx
            tx._commit()

    def recover(self) -> str | None:
        """Finish a committed or roll back a prepared interrupted write (call with the writers' lock held).

        Returns what was done (also passed to ``notify``), or None when nothing was pending.
        """
        with self._flock(COMMIT_LOCK_NAME, exclusive=True):
            journal = self._journal()
            if journal is None:
                self._remove_staging()
                return None
            started = f"{journal.get('what', 'a write')} started {journal.get('started', '?')} by pid {journal.get('pid', '?')}"
            if journal["state"] == "committed":
                self._roll_forward(journal)
                message = f"{self.root}: finished an interrupted {started} (it had committed)"
            else:
                self._roll_back(journal)
                message = f"{self.root}: rolled back an interrupted {started} (it had not committed)"
        self.notify(message)
        return message

    def _roll_forward(self, journal: dict) -> None:
        target = journal["target"]
        moves = dict(target["files"])
        if target["model_file"]:
            moves[MODEL_FILENAME] = target["model_sha256"]
        staging = self.root / STAGING_NAME / journal["id"]
        for name, digest in moves.items():
            staged, final = staging / name, self.root / name
            if self._holds(final, digest):
                continue
            if not self._holds(staged, digest):
                raise ModelDirError(f"{staged}: expected the committed {name} (SHA-256 {digest[:12]}…), "
                                    "found it missing or changed; cannot finish the interrupted write")
            os.replace(staged, final)
            faults.event(f"moved {final}")
        self._remove_staging()
        self.journal_path.unlink()
        faults.event(f"removed {self.journal_path}")

    def _roll_back(self, journal: dict) -> None:
        for rel in reversed(journal.get("created") or []):
            path = self.root / rel
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
                faults.event(f"removed {path}")
        self._remove_staging()
        self.journal_path.unlink()
        faults.event(f"removed {self.journal_path}")

    def _remove_staging(self) -> None:
        staging = self.root / STAGING_NAME
        if staging.exists():
            shutil.rmtree(staging)
            faults.event(f"removed {staging}")

    # ------------------------------------------------------------------ check and repair
    def verify(self) -> list[str]:
        """Problems of the directory, one line each (empty: it reads as one consistent state).

        Checks the model file, every library version (manifests and traces), the state an interrupted
        write left, and what a crash can leave behind (temporary files, trace files no manifest lists).
        """
        problems = []
        if not self.root.is_dir():
            return [f"{self.root}: no such directory"]
        try:
            journal = self._journal()
        except ModelDirError as e:
            return [str(e)]
        if journal is not None:
            problems.append(f"an interrupted {journal.get('what', 'write')} (pid {journal.get('pid', '?')}, "
                            f"{journal['state']}) is pending; repair "
                            + ("finishes it" if journal["state"] == "committed" else "rolls it back"))
        try:
            state = self.load()
        except (ModelFileError, LibraryError) as e:
            problems.append(f"{type(e).__name__}: {e}")
            state = None
        for v in self.library.versions():
            if state is not None and v == state.library_version:
                continue
            try:
                self.library.load(v)
            except LibraryError as e:
                if journal is None or v != journal["target"]["library_version"]:
                    problems.append(f"LibraryError: {e}")
        with contextlib.suppress(LibraryError):
            problems += [f"{p}: trace file no manifest lists (left by an interrupted write)"
                         for p in self.library.orphans()]
        problems += [f"{p}: temporary file of an interrupted write" for p in self._temporary_files()]
        return problems

    def _temporary_files(self) -> list[Path]:
        folders = [self.root, self.root / HISTORY_NAME, self.library.path, self.library.path / "traces"]
        return sorted(p for d in folders if d.is_dir() for p in d.glob(".*.tmp"))

    def repair(self, *, wait: bool = True) -> list[str]:
        """Repair what can be: finish or roll back an interrupted write, delete temporary files and
        unlisted trace files. Returns what was done. A corrupt model or library is left as it is
        (:meth:`verify` still names it)."""
        done = []
        with self._flock(LOCK_NAME, exclusive=True, wait=wait, what="heli check"):
            message = self.recover()
            if message:
                done.append(message)
            with self._flock(COMMIT_LOCK_NAME, exclusive=True):
                for p in self._temporary_files():
                    p.unlink()
                    done.append(f"removed {p}")
                with contextlib.suppress(LibraryError):
                    for p in self.library.orphans():
                        p.unlink()
                        done.append(f"removed {p} (no manifest lists it)")
        return done


class Transaction:
    """New files for a model directory, staged in memory and committed as one step (:meth:`ModelDir.transaction`).

    Attributes
    ----------
    base : ModelState
        The directory as the transaction found it (the model may be None or unreadable: ``base.params`` is
        None then; a writer that needs it raises).
    library_version : int or None
        The library version the directory will be at after the commit.
    """

    def __init__(self, model_dir: ModelDir, base: ModelState, what: str):
        self.dir = model_dir
        self.base = base
        self.what = what
        self.library_version = base.library_version
        self._model_text: str | None = None
        self._traces: list[Trace] = []
        self._reports: dict[str, bytes] = {}
        self.committed = False

    @property
    def root(self) -> Path:
        return self.dir.root

    @property
    def model_sha256(self) -> str | None:
        """SHA-256 of the ``model.json`` the directory will hold after the commit."""
        if self._model_text is not None:
            return _sha(self._model_text.encode("utf-8"))
        return self.base.model_sha256

    def write_model(self, params, **kwargs) -> Path:
        """Stage a new ``model.json`` (arguments of :func:`model_store.model_file.model_document`); its path."""
        return self.write_model_document(model_document(params, **kwargs))

    def write_model_document(self, doc: dict) -> Path:
        """Stage a new ``model.json`` from its document; returns its final path."""
        self._model_text = encode_model(doc)
        return self.dir.model_path

    def add_traces(self, items, metadata=None) -> int | None:
        """Stage disturbance traces (profiles or :class:`Trace`) for the next library version; returns it."""
        traces = DisturbanceLibrary._as_traces(items)
        if metadata:
            traces = [Trace(t.time, t.ud, t.collective,
                            {**t.metadata, "metadata": {**(t.metadata.get("metadata") or {}), **dict(metadata)}})
                      for t in traces]
        self._traces += traces
        version, _ = self.dir.library.planned(self._traces, self.base.library_version)
        self.library_version = self.base.library_version if version is None else version
        return self.library_version

    def write_report(self, name: str, content) -> Path:
        """Stage a report file at the directory's top (``report.md``, ``refresh.json``, ...); its final path."""
        if not name or Path(name).name != name or name.startswith(".") or name == MODEL_FILENAME:
            raise ValueError(f"a report is a plain file name at the model directory's top, got {name!r}")
        self._reports[name] = content.encode("utf-8") if isinstance(content, str) else bytes(content)
        return self.root / name

    # ------------------------------------------------------------------ commit
    def _commit(self) -> None:
        d = self.dir
        if self._model_text is None and not self._traces and not self._reports:
            self.committed = True
            return
        model_bytes = None if self._model_text is None else self._model_text.encode("utf-8")
        model_sha = self.model_sha256
        tx_id = uuid.uuid4().hex
        staging = self.root / STAGING_NAME / tx_id
        model_file = None if model_bytes is None else f"{STAGING_NAME}/{tx_id}/{MODEL_FILENAME}"
        version, library_files = (None, [])
        if self._traces:
            version, library_files = d.library.planned(self._traces, self.base.library_version)
        created = [f"{LIBRARY_DIRNAME}/{f}" for f in library_files]
        journal = {
            "schema": JOURNAL_SCHEMA, "schema_version": JOURNAL_SCHEMA_VERSION,
            "id": tx_id, "what": self.what, "pid": os.getpid(),
            "started": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "state": "prepared",
            "base": {"model_sha256": self.base.model_sha256, "library_version": self.base.library_version},
            "target": {"model_sha256": model_sha, "model_file": model_file,
                       "library_version": version if version is not None else self.base.library_version,
                       "files": {name: _sha(data) for name, data in self._reports.items()}},
            "created": created,
        }
        with d._flock(COMMIT_LOCK_NAME, exclusive=True):
            try:
                self._keep_replaced(model_bytes)
                write_text(d.journal_path, json.dumps(journal, indent=2) + "\n")
                faults.event(f"wrote {d.journal_path} (prepared)")
                if model_file:
                    write_bytes(self.root / model_file, model_bytes)
                    faults.event(f"wrote {model_file}")
                for name, data in self._reports.items():
                    write_bytes(staging / name, data)
                    faults.event(f"wrote {staging / name}")
                if version is not None:
                    d.library.path.mkdir(parents=True, exist_ok=True)
                    written = d.library.append(self._traces, model_sha256=model_sha,
                                               base_version=self.base.library_version)
                    if written != version:
                        raise LibraryError(f"{d.library.path}: wrote version {written}, expected {version}")
                journal["state"] = "committed"
                write_text(d.journal_path, json.dumps(journal, indent=2) + "\n")  # the commit
                faults.event(f"wrote {d.journal_path} (committed)")
            except faults.InjectedFault:
                raise
            except BaseException:
                # failed before the commit (a full disk, a read-only library, Ctrl-C): undo what was written
                if d.journal_path.exists() and d._journal()["state"] == "prepared":
                    d._roll_back(d._journal())
                raise
            self.committed = True
            d._roll_forward(journal)
        self.library_version = journal["target"]["library_version"]

    def _keep_replaced(self, model_bytes) -> None:
        """Copy the ``model.json`` the commit replaces to ``history/`` (named by content; kept once)."""
        path = self.dir.model_path
        if model_bytes is not None and path.is_file():
            digest = _sha(path.read_bytes())
            if digest != _sha(model_bytes) and not (self.root / _history_name(MODEL_FILENAME, digest)).exists():
                keep_copy(path)
                faults.event(f"kept {path} in history")
