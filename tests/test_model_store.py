"""Tests of :mod:`model_store`: the model directory read as one state and written as one transaction.

Fault injection (:mod:`model_store.faults`) stops a real ``refresh`` and a real ``identify`` into an existing
folder after each of its file events in turn, as a kill would; the folder must then read as the state before or
after, and the next run must succeed. Flights are 30 s and identified by the integral method, so that each
write costs a fraction of a second.
"""

from __future__ import annotations

import json
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from heli_cli.main import main
from heli_env import load_env_model
from heli_env.env_model import default_model_dir
from identification.bench.synthetic import simulate_flight
from identification.io import read_flight
from identification.workflows.identify import identify_and_report
from identification.workflows.refresh import refresh_model
from identification.workflows.refresh_sources import DuplicateFlightError
from model_store import DisturbanceLibrary, ModelDir, Trace, faults
from model_store.errors import LibraryError, ModelDirBusyError, ModelFileError
from model_store.model_file import load_model

DURATION = 30.0


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    folder = tmp_path_factory.mktemp("store_flights")
    for seed in (1, 2, 3, 4, 5):
        simulate_flight(duration=DURATION, seed=seed).save(folder / f"f{seed}.csv")
    return {seed: folder / f"f{seed}.csv" for seed in (1, 2, 3, 4, 5)}


def _identify(flight_paths, out, **kwargs):
    return identify_and_report([read_flight(p) for p in flight_paths], out, method="integral", plots=False,
                               progress=False, flight_paths=[str(p) for p in flight_paths],
                               sources=[{"file": Path(p).name, "sha256": ""} for p in flight_paths], **kwargs)


def _refresh(out, flight, **kwargs):
    return refresh_model(out, [flight], n_replicates=4, plots=False, progress=False, **kwargs)


@pytest.fixture(scope="module")
def base(flights, tmp_path_factory):
    """A folder identified from f1 (kept pristine; tests work on copies)."""
    out = tmp_path_factory.mktemp("store_base") / "DIR"
    _identify([flights[1]], out)
    return out


@pytest.fixture
def folder(base, tmp_path):
    out = tmp_path / "DIR"
    shutil.copytree(base, out)
    return out


@pytest.fixture(autouse=True)
def _disarmed():
    faults.arm(None)
    yield
    faults.arm(None)


def _trace(seed: int, n: int = 301) -> Trace:
    rng = np.random.default_rng(seed)
    return Trace(np.arange(n) / 50.0, 0.05 * rng.standard_normal((3, n)), np.full(n, 0.2),
                 {"source": {"name": f"t{seed}", "sha256": f"{seed:064x}", "sha256_of": "arrays"}})


def _consistent(out: Path):
    """The folder's state, checked: the model and library read as one, the env loads it, legacy readers agree."""
    state = ModelDir(out).load()
    env = load_env_model(out)
    assert env.library_version == state.library_version
    assert_allclose(env.params.values()["k2"], state.params.values()["k2"])
    return state


# ---------------------------------------------------------------------------------------- reading


def test_a_folder_written_by_the_previous_version_loads(tmp_path):
    out = tmp_path / "shipped"
    shutil.copytree(default_model_dir(), out)
    state = ModelDir(out).load()
    params, doc = load_model(out)
    assert state.params.values() == params.values() and state.document == doc
    assert state.library_version == DisturbanceLibrary.open(out).latest_version
    assert len(state.traces) == len(DisturbanceLibrary.open(out).load()) and state.pending is None
    # a transaction on it keeps the format the previous version reads: model.json and the latest manifest
    with ModelDir(out, notify=lambda m: None).transaction() as tx:
        tx.write_model(params.with_values(k3=1.5 * params.k3), structure="decoupled")
        version = tx.add_traces([_trace(1)])
    assert version == state.library_version + 1
    assert load_model(out)[0].k3 == pytest.approx(1.5 * params.k3)
    assert DisturbanceLibrary.open(out).latest_version == version
    assert ModelDir(out).verify() == []
    assert (out / "history" / f"model-{state.model_sha256[:12]}.json").read_bytes() == \
        (default_model_dir() / "model.json").read_bytes()


def test_the_shipped_model_loads_without_writing_into_the_package():
    before = sorted(p.name for p in default_model_dir().iterdir())
    assert load_env_model().n_traces >= 1
    assert sorted(p.name for p in default_model_dir().iterdir()) == before


# ---------------------------------------------------------------------------------------- fault injection


def _events(run) -> int:
    faults.arm(None)
    run()
    return faults.count()


def _run_until(n: int, run) -> bool:
    """Run with the fault armed at event ``n``; True when it struck (False: the run finished first)."""
    faults.arm(n)
    try:
        run()
    except faults.InjectedFault:
        return True
    finally:
        faults.arm(None)
    return False


