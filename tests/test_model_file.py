"""Tests of :mod:`model_store.model_file`: ``model.json`` round trip, checks and atomic writes.

One ``pytest.raises(ModelFileError, match=...)`` per bad input class; each
match checks that the message says what was expected and what came.
"""

from __future__ import annotations

import json
import math
import pathlib

import numpy as np
import pytest

from heli_core.params import ModelParams
from heli_core.terms import BASE_PARAMS
from model_store.errors import ModelFileError
from model_store.model_file import (
    MODEL_FILENAME,
    SCHEMA,
    SCHEMA_VERSION,
    ModelDocument,
    Source,
    encode_model,
    load_model,
    model_document,
    params_from_document,
    save_model,
)

# Every one of the 15 base parameters non-zero and distinct, delays on all axes, two added terms.
PARAMS = ModelParams(
    **{name: 0.1 * (i + 1) * (-1) ** i for i, name in enumerate(BASE_PARAMS)},
    tau_roll=0.08, tau_pitch=0.07, tau_yaw=0.05, extra=(("nld1", 2.0), ("gs3", -8.1)),
)
SOURCES = [{"file": "hover.csv", "sha256": "ab" * 32}]


def _strict_json(text):
    """Parse as standard JSON: NaN / Infinity tokens are an error."""
    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")

    return json.loads(text, parse_constant=refuse)


def _write(tmp_path, doc, name=MODEL_FILENAME):
    path = tmp_path / name
    path.write_text(json.dumps(doc), encoding="utf-8")  # json.dumps writes NaN as the token NaN
    return path


@pytest.fixture
def doc():
    """A valid model document, to spoil one field at a time."""
    return json.loads(json.dumps(model_document(PARAMS, structure="coupled")))


# ---------------------------------------------------------------------------------------- round trip


def test_save_and_load_round_trip(tmp_path):
    path = save_model(tmp_path, PARAMS, structure="coupled", sample_rate=100.0, sources=SOURCES,
                      identification={"method": "integral (Fig. 5)", "interval": 1.0})
    assert path == tmp_path / MODEL_FILENAME
    params, typed = load_model(path)
    assert params == PARAMS == typed.params  # all 15 parameters, the three delays and the added terms, exactly
    assert (typed.structure, typed.sample_rate, typed.method) == ("coupled", 100.0, "integral (Fig. 5)")
    assert typed.sources == (Source("hover.csv", "ab" * 32),) and typed.estimator == "integral"
    document = typed.to_dict()  # the JSON document as read: what is on disk
    assert list(document["parameters"]) == list(BASE_PARAMS)
    assert document["parameters"] == {k: getattr(PARAMS, k) for k in BASE_PARAMS}
    assert document["added_terms"] == {"gs3": -8.1, "nld1": 2.0}
    assert document["servo_delay_s"] == {"roll": 0.08, "pitch": 0.07, "yaw": 0.05}
    assert (document["schema"], document["schema_version"]) == (SCHEMA, SCHEMA_VERSION)
    assert document["structure"] == "coupled"
    assert document["sample_rate_hz"] == 100.0
    assert document["provenance"]["sources"] == SOURCES
    assert document["units"]["k2"] == "rad/s^2" and document["units"]["nld1"]


def test_load_model_on_a_directory_reads_its_model_json(tmp_path):
    save_model(tmp_path / "run", PARAMS)
    params, _ = load_model(tmp_path / "run")
    assert params == PARAMS


def test_save_model_to_a_named_json_file(tmp_path):
    path = save_model(tmp_path / "roll_only.json", PARAMS)
    assert path == tmp_path / "roll_only.json"
    assert load_model(path)[0] == PARAMS


def test_non_finite_fit_statistics_are_stored_as_null(tmp_path):
    stats = {
        "r2": float("nan"), "condition": float("inf"), "se64": np.float64("nan"), "se32": np.float32("nan"),
        "errors": np.array([0.5, np.nan]), "history": (1.0, -math.inf), "ok": np.float32(0.25),
    }
    path = save_model(tmp_path, PARAMS, fit_statistics={"axes": {"roll": stats}})
    got = _strict_json(path.read_text())["fit_statistics"]["axes"]["roll"]
    assert got == {"r2": None, "condition": None, "se64": None, "se32": None, "errors": [0.5, None],
                   "history": [1.0, None], "ok": 0.25}


def test_standard_errors_read_widened_by_the_holds_doubt_where_the_fit_recorded_one():
    """A refresh's drift table reads the previous model's standard errors: where identify found the log's hold in
    doubt, the ones widened by it (what the report printed), the Fisher information's elsewhere."""
    axes = {"roll": {"std_errors": {"k2": 0.01, "k3": 0.1}, "std_errors_with_hold": {"k2": 0.01, "k3": 0.3}},
            "pitch": {"std_errors": {"k6": 0.02, "k7": 0.2}}}
    plain = ModelDocument.from_dict(model_document(PARAMS, fit_statistics={"axes": axes}))
    assert plain.std_errors() == {"k2": 0.01, "k3": 0.3, "k6": 0.02, "k7": 0.2} and not plain.hold_in_doubt()
    doubt = ModelDocument.from_dict(model_document(PARAMS, fit_statistics={
        "axes": axes, "input_hold_alternative": {"hold": "zoh", "lr": 2.3}}))
    assert doubt.hold_in_doubt()


