"""Tests of model_store.disturbance_library: versions, validation on read, crash safety."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from heli_core.files import sha256_of
from identification.bench.synthetic import simulate_flight
from identification.disturbance.equivalent_input import identify_disturbance
from identification.integral.method import IntegralIdentifier
from model_store.disturbance_library import COLUMNS, DisturbanceLibrary, Trace, manifest_name
from model_store.errors import LibraryError

REPO = Path(__file__).resolve().parents[1]


def _trace(n=501, fs=50.0, seed=0, **metadata) -> Trace:
    rng = np.random.default_rng(seed)
    time = np.arange(n) / fs
    return Trace(time, 0.05 * rng.standard_normal((3, n)), 0.2 + 0.01 * rng.standard_normal(n),
                 {"source": {"name": f"test-{seed}", "sha256": "0" * 64, "sha256_of": "arrays"}, **metadata})


@pytest.fixture(scope="session")
def profiles():
    """Disturbance profiles of two short synthetic flights (default settings)."""
    out = []
    for seed in (5, 6):
        sf = simulate_flight(30, seed=seed)
        params = IntegralIdentifier().fit(sf.flight).params_
        out.append(identify_disturbance(sf.flight, params, simulate=False))
    return out


@pytest.fixture
def library(tmp_path):
    lib = DisturbanceLibrary.create(tmp_path)
    assert lib.append(_trace(seed=1)) == 1
    return lib


# ------------------------------------------------------------------ round trip
def test_profile_round_trip(tmp_path, profiles):
    prof = profiles[0]
    lib = DisturbanceLibrary.create(tmp_path)
    assert lib.latest_version is None
    v = lib.append(prof, model_sha256="ab" * 32, metadata={"flight": "seed5.csv"})
    assert v == 1 and lib.versions() == [1] and lib.latest_version == 1
    (trace,) = DisturbanceLibrary.open(tmp_path).load()
    assert_array_equal(trace.ud, prof.trace)
    assert_array_equal(trace.collective, prof.collective)
    assert_array_equal(trace.time, prof.time)
    assert trace.sample_rate == pytest.approx(100.0)
    m = trace.metadata
    assert m["n_samples"] == prof.time.size
    assert m["interval_s"] == pytest.approx(prof.interval)
    assert m["smoothing"]["passes"] == {"roll": 5, "pitch": 5, "yaw": 5}
    assert m["source"] == prof.source
    assert m["model"]["sha256"] == "ab" * 32
    assert m["model"]["parameters"]["k2"] == pytest.approx(prof.params.k2)
    assert m["metadata"] == {"flight": "seed5.csv"}
    assert m["statistics"]["roll"]["std"] == pytest.approx(prof.trace[0].std())
    assert m["file"] == f"traces/{m['sha256']}.npy"
    assert sha256_of(lib.path / m["file"]) == m["sha256"]
    doc = lib.manifest()
    assert doc["columns"] == list(COLUMNS) and doc["previous"] is None


def test_two_flights_append_and_previous_version_is_kept(tmp_path, profiles):
    lib = DisturbanceLibrary.create(tmp_path)
    lib.append(profiles[0])
    v1 = lib.path / manifest_name(1)
    before = v1.read_bytes()
    assert lib.append(profiles[1]) == 2
    assert v1.read_bytes() == before  # never rewritten
    assert lib.versions() == [1, 2]
    assert len(lib.load(1)) == 1
    latest = lib.load()
    assert len(latest) == 2
    assert [t.metadata["added_in_version"] for t in latest] == [1, 2]
    assert [t.metadata["source"]["name"] for t in latest] == [p.source["name"] for p in profiles]
    assert lib.manifest(2)["previous"] == {"file": manifest_name(1), "sha256": sha256_of(v1)}


def test_append_many_and_duplicates(library):
    assert library.append([_trace(seed=2), _trace(seed=3)]) == 2
    assert len(library.load()) == 3
    # the same trace again: nothing new, nothing written
    assert library.append(_trace(seed=2)) == 2
    assert library.versions() == [1, 2]


def test_loaded_traces_can_seed_another_library(library, tmp_path):
    other = DisturbanceLibrary.create(tmp_path / "other")
    assert other.append(library.load()) == 1
    assert_array_equal(other.load()[0].ud, library.load()[0].ud)


def test_create_refuses_an_existing_library(library):
    with pytest.raises(LibraryError, match="already holds a disturbance library"):
        DisturbanceLibrary.create(library.root)


def test_open_missing_and_empty(tmp_path):
    with pytest.raises(LibraryError, match="no disturbance library at"):
        DisturbanceLibrary.open(tmp_path / "nowhere")
    lib = DisturbanceLibrary.open(tmp_path / "new", create=True)
    with pytest.raises(LibraryError, match="is empty"):
        lib.load()


def test_unknown_version(library):
    with pytest.raises(LibraryError, match=r"has no version 7; versions present: \[1\]"):
        library.load(7)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"ud": np.zeros((2, 5))}, r"ud must have shape \(3, 5\)"),
        ({"collective": np.zeros(4)}, r"collective must have shape \(5,\)"),
        ({"time": np.array([0.0, 0.1, 0.2, 0.4, 0.5])}, "uniformly sampled"),
        ({"ud": np.full((3, 5), np.nan)}, "non-finite"),
    ],
)
def test_bad_trace(kwargs, match):
    args = {"time": np.arange(5) * 0.1, "ud": np.zeros((3, 5)), "collective": np.zeros(5)} | kwargs
    with pytest.raises(LibraryError, match=match):
        Trace(**args)


# -------------------------------------------------------------- read validation
def _entry_path(lib, version=1, k=0):
    doc = lib.manifest(version)
    return lib.path / doc["traces"][k]["file"], doc


def _edit_manifest(lib, version, fn):
    path = lib.path / manifest_name(version)
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))


def test_checksum_mismatch(library):
    path, doc = _entry_path(library)
    data = bytearray(path.read_bytes())
    data[-1] ^= 0x01  # one bit of the last collective sample
    path.write_bytes(bytes(data))
    with pytest.raises(LibraryError, match=rf"{path.name}: SHA-256 is [0-9a-f]{{64}}, manifest-v0001.json expects "
                                           rf"{doc['traces'][0]['sha256']}"):
        library.load()


def test_length_mismatch(library):
    _edit_manifest(library, 1, lambda d: d["traces"][0].update(n_samples=500))
    with pytest.raises(LibraryError, match="trace has 501 samples, manifest-v0001.json expects 500"):
        library.load()


def test_length_mismatch_of_a_replaced_file(library):
    path, _ = _entry_path(library)
    path.write_bytes(_trace(n=300, seed=1).to_bytes())
    with pytest.raises(LibraryError, match="trace has 300 samples, manifest-v0001.json expects 501"):
        library.load()


def test_sample_rate_mismatch(library):
    _edit_manifest(library, 1, lambda d: d["traces"][0].update(sample_rate_hz=100.0))
    with pytest.raises(LibraryError, match="sampled at 50 Hz, manifest-v0001.json expects 100 Hz"):
        library.load()


def test_missing_trace_file(library):
    path, doc = _entry_path(library)
    path.unlink()
    with pytest.raises(LibraryError, match=f"{path.name}: trace file listed in manifest-v0001.json is missing"):
        library.load()


def test_unreadable_trace_file(library):
    path, _ = _entry_path(library)
    path.write_bytes(b"not a numpy file")
    with pytest.raises(LibraryError, match="expected a .npy trace file"):
        library.load()


def test_corrupt_manifest(library):
    path = library.path / manifest_name(1)
    path.write_text(path.read_text()[:100])
    with pytest.raises(LibraryError, match="manifest-v0001.json: expected a JSON manifest"):
        library.load()
    # nothing is written on top of a corrupt manifest
    with pytest.raises(LibraryError, match="expected a JSON manifest"):
        library.append(_trace(seed=9))
    assert library.versions() == [1]


def test_unknown_schema_version(library):
    _edit_manifest(library, 1, lambda d: d.update(schema_version=2))
    with pytest.raises(LibraryError, match="schema_version 2 is not supported; this heli-env reads version 1"):
        library.load()


def test_wrong_schema_and_version_field(library):
    _edit_manifest(library, 1, lambda d: d.update(version=3))
    with pytest.raises(LibraryError, match='expected "version": 1 \\(from the file name\\), got 3'):
        library.load()
    _edit_manifest(library, 1, lambda d: d.update(version=1, schema="something/else"))
    with pytest.raises(LibraryError, match="expected schema 'heli-env/disturbance-library'"):
        library.load()


def test_trace_path_must_stay_in_the_library(library):
    _edit_manifest(library, 1, lambda d: d["traces"][0].update(file="../../etc/passwd"))
    with pytest.raises(LibraryError, match="file must be 'traces/<sha256>.npy'"):
        library.load()


# ---------------------------------------------------------------- crash safety
_CHILD = r"""
import pathlib, sys, time
import numpy as np
from model_store.disturbance_library import DisturbanceLibrary, Trace

