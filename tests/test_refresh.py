"""Tests of ``heli refresh`` (identification.workflows.refresh) and of the interval bootstrap
(identification.integral.bootstrap).

Scenario: flight 1 (seed 11, the paper's wind) is identified with ``heli identify``;
flight 2 (seed 12, half the wind, roll damping k3 raised by 30 %) refreshes it.
Flight 3 (seed 13, the same aircraft as flight 1) checks that an unchanged aircraft
is pooled and not flagged. Flights last 120 s; the bootstrap uses 60 replicates.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from numpy.testing import assert_allclose

import heli_env  # noqa: F401  (registers HeliAttitude-v0)
from heli_cli.main import main
from heli_core.files import sha256_of
from identification.bench.flight_config import PAPER_PARAMS, FlightConfig
from identification.bench.synthetic import simulate_flight
from identification.errors import IdentifiabilityError
from identification.integral.bootstrap import interval_bootstrap, interval_flights
from identification.integral.method import IntegralIdentifier
from identification.workflows.refresh import refresh_model
from identification.workflows.refresh_sources import DuplicateFlightError, RefreshError
from model_store.disturbance_library import DisturbanceLibrary

DURATION = 120.0
K3_CHANGE = 1.3
REPLICATES = "60"


@pytest.fixture(scope="session")
def flights(tmp_path_factory):
    """Three synthetic flights as CSV files in one folder: f1 and f3 the same aircraft, f2 with k3 x 1.3."""
    folder = tmp_path_factory.mktemp("refresh_flights")
    simulate_flight(duration=DURATION, seed=11).save(folder / "f1.csv")
    calm = FlightConfig(duration=DURATION, wind_level=(0.045, 0.045, 0.015))
    simulate_flight(seed=12, config=calm, truth=PAPER_PARAMS.with_values(k3=PAPER_PARAMS.k3 * K3_CHANGE)).save(
        folder / "f2.csv")
    simulate_flight(duration=DURATION, seed=13).save(folder / "f3.csv")
    return {name: folder / f"{name}.csv" for name in ("f1", "f2", "f3")}


@pytest.fixture(scope="session")
def identified_base(flights, tmp_path_factory):
    """``heli identify f1.csv --out DIR --no-plots`` (kept pristine; tests work on copies)."""
    out = tmp_path_factory.mktemp("refresh_base") / "DIR"
    assert main(["identify", str(flights["f1"]), "--out", str(out), "--no-plots"]) == 0
    return out


@pytest.fixture
def model_dir(identified_base, tmp_path):
    out = tmp_path / "DIR"
    shutil.copytree(identified_base, out)
    return out


STAGES = {}
"""What the ``refreshed`` fixture's command printed on stderr (its progress), under "stderr"."""


@pytest.fixture(scope="session")
def refreshed(identified_base, flights, tmp_path_factory):
    """``heli refresh DIR f2.csv`` on a copy of the identified model; returns (DIR, bytes before)."""
    import contextlib
    import io

    out = tmp_path_factory.mktemp("refreshed") / "DIR"
    shutil.copytree(identified_base, out)
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    err = io.StringIO()  # not a terminal: one line per stage
    with contextlib.redirect_stderr(err):
        assert main(["refresh", str(out), str(flights["f2"]), "--bootstrap", REPLICATES, "--seed", "0",
                     "--no-plots"]) == 0
    STAGES["stderr"] = err.getvalue()
    return out, before


def _refresh_doc(out):
    return json.loads((out / "refresh.json").read_text())


# ---------------------------------------------------------------------------------------- the scenario


