"""The model file ``model.json``: an identified model with its provenance.

Schema (``schema_version`` 1)::

    {
      "schema": "heli-env/model",
      "schema_version": 1,
      "structure": "decoupled" | "coupled" | "custom",
      "verdict": {"level": "usable" | "doubtful" | "unusable", "reasons": [...]},   # optional: whether the
                                             # model can be used (model_store.verdict); absent: "not judged"
      "parameters": {"k1": 0.0, "k2": 1.3475, ..., "kd3": 0.0964},   # all 15 of eqs. (18), (21)
      "added_terms": {"nld1": 0.2},          # catalogue terms beyond the paper's model
      "servo_delay_s": {"roll": 0.0, "pitch": 0.0, "yaw": 0.0},       # eq. (31)
      "servo_lag_s": {"roll": 0.04, ...},    # optional: a servo lag the data supported (eq. 31's d1)
      "sensors": {"gyro_noise_rad_s": {...}, "attitude_noise_rad": {...},   # optional: what the
                  "gyro_lines": [{"axis", "frequency_hz", "amplitude_rad_s"}]},  # env measures through
      "units": {"k2": "rad/s^2", ...},
      "sample_rate_hz": 100.0,
      "filter": {...} | null,                # Section 3.1 prefilter settings
      "identification": {...},               # method and its settings
      "fit_statistics": {...},               # per axis: r2, condition number, std errors ...; the fitted flight's
                                             # validation, the frequency response (frequency_response) and the
                                             # flights of --validate (validation_flights), when identified
      "provenance": {"sources": [{"file": "flight.csv", "sha256": "..."}], "created": "...", "heli_env": "0.1.0"}
    }

Parameters keep the paper's names and sign conventions (eq. 18: ``-k3*p``;
eq. 21: ``-k12*col``). Files are written atomically.

A document is written from :func:`model_document`'s dictionary and read as one frozen
:class:`ModelDocument` (:meth:`ModelDocument.from_dict`, the one parser of the format: the parameters, the
verdict, the sensors and the provenance's sources are checked and typed there). Every reader outside this
package takes a :class:`ModelDocument`, from :meth:`model_store.ModelDir.load` for a model folder.
"""

from __future__ import annotations

import copy
import datetime as _dt
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from .errors import ModelFileError, UnusableModelError
from .verdict import ModelVerdict
from heli_core.files import jsonable, keep_copy, write_text
from heli_core.params import ModelParams
from heli_core.sensors import SensorModel
from heli_core.terms import AXES, BASE_PARAMS, EXTRA_PARAMS, TERMS

SCHEMA = "heli-env/model"
SCHEMA_VERSION = 1
MODEL_FILENAME = "model.json"
MAX_PARAMETER = 1e6
"""Largest |value| a model file's parameter may have. The estimators' searches stop far below it (a damping at
most 200 1/s; the largest control gain a real log gave, a 5-inch quad's, about 2100 rad/s² per unit stick): a value
beyond it is a file edited or corrupted, or a fit that failed, and would overflow the discretised model (k3 = 1e300
gave NaN states)."""


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("heli-env")
    except Exception:  # pragma: no cover - not installed
        return "unknown"


def model_document(params: ModelParams, *, structure: str = "custom", sample_rate: float | None = None,
                   filter_settings=None, identification=None, fit_statistics=None, sources=(),
                   extra=None, sensors: SensorModel | None = None, verdict: ModelVerdict | None = None) -> dict:
    """Build the JSON document of a model (see the module docstring); ``sensors`` (identified from the
    flights, :mod:`identification.sensors`) and ``verdict`` (:mod:`model_store.verdict`) are stored when
    given."""
    values = params.values()
    doc = {
        "schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "structure": structure,
        "parameters": {k: values[k] for k in BASE_PARAMS},
        "added_terms": {k: v for k, v in params.extra},
        "servo_delay_s": {axis: params.taus[i] for i, axis in enumerate(AXES)},
        "units": {k: TERMS[k].unit for k in list(BASE_PARAMS) + [k for k, _ in params.extra]} | {"servo_delay_s": "s"},
        "sample_rate_hz": sample_rate,
        "filter": filter_settings,
        "identification": identification or {},
        "fit_statistics": fit_statistics or {},
        "provenance": {
            "sources": [dict(s) for s in sources],
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "heli_env": _version(),
        },
    }
    if verdict is not None:
        doc = with_verdict(doc, verdict)
    if any(params.lags):  # written only when identified: files of servos without a lag stay as they were
        doc["servo_lag_s"] = {axis: params.lags[i] for i, axis in enumerate(AXES)}
        doc["units"]["servo_lag_s"] = "s"
    if sensors is not None:
        doc["sensors"] = sensors.to_dict()
    if extra:
        doc.update(extra)
    return doc


