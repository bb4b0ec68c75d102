"""The sweep's default windows (the library tiled) and the 90 % interval beside each p90 (sweep_interval)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from controllers.sweep import sweep_pairs
from controllers.sweep_inputs import tile_windows
from controllers.sweep_interval import (INTERVAL_COLUMNS, half_width, quantiles_at, trace_blocks,
                                        woodruff_levels)
from heli_cli.main import main

PAIRS = [(5.0, 0.5), (20.0, 3.0)]


@pytest.fixture(scope="module")
def tiled(shipped):
    return sweep_pairs(shipped, PAIRS, duration=20.0, progress=False, seed=4)


def test_default_windows_tile_every_trace_once(shipped, tiled):
    span = 2000  # 20 s at 100 Hz
    per_trace = {t: sorted(off for tt, off in tiled.windows if tt == t) for t in range(shipped.n_traces)}
    for t, offs in per_trace.items():
        assert len(offs) == (shipped.lengths[t] - 1) // span
        assert np.all(np.diff(offs) == span)  # end to end, no overlap
        assert offs[-1] + span <= shipped.lengths[t] - 1
    s = tiled.settings["p90_interval"]
    assert s["library_s_flown"] == pytest.approx(len(tiled.windows) * 20.0)
    assert tile_windows(shipped, [0, 1, 2], 2000, 1, 4) == tiled.windows  # same seed, same windows


def test_each_p90_sits_inside_its_interval_and_more_library_narrows_it(shipped, tiled):
    few = sweep_pairs(shipped, PAIRS, duration=20.0, windows=2, progress=False, seed=4)
    for r in (tiled, few):
        t = r.table
        for name, unit in (("att", "deg"), ("rate", "dps")):
            lo, p90, hi = (np.asarray(t[f"{name}_p90{s}_{unit}"], float) for s in ("_lo", "", "_hi"))
            assert np.all(lo <= p90) and np.all(p90 <= hi) and np.all(lo < hi)
    assert np.all(half_width(tiled.table) < half_width(few.table))
    assert np.all(half_width(tiled.table) < 0.15)
    summary = tiled.settings["p90_interval"]
    assert summary["level"] == 0.9 and summary["n_blocks"] >= 50
    assert summary["median_half_width"] == pytest.approx(float(np.median(half_width(tiled.table))))


def test_intervals_are_deterministic_for_a_seed(shipped, tiled):
    again = sweep_pairs(shipped, PAIRS, duration=20.0, progress=False, seed=4)
    for c in INTERVAL_COLUMNS:
        assert_array_equal(again.table[c], tiled.table[c], err_msg=c)


def test_blocks_gather_every_window_over_one_stretch_of_trace():
    # two windows over the same seconds of trace 0, one of trace 1; 1 s blocks at 10 Hz, 2 samples per period
    blocks, adjacent = trace_blocks([(0, 0), (0, 4), (1, 0)], steps=10, ratio=2, sample_rate=10.0,
                                    block_seconds=1.0)
    assert blocks.shape == (10, 3)
    assert blocks[2, 1] == blocks[4, 0]  # sample 8 of trace 0, reached by both windows
    assert set(blocks[:, 2]).isdisjoint(blocks[:, :2].ravel())  # trace 1 has its own blocks
    assert len(np.unique(blocks)) == 3 + 2  # trace 0: samples 0..22 -> blocks 0-2; trace 1: 0..18 -> 0-1
    assert {tuple(p) for p in adjacent} == {(0, 1), (1, 2), (3, 4)}


@pytest.mark.parametrize("shared", [False, True])
def test_woodruff_interval_covers_the_true_quantile(shared):
    """Coverage over 300 replications of 40 blocks x 250 samples: exponential samples, independent or scaled
    by a level shared within each block (then the p90 solves 2 sqrt(q) K1(2 sqrt(q)) = 0.1); measured 0.90
    in both cases."""
    from scipy import optimize, special

    rng = np.random.default_rng(0)
    blocks = np.repeat(np.arange(40), 250)
    true_q = (optimize.brentq(lambda q: 2 * np.sqrt(q) * special.k1(2 * np.sqrt(q)) - 0.1, 0.1, 50.0) if shared
              else -np.log(0.1))
    hits, n_rep = 0, 300
    for _ in range(n_rep):
        level = rng.exponential(1.0, 40)[blocks] if shared else 1.0
        x = (rng.exponential(1.0, blocks.size) * level)[None, :]
        lo, hi = quantiles_at(x.copy(), woodruff_levels(x, blocks, np.empty((0, 2), dtype=int)))[0]
        hits += lo <= true_q <= hi
    assert 0.84 <= hits / n_rep <= 0.96


def test_woodruff_interval_widens_with_correlation_inside_blocks():
    rng = np.random.default_rng(1)
    blocks = np.repeat(np.arange(40), 250)
    iid = rng.exponential(1.0, blocks.size)[None, :]
    shared = (rng.exponential(1.0, 40)[blocks] * rng.exponential(1.0, blocks.size))[None, :]  # a level per block
    widths = []
    for x in (iid, shared):
        lo, hi = quantiles_at(x.copy(), woodruff_levels(x, blocks, np.empty((0, 2), dtype=int)))[0]
        widths.append((hi - lo) / np.quantile(x, 0.9))
    assert widths[1] > 2 * widths[0]
    one_block = woodruff_levels(iid, np.zeros(blocks.size, dtype=int), np.empty((0, 2), dtype=int))
    assert np.all(np.isnan(one_block))


def test_cli_json_and_markdown_carry_the_intervals(tmp_path):
    out = tmp_path / "sw"
    assert main(["sweep", "--kp", "5:20:2", "--kd", "1", "--duration", "20", "--no-extend", "--no-plots",
                 "--out", str(out), "--no-progress", "--workers", "1"]) == 0
    doc = json.loads((out / "sweep.json").read_text())
    assert doc["schema_version"] == 3
    assert all(c in doc["columns"] for c in INTERVAL_COLUMNS)
    row = doc["rows"][0]
    assert row["att_p90_lo_deg"] <= row["att_p90_deg"] <= row["att_p90_hi_deg"]
    assert doc["settings"]["p90_interval"]["median_half_width"] > 0
    md = (out / "sweep.md").read_text()
    assert "sampling error of the p90s" in md
    assert f"{row['att_p90_deg']:.3f} [{row['att_p90_lo_deg']:.3f}, {row['att_p90_hi_deg']:.3f}]" in md
    header = (out / "sweep.csv").read_text().splitlines()[0].split(",")
    assert "att_p90_lo_deg" in header and "rate_p90_hi_dps" in header