@pytest.mark.slow  # over 5 s: make test-slow
def test_changed_damping_is_flagged_and_nothing_else(refreshed):
    out, _ = refreshed
    doc = _refresh_doc(out)
    rows = {r["name"]: r for r in doc["drift"]}
    assert doc["flagged"] == ["k3"]
    k3 = rows["k3"]
    assert k3["flagged"] and k3["z"] > 2 * k3["threshold"]
    # the new flights' k3 recovers the changed truth; the old one the original (5 % tolerance each)
    assert_allclose(k3["new"], PAPER_PARAMS.k3 * K3_CHANGE, rtol=0.05)
    assert_allclose(k3["old"], PAPER_PARAMS.k3, rtol=0.05)
    assert_allclose(k3["delta"], k3["new"] - k3["old"])
    # uncertainty from the Fisher information of both maximum-likelihood fits (the previous flight lies
    # beside the new one); the offsets kd are per-flight trim values and are not compared
    assert k3["se_old_source"] == "Fisher" and doc["previous_flights"]["missing"] == []
    assert k3["ci_new"][0] < k3["new"] < k3["ci_new"][1]
    z = doc["criterion"]["z"]
    assert doc["criterion"]["n_parameters"] == len(rows) == 7
    assert not any(name.startswith("kd") for name in rows)
    assert set(doc["flight_offsets"]) == {"roll", "pitch", "yaw"}
    assert_allclose(z, 2.690, atol=1e-3)  # Bonferroni, alpha 0.05 over 7 parameters
    for r in rows.values():
        assert_allclose(r["z"], abs(r["delta"]) / np.hypot(r["se_old"], r["se_new"]), rtol=1e-12)


def test_refresh_announces_each_long_step_as_it_starts(refreshed):
    """Issue 31: 'heli refresh' showed nothing moving for 17 s. Off a terminal each step that can take seconds is
    one line as it starts: the new flight's fit, the previous flight's refit, the refreshed model's fit and wind."""
    lines = STAGES["stderr"].splitlines()
    assert lines[0].startswith("refresh: reading ") and lines[0].endswith(" and checking the new flights ...")
    steps = [ln for ln in lines if ln.startswith("refresh: ")]
    assert steps[1] == "refresh: reading and fitting 1 new flight (maximum likelihood) for the drift table ..."
    assert steps[2] == ("refresh: reading and fitting 1 previous flight (maximum likelihood) for the current model's "
                        "uncertainty ...")
    assert any(ln.startswith("refresh: refreshed model: fitting ") for ln in steps)
    assert "refresh: refreshed model: identifying the wind of 1 flight ..." in steps
    assert not any("drawing" in ln for ln in steps)  # --no-plots


def test_changed_aircraft_is_refitted_on_the_new_flight_alone(refreshed, flights):
    out, before = refreshed
    model = json.loads((out / "model.json").read_text())
    assert [s["file"] for s in model["provenance"]["sources"]] == ["f2.csv"]
    record = model["refresh"]
    assert record["fit"] == "new" and "k3" in record["reason"] and record["flagged"] == ["k3"]
    old_sha = record["previous_model"]["sha256"]
    assert old_sha == hashlib.sha256(before[Path("model.json")]).hexdigest()
    assert (out / record["previous_model"]["kept_as"]).read_bytes() == before[Path("model.json")]
    assert record["previous_model"]["sources"][0]["file"] == "f1.csv"
    assert set(record["bootstrap"]["std_errors"]) == set(_refresh_doc(out)["refreshed_parameters"])
    assert_allclose(model["parameters"]["k3"], PAPER_PARAMS.k3 * K3_CHANGE, rtol=0.05)
    # the replaced identification report is kept too
    assert any(p.name.startswith("report-") for p in (out / "history").iterdir())
    assert "k3" in (out / "refresh.md").read_text()


def test_library_gains_a_version_with_both_flights(refreshed, flights):
    out, before = refreshed
    lib = DisturbanceLibrary.open(out)
    assert lib.versions() == [1, 2]
    assert (lib.path / "manifest-v0001.json").read_bytes() == before[Path("disturbances/manifest-v0001.json")]
    traces = lib.manifest(2)["traces"]
    assert [t["source"]["name"] for t in traces] == ["f1.csv", "f2.csv"]
    assert [t["source"]["sha256"] for t in traces] == [sha256_of(flights["f1"]), sha256_of(flights["f2"])]
    assert traces[1]["added_in_version"] == 2
    assert traces[1]["model"]["sha256"] == sha256_of(out / "model.json")
    assert lib.orphans() == []


def test_refresh_rewrites_report_html_and_check_finds_the_folder_current(refreshed, capsys):
    """report.html shows the refreshed report.md, not the identified one; the old page is kept in history/."""
    from heli_cli.html_report import stale_reasons

    out, before = refreshed
    assert (out / "report.md").read_bytes() != before[Path("report.md")]
    page = (out / "report.html").read_text(encoding="utf-8")
    assert f'content="report.md" data-sha256="{hashlib.sha256((out / "report.md").read_bytes()).hexdigest()}"' in page
    assert stale_reasons(out / "report.html") == []
    assert any(p.name.startswith("report") and p.suffix == ".html" for p in (out / "history").iterdir())
    assert main(["check", str(out), "--no-repair"]) == 0
    assert "consistent" in capsys.readouterr().out


