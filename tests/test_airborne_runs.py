"""Every airborne run of a log as a flight of its own (``heli import --segment each``,
:func:`identification.io.read_log_runs`), and the note that a default import leaves runs out.

On the real Betaflight flash dump of ``../shared/fixtures/logs`` (skipped, saying why, when absent): its
chosen log holds four airborne runs (6, 78, 30 and 19 s), of which the default import keeps the longest.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from test_import_logs import _fixture

import identification.io as io
from heli_cli.main import main
from identification.flight import Flight, make_flight
from identification.io import SegmentError, read_log_runs, write_csv_flight
from identification.io.raw_log import to_flight, to_flights
from identification.io.segment import MIN_AIRBORNE_S, TRIM_S
from identification.validation.fit_warnings import MIN_DURATION_S, fit_warnings

MULTI_RUN = "betaflight_multi_btfl_all.bbl"


@pytest.fixture(scope="module")
def multi_run():
    """The flash dump's path and its chosen log decoded once (it decodes 44 logs: seconds)."""
    path = _fixture(MULTI_RUN, "orangebox")
    return path, io._load_raw(path, "blackbox", False)


def test_each_airborne_run_is_a_flight_and_the_longest_is_the_default_import(multi_run):
    _, raw = multi_run
    longest = to_flight(raw)
    runs = to_flights(raw)
    detection = longest.metadata["airborne_detection"]
    assert len(runs) == len(detection["airborne_runs_s"]) >= 2
    starts = [f.time[0] for f in runs]
    assert starts == sorted(starts), "in time order"
    for k, (flight, (a, b)) in enumerate(zip(runs, detection["airborne_runs_s"])):
        assert flight.metadata["airborne_run"] == {"index": k + 1, "of": len(runs)}
        assert flight.metadata["segment_mode"] == "each"
        # each run trimmed as the longest is: TRIM_S off both ends of what the detector found airborne
        assert abs(flight.time[0] - (a + TRIM_S)) < 0.011 and abs(flight.time[-1] - (b - TRIM_S)) < 0.011
        assert flight.duration >= MIN_AIRBORNE_S - 2 * TRIM_S - 0.01
    same = max(runs, key=lambda f: f.duration)
    for x, y in ((same.time, longest.time), (same.rates, longest.rates), (same.attitude, longest.attitude),
                 (same.sticks, longest.sticks)):
        assert_array_equal(x, y)
    # the default import says what it left out, and how to have it
    (note,) = [w for w in longest.metadata["import_warnings"] if "airborne runs" in w]
    left_out = sum(b - a for a, b in detection["airborne_runs_s"]) - max(b - a for a, b in detection["airborne_runs_s"])
    assert note.startswith(f"the log holds {len(runs)} airborne runs (")
    assert f"the other {len(runs) - 1}'s {left_out:.1f} s are left out" in note and "--segment each" in note
    assert not any("airborne runs" in w for f in runs for w in f.metadata.get("import_warnings", ()))


def test_heli_import_segment_each_writes_a_numbered_csv_per_run_and_the_identify_command(multi_run, tmp_path,
                                                                                         monkeypatch, capsys):
    path, raw = multi_run
    monkeypatch.setattr(io, "_load_raw", lambda *args, **kwargs: raw)  # decoded once, above
    assert main(["import", str(path), "--segment", "each", "--out", str(tmp_path / "flight.csv"), "--quiet"]) == 0
    out = capsys.readouterr().out
    runs = to_flights(raw)
    written = [tmp_path / f"flight-{k + 1}.csv" for k in range(len(runs))]
    assert sorted(tmp_path.iterdir()) == sorted(written + [p.with_suffix(".meta.json") for p in written])
    for k, (p, flight) in enumerate(zip(written, runs)):
        back = io.read_log(p)
        assert_array_equal(back.time, flight.time)
        assert np.allclose(back.rates, flight.rates, rtol=0, atol=1e-12)
        meta = json.loads(p.with_suffix(".meta.json").read_text())
        assert meta["airborne_run"] == {"index": k + 1, "of": len(runs)} and meta["source"] == MULTI_RUN
        assert f"airborne run {k + 1} of {len(runs)}: segment {flight.time[0]:.3f}..{flight.time[-1]:.3f} s" in out
    assert f"identify from every run: heli identify {' '.join(str(p) for p in written)} --out model/" in out


def test_a_csv_flight_has_no_airborne_runs_to_find(tmp_path, capsys):
    csv = write_csv_flight(_flight(5.0, "f.csv"), tmp_path / "f.csv")
    with pytest.raises(SegmentError, match="segment 'each' needs a flight-controller log"):
        read_log_runs(csv)
    with pytest.raises(SegmentError, match="segment='each' needs a flight-controller log"):
        io.read_log(csv, segment="each")
    assert main(["import", str(csv), "--segment", "each", "--out", str(tmp_path / "g.csv"), "--quiet"]) != 0
    assert "needs a flight-controller log" in capsys.readouterr().err
    assert not (tmp_path / "g-1.csv").exists()


def _flight(duration: float, name: str) -> Flight:
    t = np.arange(0.0, duration, 0.01)
    rng = np.random.default_rng(int(duration * 10))
    return make_flight(t, rng.normal(0, 0.2, (3, t.size)), np.clip(rng.normal(0, 0.2, (4, t.size)), -1, 1),
                       metadata={"source": name})


def test_short_runs_fitted_together_are_judged_by_their_total():
    runs = [_flight(d, f"flight-{k + 1}.csv") for k, d in enumerate((6.0, 30.0, 20.0, 25.0))]
    assert not any("shorter than" in w for w in fit_warnings(runs))  # 81 s in all
    lines = [w for w in fit_warnings(runs[:2]) if "shorter than" in w]
    assert lines == [f"the 2 flights ('flight-1.csv' {runs[0].duration:.1f} s, 'flight-2.csv' {runs[1].duration:.1f} s) "
                     f"last {runs[0].duration + runs[1].duration:.1f} s in all, shorter than "
                     f"{MIN_DURATION_S:.0f} s: too short for the parameters and the wind statistics to settle; "
                     "identify from longer flights or more of them"]