def with_verdict(doc: dict, verdict: ModelVerdict) -> dict:
    """A copy of model document ``doc`` with ``verdict`` stored, right after ``"structure"`` (where a reader
    of ``model.json`` meets it before the numbers it judges)."""
    out = {}
    for key, value in doc.items():
        if key != "verdict":
            out[key] = value
        if key == "structure":
            out["verdict"] = verdict.to_dict()
    out.setdefault("verdict", verdict.to_dict())
    return out


def verdict_of(document, where: str = "model") -> ModelVerdict:
    """The verdict stored in a model document (:data:`model_store.verdict.NOT_JUDGED` when it has none).

    Raises
    ------
    ModelFileError
        A malformed ``"verdict"`` entry.
    """
    try:
        return ModelVerdict.from_dict((document or {}).get("verdict"))
    except ValueError as e:
        raise ModelFileError(f"{where}: {e}") from None


def require_usable(verdict: ModelVerdict, where: str = "model", *, flag: str, accept: bool = False,
                   use: str = "use it") -> ModelVerdict:
    """``verdict`` (a model's: :attr:`ModelDocument.verdict`), refusing an unusable model
    unless ``accept``.

    Parameters
    ----------
    verdict : ModelVerdict
        The model's verdict.
    where : str
        What to call the model in the message (its path).
    flag : str
        The option that sets ``accept`` (the CLI's ``--accept-unusable-model``), named in the message.
    accept : bool
        Use an unusable model anyway (``flag`` was given).
    use : str
        What the command would do with the model (``"design a controller on it"``), for the message.

    Raises
    ------
    UnusableModelError
        The model is judged unusable and ``accept`` is false: one line naming the reasons and ``flag``.
    """
    if verdict.unusable and not accept:
        raise UnusableModelError(f"{where} is judged unusable: {'; '.join(verdict.reasons)}. Identify it again "
                                 f"from a flight that shows these axes, or {use} anyway with {flag}")
    return verdict


def sensors_from_document(doc: dict, where: str = "model") -> SensorModel:
    """The :class:`~heli_core.sensors.SensorModel` of a model document's dictionary (silent when it has none).

    Raises
    ------
    ModelFileError
        A malformed ``"sensors"`` entry (the message names the field).
    """
    try:
        return SensorModel.from_dict(doc.get("sensors"))
    except ValueError as e:
        raise ModelFileError(f"{where}: {e}") from None


def save_model(path, params: ModelParams, **kwargs) -> Path:
    """Write ``model.json`` atomically; ``path`` may be the file or its directory. Returns the file path.

    A model file already there is first copied to ``history/model-<sha256[:12]>.json``. This writes the one
    file only; a model directory's model and library together are written by
    :meth:`model_store.ModelDir.transaction`, as one step.
    """
    path = Path(path)
    if path.suffix != ".json":
        path = path / MODEL_FILENAME
    text = encode_model(model_document(params, **kwargs))  # an unstorable value fails before anything is touched
    if path.exists():
        keep_copy(path)  # nothing the user had is lost: the model being replaced is kept under history/
    write_text(path, text)
    return path