# ---------------------------------------------------------------------------------------- bad input


def test_missing_file(tmp_path):
    with pytest.raises(ModelFileError, match=r"model file '.*nowhere.json' does not exist"):
        load_model(tmp_path / "nowhere.json")
    with pytest.raises(ModelFileError, match=r"model\.json' does not exist"):
        load_model(tmp_path)  # a directory without model.json


def test_invalid_json(tmp_path):
    path = tmp_path / MODEL_FILENAME
    path.write_text('{"schema": "heli-env/model", "parameters": {', encoding="utf-8")
    with pytest.raises(ModelFileError, match="not a readable JSON model file"):
        load_model(path)


def test_not_an_object(tmp_path):
    with pytest.raises(ModelFileError, match="expected a JSON object, got list"):
        load_model(_write(tmp_path, [1, 2, 3]))


def test_wrong_schema(tmp_path, doc):
    doc["schema"] = "heli-env/disturbance-library"
    with pytest.raises(ModelFileError, match="expected schema 'heli-env/model', got 'heli-env/disturbance-library'"):
        load_model(_write(tmp_path, doc))


def test_wrong_schema_version(tmp_path, doc):
    doc["schema_version"] = 2
    with pytest.raises(ModelFileError, match="schema_version 2 is not supported; this heli-env reads version 1"):
        load_model(_write(tmp_path, doc))


def test_missing_parameters_are_named(tmp_path, doc):
    del doc["parameters"]["k4"], doc["parameters"]["kd2"]
    with pytest.raises(ModelFileError, match=r"missing parameter\(s\) \['k4', 'kd2'\]; expected all of k1, k2"):
        load_model(_write(tmp_path, doc))


def test_parameters_not_an_object(tmp_path, doc):
    doc["parameters"] = [1.0] * 15
    with pytest.raises(ModelFileError, match="'parameters' must be an object keyed by the paper's names"):
        load_model(_write(tmp_path, doc))


def test_unknown_parameter(tmp_path, doc):
    doc["parameters"]["k13"] = 1.0
    with pytest.raises(ModelFileError, match=r"unknown parameter\(s\) \['k13'\] in 'parameters'"):
        load_model(_write(tmp_path, doc))


def test_unknown_added_term(tmp_path, doc):
    doc["added_terms"]["drag9"] = 0.1
    with pytest.raises(ModelFileError, match=r"unknown added term\(s\) \['drag9'\]; known: ct1, ct2, nld1"):
        load_model(_write(tmp_path, doc))


def test_a_servo_lag_is_stored_only_where_there_is_one(tmp_path):
    from heli_core.params import ModelParams
    from model_store.model_file import model_document

    plain = ModelParams(k2=1.3, k3=2.4, tau_roll=0.04)
    assert "servo_lag_s" not in model_document(plain)  # files of servos without a lag stay as they were
    lagged = plain.with_values(lag_roll=0.03, lag_yaw=0.02)
    doc = model_document(lagged)
    assert doc["servo_lag_s"] == {"roll": 0.03, "pitch": 0.0, "yaw": 0.02} and doc["units"]["servo_lag_s"] == "s"
    assert load_model(_write(tmp_path, doc))[0] == lagged
    doc["servo_lag_s"] = {"rol": 0.1}
    with pytest.raises(ModelFileError, match="'servo_lag_s' must be an object with keys among roll, pitch, yaw"):
        load_model(_write(tmp_path, doc))


@pytest.mark.parametrize("section", ["added_terms", "servo_delay_s"])
def test_sections_that_are_not_objects(tmp_path, doc, section):
    doc[section] = [0.1, 0.1, 0.1]
    with pytest.raises(ModelFileError, match=f"'{section}' must be an object"):
        load_model(_write(tmp_path, doc))


def test_unknown_servo_delay_axis(tmp_path, doc):
    doc["servo_delay_s"] = {"rol": 0.1}
    with pytest.raises(ModelFileError, match="'servo_delay_s' must be an object with keys among roll, pitch, yaw"):
        load_model(_write(tmp_path, doc))


@pytest.mark.parametrize(
    "section, name, value, says",
    [
        ("parameters", "k2", float("nan"), "parameter k2 must be a finite number"),
        ("parameters", "k7", float("inf"), "parameter k7 must be a finite number"),
        ("parameters", "k3", "2.4", "parameter k3 must be a finite number, got '2.4'"),
        ("parameters", "kd1", None, "parameter kd1 must be a finite number, got None"),
        ("added_terms", "nld1", float("nan"), "extra term nld1 must be finite"),
        ("servo_delay_s", "roll", 3.0, r"tau_roll must be a delay in \[0, 2\] s, got 3.0"),
        ("servo_delay_s", "yaw", "slow", "could not convert string to float"),
    ],
)
def test_invalid_values(tmp_path, doc, section, name, value, says):
    doc[section][name] = value
    with pytest.raises(ModelFileError, match=f"invalid parameter value: {says}"):
        load_model(_write(tmp_path, doc))