def test_check_finds_a_stale_report_html_and_writes_it_again(model_dir, capsys):
    """As a refresh by an older heli left it: report.md rewritten, report.html not."""
    report = model_dir / "report.md"
    report.write_text(report.read_text(encoding="utf-8") + "\nA line the page does not show.\n", encoding="utf-8")
    assert main(["check", str(model_dir), "--no-repair"]) == 2
    out = capsys.readouterr().out
    assert "problem: report.html does not show the current report: report.md changed since report.html" in out
    assert main(["check", str(model_dir)]) == 0
    assert "repaired: report.html rewritten from report.md" in capsys.readouterr().out
    assert "A line the page does not show." in (model_dir / "report.html").read_text(encoding="utf-8")


def test_env_replays_both_flights(refreshed):
    out, _ = refreshed
    env = gym.make("HeliAttitude-v0", model=str(out))
    ids = set()
    for seed in range(40):
        _, info = env.reset(seed=seed)
        ids.add(info["trace_id"])
    env.close()
    traces = DisturbanceLibrary.open(out).manifest()["traces"]
    assert ids == {t["id"] for t in traces} and len(ids) == 2


def test_a_flight_already_in_the_library_is_refused_and_nothing_written(refreshed, flights, capsys):
    out, _ = refreshed
    snapshot = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    for name in ("f1", "f2"):
        assert main(["refresh", str(out), str(flights[name]), "--bootstrap", "10", "--no-plots"]) == 2
        err = capsys.readouterr().err
        assert "DuplicateFlightError" in err and f"{name}.csv" in err and "already in the disturbance library" in err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == snapshot


def test_the_same_flight_twice_is_refused(model_dir, flights):
    with pytest.raises(DuplicateFlightError, match="is the same file as f3.csv"):
        refresh_model(model_dir, [flights["f3"], flights["f3"]], n_replicates=10, plots=False)


@pytest.mark.slow  # over 5 s: make test-slow
def test_unchanged_aircraft_is_pooled_without_flags(model_dir, flights, tmp_path):
    """The new flight with three samples missing, as a logger drops them: read on its clock (the missing ones
    interpolated), and the refresh's notes say so."""
    lines = flights["f3"].read_text().splitlines(keepends=True)
    f3 = tmp_path / "f3.csv"
    f3.write_text("".join(line for i, line in enumerate(lines) if i not in (501, 502, 2001)))
    (tmp_path / "f1.csv").write_bytes(flights["f1"].read_bytes())  # the previous flight, found beside it
    r = refresh_model(model_dir, [f3], n_replicates=60, seed=0, plots=False, progress=False)
    assert r.notes[0].startswith("f3.csv: the time column is not uniform: 3 sample(s) missing")
    assert r.flagged == [] and r.fit == "pooled"
    assert max(row.z for row in r.drift) < r.criterion["z"]
    model = json.loads((model_dir / "model.json").read_text())
    assert [s["file"] for s in model["provenance"]["sources"]] == ["f3.csv", "f1.csv"]
    assert r.bootstrap_model.n_intervals == r.bootstrap_new.n_intervals + r.bootstrap_old.n_intervals
    # pooling tightens the estimates
    for k in ("k2", "k3", "k6", "k7", "k10", "k11"):
        assert r.bootstrap_model.std_errors[k] < r.bootstrap_new.std_errors[k]


@pytest.mark.slow  # over 5 s: make test-slow
def test_a_new_flight_read_as_a_stretch_is_recorded_so(model_dir, flights):
    """``heli refresh --segment T0:T1``: the new log is fitted on that stretch and its source records it (a later
    refresh reads it the same way); the previous flight, read by default, records none."""
    assert main(["refresh", str(model_dir), str(flights["f3"]), "--segment", "10:110", "--bootstrap", REPLICATES,
                 "--no-plots", "-q"]) == 0
    sources = {s["file"]: s for s in json.loads((model_dir / "model.json").read_text())["provenance"]["sources"]}
    assert sources["f3.csv"]["segment"] == pytest.approx([10.0, 110.0], abs=0.011) and "segment" not in sources["f1.csv"]
    new, = _refresh_doc(model_dir)["new_flights"]
    assert new["duration_s"] == pytest.approx(100.0, abs=0.02) and new["segment"] == sources["f3.csv"]["segment"]