def encode_model(doc: dict) -> str:
    """The text of ``model.json`` for a model document (strict JSON: no NaN, every value storable)."""
    return json.dumps(jsonable(doc), indent=2, allow_nan=False, default=_unstorable) + "\n"


def _unstorable(obj):
    raise TypeError(f"cannot store {type(obj).__name__} in model.json")


def params_from_document(doc: dict, where: str = "model") -> ModelParams:
    """The :class:`ModelParams` of a model document's dictionary, checked (:meth:`ModelDocument.from_dict`)."""
    return ModelDocument.from_dict(doc, where).params


def _check_schema(doc, where: str) -> None:
    if not isinstance(doc, dict):
        raise ModelFileError(f"{where}: expected a JSON object, got {type(doc).__name__}")
    if doc.get("schema") != SCHEMA:
        raise ModelFileError(f"{where}: expected schema {SCHEMA!r}, got {doc.get('schema')!r}")
    if doc.get("schema_version") != SCHEMA_VERSION:
        raise ModelFileError(
            f"{where}: schema_version {doc.get('schema_version')!r} is not supported; this heli-env reads "
            f"version {SCHEMA_VERSION}"
        )


def _params(doc: dict, where: str) -> ModelParams:
    """The parameters, added terms, servo delays and lags of a document whose schema is checked."""
    params = doc.get("parameters")
    if not isinstance(params, dict):
        raise ModelFileError(f"{where}: 'parameters' must be an object keyed by the paper's names (k1 ... kd3)")
    missing = [k for k in BASE_PARAMS if k not in params]
    if missing:
        raise ModelFileError(f"{where}: missing parameter(s) {missing}; expected all of {', '.join(BASE_PARAMS)}")
    unknown = [k for k in params if k not in BASE_PARAMS]
    if unknown:
        raise ModelFileError(f"{where}: unknown parameter(s) {unknown} in 'parameters'")
    added = doc.get("added_terms") or {}
    if not isinstance(added, dict):
        raise ModelFileError(f"{where}: 'added_terms' must be an object of term name to value, got {type(added).__name__}")
    bad = [k for k in added if k not in EXTRA_PARAMS]
    if bad:
        raise ModelFileError(f"{where}: unknown added term(s) {bad}; known: {', '.join(EXTRA_PARAMS)}")
    delays = doc.get("servo_delay_s") or {}
    if not isinstance(delays, dict) or set(delays) - set(AXES):
        raise ModelFileError(f"{where}: 'servo_delay_s' must be an object with keys among {', '.join(AXES)}, got {delays!r}")
    verdict_of(doc, where)  # a malformed verdict is refused here; a missing one reads as "not judged"
    lags = doc.get("servo_lag_s") or {}
    if not isinstance(lags, dict) or set(lags) - set(AXES):
        raise ModelFileError(f"{where}: 'servo_lag_s' must be an object with keys among {', '.join(AXES)}, got {lags!r}")
    huge = {k: v for k, v in list(params.items()) + list(added.items())
            if isinstance(v, (int, float)) and not isinstance(v, bool) and MAX_PARAMETER < abs(v) < float("inf")}
    if huge:
        raise ModelFileError(f"{where}: parameter(s) beyond any aircraft: " + ", ".join(
            f"{k} = {v:g}" for k, v in huge.items()) + f" (|value| > {MAX_PARAMETER:g} in the model's units, 1/s "
            "and rad/s² per unit stick): the file was edited or corrupted, or its fit failed; identify the model again")
    try:
        return ModelParams(
            **{k: params[k] for k in BASE_PARAMS},
            **{f"tau_{axis}": float(delays.get(axis, 0.0)) for axis in AXES},
            **{f"lag_{axis}": float(lags.get(axis, 0.0)) for axis in AXES},
            extra=tuple(added.items()),
        )
    except (TypeError, ValueError) as e:
        raise ModelFileError(f"{where}: invalid parameter value: {e}") from e


