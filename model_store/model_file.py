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
"""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path

from .errors import ModelFileError
from .verdict import ModelVerdict, verdict_of
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


def sensors_from_document(doc: dict, where: str = "model") -> SensorModel:
    """The :class:`~heli_core.sensors.SensorModel` of a model document (silent when it has none).

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
    """The :class:`ModelParams` of a model document, checked."""
    if not isinstance(doc, dict):
        raise ModelFileError(f"{where}: expected a JSON object, got {type(doc).__name__}")
    if doc.get("schema") != SCHEMA:
        raise ModelFileError(f"{where}: expected schema {SCHEMA!r}, got {doc.get('schema')!r}")
    if doc.get("schema_version") != SCHEMA_VERSION:
        raise ModelFileError(
            f"{where}: schema_version {doc.get('schema_version')!r} is not supported; this heli-env reads "
            f"version {SCHEMA_VERSION}"
        )
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


def load_model(path) -> tuple[ModelParams, dict]:
    """Read a model file (or the ``model.json`` in a directory).

    Returns
    -------
    params : ModelParams
    document : dict
        The whole JSON document (provenance, statistics, settings).

    Raises
    ------
    ModelFileError
        Missing or unreadable file, invalid JSON, wrong schema or version,
        missing or unknown parameters.
    """
    path = Path(path)
    if path.is_dir():
        path = path / MODEL_FILENAME
    if not path.exists():
        raise ModelFileError(f"model file {str(path)!r} does not exist (write one with 'heli identify')")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ModelFileError(f"{path}: not a readable JSON model file: {e}") from e
    return params_from_document(doc, str(path)), doc