def test_a_stretch_outside_the_new_flight_is_refused_in_one_line_and_nothing_written(model_dir, flights, capsys):
    before = {p: p.read_bytes() for p in model_dir.rglob("*") if p.is_file()}
    assert main(["refresh", str(model_dir), str(flights["f3"]), "--segment", "500:600", "--no-plots", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("heli refresh: error: FlightLogError: segment [500.0, 600.0] s holds 0 samples")
    assert {p: p.read_bytes() for p in model_dir.rglob("*") if p.is_file()} == before


@pytest.mark.slow  # over 5 s: make test-slow
def test_without_the_previous_flights_ml_uses_the_recorded_fisher_errors(model_dir, flights, tmp_path):
    lone = tmp_path / "elsewhere"
    lone.mkdir()
    shutil.copy(flights["f3"], lone / "f3.csv")
    r = refresh_model(model_dir, [lone / "f3.csv"], plots=False, progress=False)
    assert r.fit == "new" and "f1.csv missing" in r.reason and r.bootstrap_old is None
    assert {row.se_old_source for row in r.drift} == {"Fisher information recorded in model.json"}
    recorded = json.loads((model_dir / "model.json").read_text())["refresh"]["bootstrap"]["std_errors"]
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(flights["f2"], other / "f2.csv")
    r2 = refresh_model(model_dir, [other / "f2.csv"], plots=False, progress=False)
    assert {row.se_old_source for row in r2.drift} == {"recorded Fisher information"}
    assert {row.name: row.se_old for row in r2.drift} == recorded


@pytest.fixture
def integral_model_dir(flights, tmp_path):
    out = tmp_path / "INT"
    assert main(["identify", str(flights["f1"]), "--out", str(out), "--no-plots", "--method", "integral"]) == 0
    return out


def test_without_the_previous_flights_the_new_flights_alone_are_used(integral_model_dir, flights, tmp_path):
    model_dir = integral_model_dir
    lone = tmp_path / "elsewhere"
    lone.mkdir()
    shutil.copy(flights["f3"], lone / "f3.csv")
    with pytest.raises(RefreshError, match=r"needs the previous model's flights; not found: f1\.csv"):
        refresh_model(model_dir, [lone / "f3.csv"], fit="pooled", n_replicates=10, plots=False)
    r = refresh_model(model_dir, [lone / "f3.csv"], n_replicates=30, plots=False, progress=False)
    assert r.fit == "new" and "f1.csv missing" in r.reason and r.bootstrap_old is None
    assert {row.se_old_source for row in r.drift} == {"scaled from the new flights"}
    assert any("sqrt(" in n for n in r.notes)  # old interval count from the library's trace durations
    # the next refresh finds no flights either, and uses the bootstrap this one recorded in model.json
    recorded = json.loads((model_dir / "model.json").read_text())["refresh"]["bootstrap"]["std_errors"]
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(flights["f2"], other / "f2.csv")
    r2 = refresh_model(model_dir, [other / "f2.csv"], n_replicates=30, plots=False, progress=False)
    assert {row.se_old_source for row in r2.drift} == {"recorded bootstrap"}
    assert {row.name: row.se_old for row in r2.drift} == recorded


# ---------------------------------------------------------------------------------------- the bootstrap


@pytest.fixture(scope="session")
def short_flight():
    return simulate_flight(duration=60, seed=5, effects=("servo_delay",)).flight


def test_intervals_refitted_in_order_reproduce_the_fit(short_flight):
    ident = IntegralIdentifier(delay=(0.08, 0.08, 0.05)).fit(short_flight)
    pieces, owner = interval_flights(short_flight, ident)
    assert len(pieces) == owner.size == int((short_flight.n - 1) // 100)
    refit = IntegralIdentifier(prefilter=False).fit(pieces)
    a, b = ident.params_.values(), refit.params_.values()
    assert_allclose([b[k] for k in a], [a[k] for k in a], rtol=1e-9, atol=1e-12)


def test_same_seed_same_bootstrap(short_flight):
    ident = IntegralIdentifier().fit(short_flight)
    r1 = interval_bootstrap(short_flight, ident, 20, block=2, seed=7)
    r2 = interval_bootstrap(short_flight, ident, 20, block=2, seed=7)
    r3 = interval_bootstrap(short_flight, ident, 20, block=2, seed=8)
    np.testing.assert_array_equal(r1.replicates, r2.replicates)
    assert not np.array_equal(r1.replicates, r3.replicates)
    assert r1.n_failed == 0 and r1.replicates.shape == (20, 10)


@pytest.mark.parametrize("kwargs, match", [({"n_replicates": 1}, "n_replicates"), ({"block": 0}, "block"),
                                           ({"level": 1.0}, "level")])
def test_bootstrap_rejects_bad_settings(short_flight, kwargs, match):
    with pytest.raises(ValueError, match=match):
        interval_bootstrap(short_flight, IntegralIdentifier(), **kwargs)


def test_bootstrap_block_longer_than_the_flight(short_flight):
    with pytest.raises(IdentifiabilityError, match="do not fit in any flight"):
        interval_bootstrap(short_flight, IntegralIdentifier(), 5, block=100)


@pytest.mark.parametrize("option, value", [("--bootstrap", "1"), ("--alpha", "1.5"), ("--block", "0"),
                                           ("--fit", "both"), ("--min-change", "-1")])
def test_refresh_rejects_bad_options(model_dir, flights, capsys, option, value):
    with pytest.raises(SystemExit) as exc:
        main(["refresh", str(model_dir), str(flights["f3"]), option, value])
    assert exc.value.code == 2
    assert f"argument {option}" in capsys.readouterr().err


def test_refresh_of_a_missing_model_is_one_line(tmp_path, flights, capsys):
    assert main(["refresh", str(tmp_path / "nowhere"), str(flights["f3"])]) == 2
    # the stage line ("refresh: refitting ...") is progress; the error is one line of its own
    err = [line for line in capsys.readouterr().err.strip().splitlines() if not line.startswith("refresh: ")]
    assert len(err) == 1 and "ModelFileError" in err[0] and "does not exist" in err[0]


# slow (10 s): tests/test_model_store.py kills a refresh at every file event in 3 s
@pytest.mark.slow
def test_a_refresh_stopped_before_the_library_write_can_be_run_again(model_dir, flights, monkeypatch):
    before = (model_dir / "model.json").read_bytes()

    def disk_full(*args, **kwargs):
        raise OSError("No space left on device")

    monkeypatch.setattr(DisturbanceLibrary, "append", disk_full)
    with pytest.raises(OSError, match="No space left"):
        refresh_model(model_dir, [flights["f3"]], n_replicates=10, plots=False, progress=False)
    assert (model_dir / "model.json").read_bytes() == before
    assert DisturbanceLibrary.open(model_dir).versions() == [1]
    monkeypatch.undo()
    r = refresh_model(model_dir, [flights["f3"]], n_replicates=10, plots=False, progress=False)
    assert r.library_version == 2


def test_a_refresh_removes_the_figures_only_the_replaced_report_showed(tmp_path):
    """A figure of the model before (a second flight's wind figure, after a refresh on one flight) does not stay
    beside the new report as if it were current: it goes to history/, byte for byte; a figure both reports show
    and a PNG no report linked (the user's) stay."""
    from identification.workflows.refresh import _drop_stale_figures, _report_figures

    (tmp_path / "report.md").write_text("![rates](rates.png)\n![wind 2](disturbance_2_psd.png)\n")
    for name in ("rates.png", "disturbance_2_psd.png", "photo.png"):
        (tmp_path / name).write_bytes(b"\x89PNG" + name.encode())
    before = _report_figures(tmp_path)
    assert before == {"rates.png", "disturbance_2_psd.png"}
    (tmp_path / "report.md").write_text("# refreshed\n![rates](rates.png)\n")
    gone = _drop_stale_figures(tmp_path, before)
    assert gone == [tmp_path / "disturbance_2_psd.png"] and not gone[0].exists()
    assert (tmp_path / "rates.png").exists() and (tmp_path / "photo.png").exists()
    kept = list((tmp_path / "history").glob("disturbance_2_psd-*.png"))
    assert len(kept) == 1 and kept[0].read_bytes() == b"\x89PNGdisturbance_2_psd.png"