@dataclass(frozen=True)
class Source:
    """A flight a model was fitted on: an entry of ``provenance.sources``.

    Attributes
    ----------
    file : str or None
        The flight file's name (no folder).
    sha256 : str or None
        SHA-256 of its bytes (hex).
    segment : (float, float) or None
        The stretch of a flight-controller log that was fitted, on the log's own clock [s], when the flight was read
        with one given (``--segment``); None: the file as it reads by default (a log's airborne segment found
        automatically, a CSV whole). ``heli refresh`` reads the flight again the same way.
    controller_loop_hz : float or None
        Where the flight's inputs were stated as a flight controller's commands from a loop at this rate [Hz]
        (``--controller-loop``, for a CSV that cannot say so); None: as its file states them. ``heli refresh`` states
        them again when it reads the flight.
    gyro_filter_hz : float or None
        Where the flight's gyro was stated low-passed at this corner [Hz] before its controller read it and its log
        wrote it (``--gyro-filter``); None: as its file states it (an ArduPilot log's ``INS_GYRO_FILTER``).
    """

    file: str | None
    sha256: str | None
    segment: tuple | None = None
    controller_loop_hz: float | None = None
    gyro_filter_hz: float | None = None

    def to_dict(self) -> dict:
        """The ``provenance.sources`` entry (what :func:`identification.workflows.identify.source_entry` writes)."""
        return {"file": self.file, "sha256": self.sha256,
                **({"segment": list(self.segment)} if self.segment is not None else {}),
                **({"controller_loop_hz": self.controller_loop_hz} if self.controller_loop_hz is not None else {}),
                **({"gyro_filter_hz": self.gyro_filter_hz} if self.gyro_filter_hz is not None else {})}


def _sources(provenance, where: str) -> tuple:
    """``provenance.sources``, the one place it is parsed."""
    if provenance is None:
        return ()
    if not isinstance(provenance, dict) or not isinstance(provenance.get("sources", []), list):
        raise ModelFileError(f"{where}: 'provenance' must be an object with a list 'sources', got {provenance!r}")
    out = []
    for i, entry in enumerate(provenance.get("sources", [])):
        if not isinstance(entry, dict) or not all(isinstance(entry.get(k), (str, type(None))) for k in ("file", "sha256")):
            raise ModelFileError(f"{where}: 'provenance.sources[{i}]' must be an object "
                                 f"{{\"file\": name, \"sha256\": hex}}, got {entry!r}")
        segment = entry.get("segment")
        if segment is not None and not (isinstance(segment, list) and len(segment) == 2 and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in segment)
                and segment[0] < segment[1]):
            raise ModelFileError(f"{where}: 'provenance.sources[{i}].segment' must be [t0, t1] in seconds with "
                                 f"t0 < t1, got {segment!r}")
        stated = {key: _positive_hz(entry.get(key), f"{where}: 'provenance.sources[{i}].{key}'", what)
                  for key, what in (("controller_loop_hz", "a loop rate"), ("gyro_filter_hz", "a filter's corner"))}
        out.append(Source(entry.get("file"), entry.get("sha256"),
                          None if segment is None else (float(segment[0]), float(segment[1])), **stated))
    return tuple(out)


def _positive_hz(value, where: str, what: str) -> float | None:
    """``value`` as a frequency in Hz above 0, None where absent; else :class:`ModelFileError` naming ``where``."""
    if value is None:
        return None
    if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
        raise ModelFileError(f"{where} must be {what} in Hz above 0, got {value!r}")
    return float(value)


def _mapping(doc: dict, key: str, where: str, empty: bool = True):
    """A read-only view of object entry ``key`` (when absent or null: an empty one, else None)."""
    value = doc.get(key)
    if value is None:
        return MappingProxyType({}) if empty else None
    if not isinstance(value, dict):
        raise ModelFileError(f"{where}: '{key}' must be an object, got {type(value).__name__}")
    return MappingProxyType(value)


