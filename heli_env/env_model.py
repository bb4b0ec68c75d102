"""The environment's model: what an environment needs from a model directory written by ``heli identify``.

A model directory holds ``model.json`` (:mod:`model_store.model_file`) and
the disturbance library ``disturbances/`` (:mod:`model_store.disturbance_library`);
:class:`model_store.ModelDir` reads them as one state (a write that was
interrupted reads as before or after it). :func:`load_env_model` reads and
checks both once and packs the library's traces into flat arrays the
environments index without copying; :func:`as_env_model` is what every
function taking "a model" (a directory, None for the shipped model, or an
:class:`EnvModel` already loaded) calls. (Until issue 34 this module was
``heli_env.model_dir``, a name :mod:`model_store.model_dir` holds too.)
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property
from importlib import resources
from pathlib import Path

import numpy as np

from heli_core.params import ModelParams
from heli_core.sensors import SensorModel
from heli_core.terms import AXES
from model_store.disturbance_library import LIBRARY_DIRNAME
from model_store.errors import LibraryError, ModelFileError
from model_store.model_dir import ModelDir
from model_store.model_file import MODEL_FILENAME, ModelDocument

from .errors import EnvModelError

DEFAULT_MODEL_NAME = "default"


def default_model_dir() -> Path:
    """The model directory that ships with the package.

    heli-env identified it itself from three synthetic flights of its truth model
    (``scripts/build_default_model.py``); ``report.md`` beside ``model.json`` tells how.
    """
    return Path(str(resources.files("heli_env") / "data" / DEFAULT_MODEL_NAME))


@dataclass(frozen=True, eq=False)
class EnvModel:
    """An identified model and its disturbance traces, ready for an environment.

    Attributes
    ----------
    params : ModelParams
    path : Path
        The model directory.
    document : ModelDocument
        The model file's document (its verdict, sensors, provenance, fit statistics).
    ud : ndarray, shape (3, total)
        u_d of every trace, concatenated [stick units].
    gains : ndarray, shape (3, n_traces)
        Control gains (k2, k6, k10) of the model each trace was identified with
        (the library records them; the current model's where it does not).
    collective : ndarray, shape (total,)
        Recorded collective of every trace, concatenated [-1, 1].
    starts, lengths : ndarray of int, shape (n_traces,)
        Where each trace starts in the concatenation, and its length [samples].
    sample_rate : float
        Sample rate shared by all traces [Hz].
    trace_ids : tuple of str
        Library id of each trace.
    sources : tuple of str
        Source flight of each trace.
    library_version : int
    """

    params: ModelParams
    path: Path
    document: ModelDocument
    ud: np.ndarray
    gains: np.ndarray
    collective: np.ndarray
    starts: np.ndarray
    lengths: np.ndarray
    sample_rate: float
    trace_ids: tuple
    sources: tuple
    library_version: int

    @property
    def n_traces(self) -> int:
        return int(self.starts.size)

    @property
    def sensors(self) -> SensorModel:
        """The gyros' and the attitude estimate's noise and lines identified with the model
        (:attr:`ModelDocument.sensors`; silent for a model written without them)."""
        return self.document.sensors

    @cached_property
    def torque(self) -> np.ndarray:
        """The gust torque per inertia the environments replay, shape (3, total) [rad/s^2].

        Each trace's u_d times the gains it was identified with: the identified
        torque is ``k * u_d`` with the identifying model's ``k`` (eq. 42), so a
        trace from an earlier flight keeps the torque the aircraft met when the
        model is refreshed and its gains move.
        """
        torque = np.repeat(self.gains, self.lengths, axis=1) * self.ud
        torque.setflags(write=False)
        return torque

    @cached_property
    def replay_ud(self) -> np.ndarray:
        """:attr:`torque` in the current model's stick units, shape (3, total): the u_d this
        model would need to feel the replayed gusts (equal to ``ud`` where a trace's gains are
        the model's). What spectra and gust statistics of the replayed wind are taken from."""
        scale = self.gains / self.params.control_gains[:, None]
        ud = np.repeat(scale, self.lengths, axis=1) * self.ud
        ud.setflags(write=False)
        return ud


def load_env_model(path=None, library_version: int | None = None) -> EnvModel:
    """Read ``model.json`` and the disturbance library of a model directory.

    Parameters
    ----------
    path : str or Path, optional
        Model directory (or its ``model.json``). Default: the model shipped with the package.
    library_version : int, optional
        Library version to replay (default the directory's own: its latest committed version).

    Raises
    ------
    EnvModelError
        The directory, ``model.json`` or the library is missing or corrupt, or
        the traces do not share one sample rate; the message names the file.
    """
    root = default_model_dir() if path is None else Path(path)
    if root.suffix == ".json":
        root = root.parent
    if not root.is_dir():
        raise EnvModelError(f"model directory {str(root)!r} does not exist (write one with 'heli identify')")
    lib_dir = root / LIBRARY_DIRNAME
    try:
        state = ModelDir(root).load(library_version)
    except LibraryError as e:
        raise EnvModelError(f"{lib_dir}: {e}") from e
    except ModelFileError as e:
        raise EnvModelError(str(e)) from e
    params, doc, traces, version = state.params, state.document, state.traces, state.library_version
    if version is None:
        raise EnvModelError(
            f"{lib_dir}: no disturbance library beside {MODEL_FILENAME}; 'heli identify' writes one "
            "(the environment replays its gusts)" if not lib_dir.is_dir() else
            f"{lib_dir}: the disturbance library at {lib_dir} is empty: no manifest-vNNNN.json yet"
        )
    if not traces:
        raise EnvModelError(f"{lib_dir}: the library holds no traces")
    rates = np.array([t.sample_rate for t in traces])
    if np.any(np.abs(rates - rates[0]) > 1e-6 * rates[0]):
        raise EnvModelError(f"{lib_dir}: traces must share one sample rate to be replayed, got {sorted(set(rates))} Hz")
    lengths = np.array([t.n for t in traces], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    ud = np.ascontiguousarray(np.concatenate([t.ud for t in traces], axis=1))
    gains = np.column_stack([_trace_gains(t.metadata, params, lib_dir) for t in traces])
    col = np.ascontiguousarray(np.concatenate([t.collective for t in traces]))
    for a in (ud, gains, col, starts, lengths):
        a.setflags(write=False)
    ids = tuple(str(t.metadata.get("id", i)) for i, t in enumerate(traces))
    sources = tuple(str((t.metadata.get("source") or {}).get("name", "")) for t in traces)
    return EnvModel(params, root, doc, ud, gains, col, starts, lengths, float(rates[0]), ids, sources, int(version))


def as_env_model(model=None, library_version: int | None = None) -> EnvModel:
    """``model`` itself when it is an :class:`EnvModel`, else the model directory it names, loaded
    (:func:`load_env_model`; None: the model shipped with the package).

    Parameters
    ----------
    model : EnvModel, str, Path or None
        A loaded model, a model directory (or its ``model.json``), or None.
    library_version : int, optional
        Library version to replay when ``model`` is loaded here (an :class:`EnvModel` is returned as it is).

    Raises
    ------
    EnvModelError
        As :func:`load_env_model`.
    """
    return model if isinstance(model, EnvModel) else load_env_model(model, library_version)


def perturbed(env_model: EnvModel, delay: float = 0.0, gain: float = 1.0) -> EnvModel:
    """``env_model`` with ``delay`` seconds more servo delay on every axis (a negative ``delay`` shortens it,
    never below 0) and its control gains times ``gain``: an aircraft that is not quite the model, as the
    robustness check (:mod:`controllers.robustness`) and a training over several servo delays fly it.

    The library's gust torque stays the aircraft's (each trace keeps the gains it was identified with).
    """
    p = env_model.params
    values = {f"tau_{axis}": max(tau + delay, 0.0) for axis, tau in zip(AXES, p.taus)}
    values.update({name: gain * getattr(p, name) for name in ("k2", "k6", "k10")})
    return dataclasses.replace(env_model, params=p.with_values(**values))


def _trace_gains(entry: dict, params: ModelParams, lib_dir: Path) -> np.ndarray:
    """(k2, k6, k10) a trace's u_d was scaled with: its library entry's ``control_gains``, else the model's."""
    recorded = entry.get("control_gains")
    if not recorded:
        return params.control_gains
    try:
        gains = np.array([float(recorded[axis]) for axis in ("roll", "pitch", "yaw")])
    except (KeyError, TypeError, ValueError) as e:
        raise EnvModelError(f"{lib_dir}: trace {entry.get('id')!r} records control_gains {recorded!r}; expected "
                            "numbers for roll, pitch and yaw") from e
    if not np.all(np.isfinite(gains)):
        raise EnvModelError(f"{lib_dir}: trace {entry.get('id')!r} records non-finite control_gains {recorded!r}")
    return gains
