"""The result of a gain sweep (:mod:`controllers.sweep`): its table, one row per PD gain pair, the columns of
that table, and its files (CSV and JSON).

Plain data: :mod:`controllers.sweep` computes it, :mod:`controllers.sweep_report` renders it (Markdown, heat
map, histograms) and :mod:`controllers.flight_test` holds flights against it; this module imports none of
them.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field

import numpy as np

from heli_core.deprecation import moved_method
from heli_core.files import jsonable, write_text

from .errors import SweepError
from .sweep_extend import best_index
from .sweep_margins import MARGIN_COLUMNS, ROBUST_GAIN_MARGIN_DB, ROBUST_PHASE_MARGIN_DEG, robust
from .sweep_replay import TD_COLUMNS

FD_COLUMNS = ("pred_att_rms_deg", "pred_att_p50_deg", "pred_att_p90_deg", "pred_att_p99_deg", "pred_rate_rms_dps",
              "pred_rate_p50_dps", "pred_rate_p90_dps", "pred_rate_p99_dps", "pred_stick_rms")
COLUMNS = ("kp", "kd", "status", "max_pole", "settle_s") + MARGIN_COLUMNS + TD_COLUMNS + FD_COLUMNS + (
    "att_p90_rel_diff", "rate_p90_rel_diff", "disagree", "extension_round")
"""Columns of the result table, one row per gain pair (Kp-major order).

``att_*`` |attitude error| [deg], ``rate_*`` |rate error| [deg/s] (``*_p90_lo_*`` and ``*_p90_hi_*`` the
ends of the time-domain p90's 90 % interval, its sampling error over blocks of the library's time,
:mod:`controllers.sweep_interval`), ``stick_*`` the
applied stick offset from trim [stick units], ``saturation`` the fraction of control
periods where the swept axis' stick was clipped, ``other_axes_max_deg`` the largest
|angle| of the two nominally held axes; ``pred_*`` the frequency-domain
prediction (Gaussian percentiles of |e|); ``*_rel_diff`` (time − frequency)/frequency
of the p90s; ``status`` "stable", "unstable" (closed-loop poles; not simulated) or
"diverged" (left ±60°); ``max_pole`` the spectral radius of the discrete closed loop and
``settle_s`` the 2 % settling time of its slowest mode, ``-4 dt / ln(max_pole)`` [s] (a loop
slower than the windows never reaches the stationary distribution the frequency domain
predicts); ``gain_margin_db`` [dB] and ``phase_margin_deg`` [deg] the margins of the same sampled
loop broken at the swept stick (:func:`controllers.sweep_margins.loop_margins`; inf where the loop
never crosses, negative for an unstable pair); ``extension_round`` 0 for the grid asked for, k for
the pairs added by the k-th extension of the grid (:mod:`controllers.sweep_extend`)."""


@dataclass(eq=False)
class SweepResult:
    """Error distributions of a PD gain sweep, per gain pair (Kp-major order).

    Attributes
    ----------
    axis : str
    kp_values, kd_values : ndarray
        The grid [stick/rad], [stick/(rad/s)], grown where the sweep extended it (the grid asked for
        is ``settings["extension"]["kp_asked"]``, ``["kd_asked"]``).
    table : dict of str -> ndarray (n_pairs,)
        :data:`COLUMNS`.
    hist_edges : ndarray (n_bins + 1,)
        Bin edges of |attitude error| [deg], shared by all pairs and by agent evaluation
        (:func:`controllers.metrics.histogram_edges`): 0, then geometric from
        :data:`~controllers.metrics.HIST_MIN_DEG` to ``hist_max_deg`` (about 7 % wide by default).
    hist_counts : ndarray (n_pairs, n_bins)
        Samples per bin; ``hist_overflow`` (n_pairs,) counts those above the last edge.
    windows : tuple of (trace, offset)
        Library windows replayed (trace index, start sample).
    psd_freq, psd : ndarray
        The Welch spectrum of u_d used by the prediction [Hz], (3, nf) [stick²/Hz].
    settings : dict
        Model, dt, duration, seed, nominal gains, tolerance, timing, and ``extension``: the grid asked
        for, the rounds of growth (edges, gains and pairs added, the best pair before each) and why the
        growth stopped (:data:`controllers.sweep_extend.STOPS`, in words under ``stop_detail``).
    samples : dict of int -> (att_err_deg, rate_err_deg_s, stick)
        Signed per-sample errors of each pair, only with ``keep_samples=True``.
    """

    axis: str
    kp_values: np.ndarray
    kd_values: np.ndarray
    table: dict
    hist_edges: np.ndarray
    hist_counts: np.ndarray
    hist_overflow: np.ndarray
    windows: tuple
    psd_freq: np.ndarray
    psd: np.ndarray
    settings: dict
    samples: dict = field(default_factory=dict)

    @property
    def n_pairs(self) -> int:
        return int(self.table["kp"].size)

    @property
    def stable(self) -> np.ndarray:
        return self.table["status"] == "stable"

    @property
    def is_grid(self) -> bool:
        return self.settings.get("layout", "grid") == "grid"

    def grid(self, column: str) -> np.ndarray:
        """A column as a (n_kp, n_kd) array (rows Kp, columns Kd); grids only."""
        if not self.is_grid:
            raise SweepError("this sweep ran a list of pairs, not a grid")
        return np.asarray(self.table[column]).reshape(self.kp_values.size, self.kd_values.size)

    def index(self, kp: float, kd: float) -> int:
        """Row of the pair nearest to ``(kp, kd)`` (relative distance in each gain)."""
        k_p, k_d = np.asarray(self.table["kp"], float), np.asarray(self.table["kd"], float)
        sp, sd = max(np.ptp(k_p), 1e-12), max(np.ptp(k_d), 1e-12)
        return int(np.argmin(((k_p - kp) / sp) ** 2 + ((k_d - kd) / sd) ** 2))

    def row(self, i: int) -> dict:
        """One pair's row as a dict of Python scalars."""
        return {c: _scalar(self.table[c][i]) for c in COLUMNS}

    def rows(self) -> list:
        return [self.row(i) for i in range(self.n_pairs)]

    def best(self, by: str = "att_p90_deg") -> dict | None:
        """The stable, simulated pair with the smallest ``by`` (default p90 |attitude error|), or None."""
        i = best_index(self.table, by)
        return None if i is None else self.row(i)

    def best_robust(self, by: str = "att_p90_deg", min_gain_margin_db: float = ROBUST_GAIN_MARGIN_DB,
                    min_phase_margin_deg: float = ROBUST_PHASE_MARGIN_DEG) -> dict | None:
        """:meth:`best` among the pairs that keep ``min_gain_margin_db`` [dB] and ``min_phase_margin_deg``
        [deg] (default 6 dB and 45°), or None when no stable pair does."""
        keeps = robust(self.table["gain_margin_db"], self.table["phase_margin_deg"], min_gain_margin_db,
                       min_phase_margin_deg)
        i = best_index(self.table, by, among=keeps)
        return None if i is None else self.row(i)

    @property
    def extension(self) -> dict:
        """``settings["extension"]``: the grid asked for, the rounds of growth and why it stopped."""
        return self.settings["extension"]

    def to_csv(self, path):
        """Write the table as CSV (one row per pair; NaN for what was not simulated), atomically
        (:func:`write_csv`)."""
        return write_csv(self, path)

    def to_json(self, path):
        """Write settings, table, histograms, windows and spectrum as JSON (NaN as null), atomically
        (:func:`write_json`)."""
        return write_json(self, path)

    def to_markdown(self) -> str:
        """Deprecated: :func:`controllers.sweep_report.markdown` renders the report."""
        return moved_method("SweepResult.to_markdown", "controllers.sweep_report", "markdown", self)

    def plot_heatmap(self, path):
        """Deprecated: :func:`controllers.sweep_report.plot_heatmap` draws the heat maps."""
        return moved_method("SweepResult.plot_heatmap", "controllers.sweep_report", "plot_heatmap", self, path)

    def plot_histograms(self, path, pairs=None):
        """Deprecated: :func:`controllers.sweep_report.plot_histograms` draws the histograms."""
        return moved_method("SweepResult.plot_histograms", "controllers.sweep_report", "plot_histograms", self,
                            path, pairs)