@pytest.mark.slow
def test_refresh_killed_at_every_file_event_reads_old_or_new_and_runs_again(base, flights, tmp_path):
    old_sha = ModelDir(base).load().model_sha256
    probe = tmp_path / "probe"
    shutil.copytree(base, probe)
    total = _events(lambda: _refresh(probe, flights[2]))
    assert total >= 8
    kinds = []
    for n in range(1, total + 1):
        out = tmp_path / f"n{n}"
        shutil.copytree(base, out)
        assert _run_until(n, lambda: _refresh(out, flights[2]))
        state = _consistent(out)  # a reader, before anything is repaired
        if state.model_sha256 == old_sha:
            kinds.append("old")
            assert state.library_version == 1
            assert refresh_model(out, [flights[2]], n_replicates=4, plots=False, progress=False).library_version == 2
        else:
            kinds.append("new")
            assert state.library_version == 2 and state.document.refresh is not None
            assert state.entries[-1]["model"]["sha256"] == state.model_sha256
            with pytest.raises(DuplicateFlightError):  # done already: the same flight again is a duplicate
                refresh_model(out, [flights[2]], n_replicates=4, plots=False, progress=False)
        assert ModelDir(out).verify() == [], n
        assert (out / "history" / f"model-{old_sha[:12]}.json").is_file()
        assert json.loads((out / "refresh.json").read_text())["model_sha256"] == ModelDir(out).load().model_sha256
    assert "old" in kinds and "new" in kinds


@pytest.mark.slow  # over 5 s: make test-slow
def test_identify_into_an_existing_folder_killed_at_every_file_event(base, flights, tmp_path):
    old_sha = ModelDir(base).load().model_sha256
    probe = tmp_path / "probe"
    shutil.copytree(base, probe)
    total = _events(lambda: _identify([flights[3]], probe))
    kinds = []
    for n in range(1, total + 1):
        out = tmp_path / f"n{n}"
        shutil.copytree(base, out)
        assert _run_until(n, lambda: _identify([flights[3]], out))
        state = _consistent(out)
        kinds.append("old" if state.model_sha256 == old_sha else "new")
        assert state.library_version == (1 if kinds[-1] == "old" else 2)
        pending, notes = (out / ".heli-journal.json").exists(), []
        with ModelDir(out, notify=notes.append).transaction():
            pass
        assert len(notes) == int(pending)  # the interrupted write is finished or rolled back, and said so
        assert ("finished" if kinds[-1] == "new" else "rolled back") in "".join(notes) or not pending
        assert _identify([flights[3]], out).library_version == 2  # the same trace again: no new version
        assert ModelDir(out).verify() == []
        assert (out / "history" / f"model-{old_sha[:12]}.json").is_file()
    assert "old" in kinds and "new" in kinds


# ---------------------------------------------------------------------------------------- writers