root, flag, phase = sys.argv[1], pathlib.Path(sys.argv[2]), sys.argv[3]
original = {"trace": pathlib.Path.write_bytes, "manifest": pathlib.Path.write_text}[phase]

def slow_write(self, data, *args, **kwargs):
    # write half, tell the parent, then hang until killed
    half = data[: len(data) // 2]
    with open(self, "wb" if isinstance(data, bytes) else "w") as fh:
        fh.write(half)
        fh.flush()
    flag.touch()
    time.sleep(120)
    return original(self, data, *args, **kwargs)

setattr(pathlib.Path, {"trace": "write_bytes", "manifest": "write_text"}[phase], slow_write)
rng = np.random.default_rng(42)
n = 2001
trace = Trace(np.arange(n) / 100.0, 0.05 * rng.standard_normal((3, n)), np.full(n, 0.2))
DisturbanceLibrary.open(root).append(trace)
"""


@pytest.mark.parametrize("phase", ["trace", "manifest"])
def test_killed_writer_leaves_previous_version_intact(library, tmp_path, phase):
    before = library.load()
    manifest_bytes = (library.path / manifest_name(1)).read_bytes()
    flag = tmp_path / "writing"
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen([sys.executable, "-c", _CHILD, str(library.root), str(flag), phase], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while not flag.exists():
            if proc.poll() is not None:
                pytest.fail(f"writer exited early: {proc.stderr.read().decode()}")
            if time.monotonic() > deadline:
                pytest.fail("writer never reached the write")
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    # a half-written temporary file is there, but no new version and the old one is untouched
    assert list(library.path.rglob(".*.tmp"))
    assert library.versions() == [1]
    assert (library.path / manifest_name(1)).read_bytes() == manifest_bytes
    after = library.load()
    assert len(after) == len(before) == 1
    assert_array_equal(after[0].ud, before[0].ud)
    # killed after the trace file was complete: it is an orphan, reused by the next append
    assert len(library.orphans()) == (1 if phase == "manifest" else 0)
    assert library.append(_trace(seed=8)) == 2
    assert len(library.load()) == 2