@dataclass(frozen=True, eq=False)
class ModelDocument:
    """A model file's document, read and checked once (``model.json``; the module docstring has its schema).

    Built by :meth:`from_dict`; :meth:`to_dict` gives back the dictionary it was read from, so a document read
    and written again is the same bytes. The entries that are an estimator's own record (``identification``,
    ``filter``, ``fit_statistics``, ``refresh``) are read-only views of theirs.

    Attributes
    ----------
    params : ModelParams
        The parameters, added terms, servo delays and lags.
    structure : str or None
        ``"decoupled"``, ``"coupled"`` or ``"custom"`` (None: not recorded).
    verdict : ModelVerdict
        Whether the model can be used (:data:`model_store.verdict.NOT_JUDGED` when the file has none).
    sensors : SensorModel
        The gyros' and the attitude estimate's noise and vibration lines (silent when the file has none).
    sources : tuple of Source
        The flights the model was fitted on (``provenance.sources``).
    created : str or None
        When the file was written (ISO 8601).
    written_by : str or None
        The heli-env version that wrote it.
    sample_rate : float or None
        The fitted flights' sample rate [Hz].
    identification : Mapping
        The estimator and its settings (``method``, ``estimator``, ``interval`` ...).
    filter_settings : Mapping or None
        The prefilter's settings (Section 3.1), None without one.
    fit_statistics : Mapping
        Per axis (``axes``) R², standard errors, the wind model; the validation on other flights
        (``validation_flights``).
    refresh : Mapping or None
        The record of the refresh that wrote the model (:mod:`identification.workflows.refresh`).
    """

    params: ModelParams
    structure: str | None
    verdict: ModelVerdict
    sensors: SensorModel
    sources: tuple
    created: str | None
    written_by: str | None
    sample_rate: float | None
    identification: Mapping
    filter_settings: Mapping | None
    fit_statistics: Mapping
    refresh: Mapping | None
    _document: Mapping = field(repr=False)

    @classmethod
    def from_dict(cls, doc, where: str = "model") -> "ModelDocument":
        """The typed form of a model document's dictionary (as ``json.load`` gives it), checked.

        Parameters
        ----------
        doc : dict
            The JSON document.
        where : str
            What to call the document in a message (its path).

        Raises
        ------
        ModelFileError
            Wrong schema or version, missing, unknown or impossible parameters, or a malformed verdict, sensors
            entry, provenance or settings entry; the message names the entry.
        """
        _check_schema(doc, where)
        params = _params(doc, where)
        provenance = doc.get("provenance")
        rate = doc.get("sample_rate_hz")
        if rate is not None and (isinstance(rate, bool) or not isinstance(rate, (int, float))):
            raise ModelFileError(f"{where}: 'sample_rate_hz' must be a number or null, got {rate!r}")
        doc = copy.deepcopy(doc)  # the views below are of the document's own copy: a caller's edits do not reach it
        return cls(
            params=params,
            structure=doc.get("structure"),
            verdict=verdict_of(doc, where),
            sensors=sensors_from_document(doc, where),
            sources=_sources(provenance, where),
            created=(provenance or {}).get("created"),
            written_by=(provenance or {}).get("heli_env"),
            sample_rate=None if rate is None else float(rate),
            identification=_mapping(doc, "identification", where),
            filter_settings=_mapping(doc, "filter", where, empty=False),
            fit_statistics=_mapping(doc, "fit_statistics", where),
            refresh=_mapping(doc, "refresh", where, empty=False),
            _document=MappingProxyType(doc),
        )

    def to_dict(self) -> dict:
        """The JSON document (a copy): :func:`encode_model` of it writes the bytes the model was read from."""
        return copy.deepcopy(dict(self._document))

    def __eq__(self, other):
        return isinstance(other, ModelDocument) and self.to_dict() == other.to_dict()

    def __reduce__(self):
        """Pickled as its JSON document (the read-only views cannot be): an :class:`EnvModel
        <heli_env.env_model.EnvModel>` travels to a backend's workers with it."""
        return ModelDocument.from_dict, (self.to_dict(),)

    __hash__ = None

    def with_sensors(self, sensors: SensorModel) -> "ModelDocument":
        """The same document with ``sensors`` stored instead of its own."""
        return ModelDocument.from_dict({**self.to_dict(), "sensors": sensors.to_dict()})

    @property
    def method(self) -> str:
        """The identification method as recorded (``"integral (Fig. 5)"`` when the file names none)."""
        return str(self.identification.get("method", "integral"))

    @property
    def estimator(self) -> str | None:
        """Which estimator identified the model: ``"ml"`` (maximum likelihood), ``"integral"`` (Fig. 5), or None
        for another method. Models written before the maximum-likelihood estimator existed record only
        ``method`` ("integral (Fig. 5)"), or nothing: they are integral-method models."""
        est = self.identification.get("estimator")
        if est is None:
            method = self.method
            est = "ml" if method.startswith("maximum") else ("integral" if method.startswith("integral") else None)
        return est if est in ("ml", "integral") else None

    def axis_statistics(self, axis: str) -> Mapping:
        """The fit statistics of ``axis`` (``"roll"``, ``"pitch"``, ``"yaw"``; empty when none are recorded)."""
        entry = (self.fit_statistics.get("axes") or {}).get(axis)
        return entry if isinstance(entry, Mapping) else MappingProxyType({})

    def std_errors(self) -> dict:
        """The standard errors the fit recorded, every axis' together (parameter name -> value): widened by the
        input hold's doubt where the fit recorded one (``std_errors_with_hold``: the log rejected neither held nor
        interpolated sticks), the Fisher information's elsewhere."""
        out = {}
        for axis in AXES:
            stats = self.axis_statistics(axis)
            out.update(stats.get("std_errors") or {})
            out.update(stats.get("std_errors_with_hold") or {})
        return out

    def hold_in_doubt(self) -> bool:
        """Whether the fit recorded the input hold in doubt (``fit_statistics.input_hold_alternative``)."""
        return bool(self.fit_statistics.get("input_hold_alternative"))

    def wind(self, axis: str):
        """The wind model the maximum-likelihood fit stored for ``axis`` (its dictionary), or None."""
        wind = self.axis_statistics(axis).get("wind")
        return wind if isinstance(wind, Mapping) else None

    @property
    def validation_flights(self) -> tuple:
        """The model's scores on flights it was not fitted on (``fit_statistics.validation_flights`` entries)."""
        return tuple(self.fit_statistics.get("validation_flights") or ())


