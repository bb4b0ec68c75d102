"""A log identified as a stretch the user named (``--segment``) is recorded so in the model's sources, and
``heli refresh`` reads it again as that stretch: without it the refit of the previous flights would read the log's
automatic airborne segment, another stretch of the same file (or none at all)."""

from __future__ import annotations

import json
from argparse import Namespace
from pathlib import Path

import pytest

from heli_core.params import ModelParams
from identification.workflows.identify import source_entry
from identification.workflows.refresh import _read_flights
from identification.workflows.refresh_sources import find_source_flights
from model_store.errors import ModelFileError
from model_store.model_file import Source, load_model, save_model

LOGS = Path(__file__).resolve().parents[2] / "shared" / "fixtures" / "logs"


def test_a_sources_segment_round_trips_and_a_bad_one_is_refused(tmp_path):
    csv = tmp_path / "hover.csv"
    csv.write_text("flight\n")
    entry = source_entry(csv, segment=(20.0, 27.5))
    assert entry["segment"] == [20.0, 27.5] and "segment" not in source_entry(csv)
    path = save_model(tmp_path, ModelParams(), structure="decoupled", sample_rate=100.0, sources=[entry])
    _, typed = load_model(path)
    assert typed.sources == (Source("hover.csv", entry["sha256"], (20.0, 27.5)),)
    assert typed.sources[0].to_dict() == entry
    doc = json.loads(path.read_text())
    for bad in ([27.5, 20.0], [20.0], ["a", 1.0], [0.0, float("inf")]):
        doc["provenance"]["sources"][0]["segment"] = bad
        path.write_text(json.dumps(doc))
        with pytest.raises(ModelFileError, match="segment' must be"):
            load_model(path)


def test_a_found_source_keeps_its_segment(tmp_path):
    log = tmp_path / "flight.bin"
    log.write_bytes(b"log bytes")
    entry = source_entry(log, segment=(3.0, 9.0))
    found, missing = find_source_flights([Source(entry["file"], entry["sha256"], (3.0, 9.0)),
                                          Source(entry["file"], entry["sha256"])], [tmp_path])
    assert not missing and found[0]["segment"] == (3.0, 9.0) and "segment" not in found[1]


def test_identify_records_the_stretch_it_read_only_when_one_was_given():
    from identification.workflows.identify import segment_read

    flight = Namespace(metadata={"segment": [17.5, 36.25], "segment_mode": "all"})
    assert segment_read("all", flight) == (17.5, 36.25)
    assert segment_read(None, flight) is None  # the default: reads the same again


@pytest.mark.skipif(not LOGS.is_dir(), reason="needs ../shared/fixtures/logs (the shared fixtures are absent)")
def test_refresh_reads_a_previous_log_as_the_stretch_its_model_recorded():
    from identification.io.errors import NotAirborneError

    log = LOGS / "rotorflight_k110_LOG246.TXT"
    with pytest.raises(NotAirborneError):  # the default reading: no airborne segment in this log
        _read_flights([log], "previous", False)
    flight, = _read_flights([log], "previous", False, [(20.0, 27.0)])
    assert flight.duration == pytest.approx(7.0, abs=0.05)


def test_a_stated_controller_loop_round_trips_is_found_and_read_so_again(tmp_path):
    """``--controller-loop HZ`` is recorded in the source (a CSV cannot state it), and the refresh's reader states the
    flight's inputs so again; a rate not above 0 is refused when the model is read."""
    from identification.bench.synthetic import simulate_flight
    from identification.validation.fit_warnings import input_source

    csv = tmp_path / "ap.csv"
    simulate_flight(duration=5.0, seed=1).save(csv)
    entry = source_entry(csv, controller_loop_hz=400)
    assert entry["controller_loop_hz"] == 400.0 and "controller_loop_hz" not in source_entry(csv)
    path = save_model(tmp_path, ModelParams(), structure="decoupled", sample_rate=100.0, sources=[entry])
    _, typed = load_model(path)
    assert typed.sources == (Source("ap.csv", entry["sha256"], None, 400.0),)
    assert typed.sources[0].to_dict() == entry
    found, missing = find_source_flights(typed.sources, [tmp_path])
    assert not missing and found[0]["controller_loop_hz"] == 400.0
    stated, plain = _read_flights([csv, csv], "previous", False, None, [400.0, None])
    assert input_source(stated.metadata) == ("flight controller commands", 400.0)
    assert input_source(plain.metadata) == ("sticks", None)  # as simulate_flight wrote it
    doc = json.loads(path.read_text())
    for bad in (0, -5.0, "400", True):
        doc["provenance"]["sources"][0]["controller_loop_hz"] = bad
        path.write_text(json.dumps(doc))
        with pytest.raises(ModelFileError, match="controller_loop_hz' must be a loop rate in Hz above 0"):
            load_model(path)