def _scalar(v):
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.floating, float)):
        return float(v)
    if isinstance(v, (np.integer, int)):
        return int(v)
    return str(v)


def write_csv(result: SweepResult, path):
    """Write ``result``'s table as CSV (one row per pair; NaN for what was not simulated), atomically."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    for row in result.rows():
        w.writerow([_csv_cell(row[c]) for c in COLUMNS])
    return write_text(path, buf.getvalue())


def write_json(result: SweepResult, path):
    """Write ``result``'s settings, table, histograms, windows and spectrum as JSON (NaN as null), atomically."""
    doc = {
        "schema": "heli-env/gain-sweep",
        # 2: margins, extension_round and settings["extension"]; the grid may have grown
        # 3: the p90s' 90 % intervals (*_p90_lo_*, *_p90_hi_*) and settings["p90_interval"]
        "schema_version": 3,
        "settings": result.settings,
        "kp_values": result.kp_values.tolist(),
        "kd_values": result.kd_values.tolist(),
        "columns": list(COLUMNS),
        "rows": result.rows(),
        "histogram": {"quantity": "|attitude error| [deg]", "edges": result.hist_edges.tolist(),
                      "counts": result.hist_counts.tolist(), "overflow": result.hist_overflow.tolist()},
        "windows": [list(w) for w in result.windows],
        "disturbance_spectrum": {"freq_hz": result.psd_freq.tolist(),
                                 "psd_stick2_per_hz": {a: p.tolist() for a, p in
                                                       zip(("roll", "pitch", "yaw"), result.psd)}},
    }
    return write_text(path, json.dumps(jsonable(doc), indent=1, allow_nan=False) + "\n")


def _csv_cell(v):
    """Floats to 6 digits; NaN (not computed) empty, an infinite margin or settling time ``inf``."""
    if not isinstance(v, float):
        return v
    if math.isnan(v):
        return ""
    return f"{v:.6g}"  # 'inf', '-inf'