def decode_model(data: bytes, where: str) -> ModelDocument:
    """The document of a model file's bytes (``where``: its path, for messages).

    Raises
    ------
    ModelFileError
        Invalid UTF-8 or JSON, or a document :meth:`ModelDocument.from_dict` refuses.
    """
    try:
        doc = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ModelFileError(f"{where}: not a readable JSON model file: {e}") from e
    return ModelDocument.from_dict(doc, where)


def read_model_bytes(path: Path) -> bytes:
    """The bytes of the model file at ``path`` (:class:`ModelFileError` when it is missing or unreadable)."""
    if not path.exists():
        raise ModelFileError(f"model file {str(path)!r} does not exist (write one with 'heli identify')")
    try:
        return path.read_bytes()
    except OSError as e:
        raise ModelFileError(f"{path}: not a readable JSON model file: {e}") from e


def load_model(path) -> tuple[ModelParams, ModelDocument]:
    """Read one model file (or the ``model.json`` in a directory), as it is on disk.

    A model folder is read with :meth:`model_store.ModelDir.load`, which also takes the state an interrupted
    write left; this reads the one file given (a file kept in ``history/``, a test's file).

    Returns
    -------
    params : ModelParams
    document : ModelDocument
        The whole document (provenance, statistics, settings).

    Raises
    ------
    ModelFileError
        Missing or unreadable file, invalid JSON, wrong schema or version,
        missing or unknown parameters.
    """
    path = Path(path)
    if path.is_dir():
        path = path / MODEL_FILENAME
    document = decode_model(read_model_bytes(path), str(path))
    return document.params, document