def test_params_from_document_names_where_it_came_from(doc):
    doc["schema_version"] = 0
    with pytest.raises(ModelFileError, match="^library/model: schema_version 0"):
        params_from_document(doc, "library/model")


@pytest.mark.parametrize("folder", [pathlib.Path(__file__).parent / "data" / "ideal_model",
                                    pathlib.Path(__file__).parents[1] / "heli_env" / "data" / "default"])
def test_a_model_folder_reads_into_its_typed_document_and_writes_the_same_bytes(folder):
    """The typed document is the file's one parser; the format on disk is unchanged: read and written again, a
    model written by an earlier heli-env is the same bytes."""
    text = (folder / MODEL_FILENAME).read_text(encoding="utf-8")
    typed = ModelDocument.from_dict(json.loads(text), str(folder))
    assert encode_model(typed.to_dict()) == text
    raw = json.loads(text)
    assert [s.to_dict() for s in typed.sources] == raw["provenance"]["sources"]
    assert typed.params == params_from_document(raw) and typed.structure == raw["structure"]
    assert typed.estimator in ("ml", "integral") and typed.sample_rate == raw["sample_rate_hz"]
    assert typed == ModelDocument.from_dict(json.loads(text)) and typed.to_dict() is not typed.to_dict()


def test_the_typed_document_pickles_as_itself(doc):
    """An EnvModel, and so its document, is pickled to a backend's worker processes."""
    import pickle

    typed = ModelDocument.from_dict(doc)
    again = pickle.loads(pickle.dumps(typed))
    assert again == typed and again.params == typed.params and again.verdict == typed.verdict


def test_the_typed_document_is_its_own_copy(doc):
    typed = ModelDocument.from_dict(doc)
    doc["identification"]["method"] = "edited"
    with pytest.raises(TypeError):
        typed.identification["method"] = "edited"  # a read-only view
    assert typed.method != "edited" and typed.to_dict()["identification"] != doc["identification"]


@pytest.mark.parametrize("provenance, says", [
    ([1, 2], "'provenance' must be an object with a list 'sources'"),
    ({"sources": "flight.csv"}, "'provenance' must be an object with a list 'sources'"),
    ({"sources": [{"file": 3, "sha256": "ab"}]}, r"'provenance.sources\[0\]' must be an object"),
])
def test_malformed_provenance_is_refused_naming_the_entry(tmp_path, doc, provenance, says):
    doc["provenance"] = provenance
    with pytest.raises(ModelFileError, match=says):
        load_model(_write(tmp_path, doc))


# ---------------------------------------------------------------------------------------- atomic write


def test_a_failed_write_leaves_the_old_model_untouched(tmp_path, monkeypatch):
    path = save_model(tmp_path, PARAMS)
    before = path.read_bytes()

    def write_half_then_fail(self, text, *args, **kwargs):
        with open(self, "w", encoding="utf-8") as fh:
            fh.write(text[: len(text) // 2])
        raise OSError("No space left on device")

    monkeypatch.setattr(pathlib.Path, "write_text", write_half_then_fail)
    with pytest.raises(OSError, match="No space left"):
        save_model(tmp_path, PARAMS.with_values(k2=99.0))
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["history", MODEL_FILENAME]  # no stray temporary file
    (backup,) = (tmp_path / "history").iterdir()  # the model about to be replaced was kept first
    assert backup.read_bytes() == before
    assert load_model(tmp_path)[0] == PARAMS


def test_an_unstorable_value_writes_nothing(tmp_path):
    with pytest.raises(TypeError, match="cannot store object in model.json"):
        save_model(tmp_path, PARAMS, identification={"settings": object()})
    assert list(tmp_path.iterdir()) == []


def test_a_parameter_beyond_any_aircraft_is_refused(tmp_path, doc):
    """k3 = 1e300 (finite, so the params' own check passed it) overflowed the discretised model into NaN states
    that `heli tune` flew; a model file with it is now refused where it is read."""
    doc["parameters"]["k3"] = 1e300
    with pytest.raises(ModelFileError, match=r"parameter\(s\) beyond any aircraft: k3 = 1e\+300 \(\|value\| > 1e\+06"):
        load_model(_write(tmp_path, doc))
    doc["parameters"]["k3"] = 200.0  # the search's bound stays readable (its verdict says what it is)
    load_model(_write(tmp_path, doc))


def test_a_nan_coefficient_compiles_into_the_physics_as_nan():
    """A coefficient that overflowed is written as an expression the generated step can run (it was the bare
    name 'nan', a NameError), so what flies it sees NaN states, not a crash."""
    from heli_core.physics import _fmt

    assert eval(_fmt(float("nan"))) != eval(_fmt(float("nan")))
    assert eval(_fmt(float("-inf"))) == float("-inf") and eval(_fmt(0.1)) == 0.1