def test_two_concurrent_refreshes_are_both_recorded(folder, flights):
    errors = []

    def refresh(flight):
        try:
            _refresh(folder, flight)
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=refresh, args=(flights[k],)) for k in (2, 4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    state = ModelDir(folder).load()
    assert state.library_version == 3
    assert sorted(e["source"]["name"] for e in state.entries) == ["f1.csv", "f2.csv", "f4.csv"]
    # the second refresh started from the first one's model: a chain back to the identified model
    second = state.document.refresh
    first_doc = json.loads((folder / second["previous_model"]["kept_as"]).read_text())
    assert {second["new_sources"][0]["file"], first_doc["refresh"]["new_sources"][0]["file"]} == {"f2.csv", "f4.csv"}
    assert (folder / first_doc["refresh"]["previous_model"]["kept_as"]).is_file()


def test_concurrent_writers_take_turns_and_lose_nothing(folder):
    def write(k):
        with ModelDir(folder, notify=lambda m: None).transaction(what=f"writer {k}") as tx:
            doc = tx.base.document.to_dict()
            doc["writers"] = list(doc.get("writers", [])) + [k]
            tx.write_model_document(doc)
            tx.add_traces([_trace(100 + k)])

    threads = [threading.Thread(target=write, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    state = ModelDir(folder).load()
    assert sorted(state.document.to_dict()["writers"]) == list(range(8))
    assert state.library_version == 9 and len(state.traces) == 9
    models = list((folder / "history").glob("model-*.json"))
    assert len(models) == 8  # every model replaced: the identified one and seven of the eight written


def test_a_busy_folder_is_refused_when_asked_not_to_wait(folder, flights):
    holding, release = threading.Event(), threading.Event()

    def hold():
        with ModelDir(folder).transaction(what="a test"):
            holding.set()
            release.wait(30)

    t = threading.Thread(target=hold)
    t.start()
    try:
        assert holding.wait(30)
        with pytest.raises(ModelDirBusyError, match=r"being written by pid \d+ \(a test"):
            _refresh(folder, flights[2], wait=False)
        assert main(["refresh", str(folder), str(flights[2]), "--no-wait", "--no-plots", "--bootstrap", "4"]) == 2
    finally:
        release.set()
        t.join()


def test_history_keeps_every_replaced_model(folder):
    shas = {ModelDir(folder).load().model_sha256}
    for k in range(4):
        with ModelDir(folder).transaction() as tx:
            tx.write_model(tx.base.params.with_values(k3=tx.base.params.k3 * (1.1 + k)), structure="decoupled")
        shas.add(ModelDir(folder).load().model_sha256)
    current = ModelDir(folder).load().model_sha256
    kept = {p.name for p in (folder / "history").glob("model-*.json")}
    assert kept == {f"model-{s[:12]}.json" for s in shas - {current}} and len(kept) == 4


def test_a_failed_write_changes_nothing(folder, monkeypatch):
    def files():
        return {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*")
                if p.is_file() and not p.name.startswith(".heli") and p.parent.name != "history"}

    before = files()

    def disk_full(*args, **kwargs):
        raise OSError("No space left on device")

    monkeypatch.setattr(DisturbanceLibrary, "_write_trace_file", disk_full)
    with pytest.raises(OSError, match="No space left"):
        with ModelDir(folder).transaction() as tx:
            tx.write_model(tx.base.params.with_values(k3=2.0), structure="decoupled")
            tx.add_traces([_trace(7)])
            tx.write_report("report.md", "new")
    assert files() == before
    assert ModelDir(folder).verify() == []


# ---------------------------------------------------------------------------------------- verify before append


def _flip_a_byte(out: Path) -> Path:
    trace = next((out / "disturbances" / "traces").glob("*.npy"))
    data = bytearray(trace.read_bytes())
    data[-3] ^= 0x01
    trace.write_bytes(bytes(data))
    return trace


def test_a_corrupt_trace_is_refused_for_writing_with_the_readers_error(folder, flights):
    _flip_a_byte(folder)
    before = (folder / "model.json").read_bytes()
    with pytest.raises(LibraryError, match="SHA-256 is .* expects") as read:
        ModelDir(folder).load()
    with pytest.raises(LibraryError, match="SHA-256 is .* expects") as refresh:
        _refresh(folder, flights[2])
    with pytest.raises(LibraryError, match="SHA-256 is .* expects"):
        _identify([flights[3]], folder)
    assert type(refresh.value) is type(read.value)
    assert (folder / "model.json").read_bytes() == before
    assert DisturbanceLibrary.open(folder).versions() == [1]


# ---------------------------------------------------------------------------------------- heli check


def test_heli_check_rolls_back_an_interrupted_write_and_names_corruption(folder, capsys):
    assert _run_until(4, lambda: _write_one(folder))
    assert (folder / ".heli-journal.json").is_file()
    assert main(["check", str(folder), "--no-repair"]) == 2
    assert "interrupted" in capsys.readouterr().out
    assert main(["check", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "rolled back" in out and "consistent" in out
    assert not (folder / ".heli-journal.json").exists() and not (folder / ".heli-staging").exists()
    _flip_a_byte(folder)
    assert main(["check", str(folder)]) == 2
    assert "SHA-256" in capsys.readouterr().out


def _write_one(out):
    with ModelDir(out, notify=lambda m: None).transaction() as tx:
        tx.write_model(tx.base.params.with_values(k3=3.0), structure="decoupled")
        tx.add_traces([_trace(9)])
        tx.write_report("report.md", "interrupted")


def test_a_journal_that_cannot_be_read_is_named(folder):
    (folder / ".heli-journal.json").write_text("{")
    with pytest.raises(ModelFileError, match="journal of an interrupted write"):
        ModelDir(folder).load()


def test_a_trace_staged_twice_is_written_once(folder):
    with ModelDir(folder).transaction() as tx:
        assert tx.add_traces([_trace(5)]) == 2
        assert tx.add_traces([_trace(5)]) == 2
    state = ModelDir(folder).load()
    assert len(state.traces) == 2
    assert_array_equal(state.traces[-1].ud, _trace(5).ud)


def test_heli_check_of_a_file_checks_a_flight_or_says_what_it_expected(tmp_path, capsys):
    """Issue 31: 'heli check flight.csv' said the (existing) file did not exist."""
    from heli_cli.main import main
    from identification.bench.synthetic import simulate_flight

    flight = tmp_path / "flight.csv"
    simulate_flight(5, seed=1).save(flight)
    assert main(["check", str(flight)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{flight}: a valid flight, not a model folder: ") and "does not exist" not in out
    (tmp_path / "bad.csv").write_text("time,p\n0,1\n")
    assert main(["check", str(tmp_path / "bad.csv")]) == 2
    err = capsys.readouterr().err
    assert "expected a model folder (written by 'heli identify'), got the file" in err
    assert "a CSV that is not a valid flight: " in err and "missing required column" in err
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "model.json").write_text("{}")
    assert main(["check", str(tmp_path / "m" / "model.json")]) == 2
    assert f"check the folder that holds it: heli check {tmp_path / 'm'}" in capsys.readouterr().err
