"""Error-distribution metrics of a controller, shared by gain sweeps and agent evaluation.

One function, :func:`error_metrics`, turns samples of attitude error, rate
error and stick into the figures the issue asks for: RMS and the 50/90/99th
percentiles of |attitude error| [deg] and |rate error| [deg/s], control-effort
RMS and 99th percentile [stick], the fraction of samples at the stick limit,
and a histogram of |attitude error| on fixed bins (:func:`histogram_edges`).
The names are the columns of :data:`controllers.sweep.TD_COLUMNS`, so a sweep
row and an evaluated agent can be read side by side.

Percentiles are numpy's default ("linear") method. Samples are taken as given:
a caller decides which periods count (the sweep and the evaluator both record
the state at the start of each control period and the action applied over it).

:func:`error_metrics_inplace` computes the same figures for a gain sweep's
records (:class:`controllers.replay.LoopRecord`): per row of a (pairs, samples)
float32 array, in place (partitioning instead of sorting, the histogram by the
index of the geometric bin), to spare copies of a few hundred MB per chunk of
pairs. It agrees with :func:`error_metrics` to float32 rounding (tested).
"""

from __future__ import annotations

import math

import numpy as np

HIST_MIN_DEG = 0.01
"""Upper edge of the first histogram bin [deg]; the bins above are geometric."""
QUANTILES = (50, 90, 99)
METRIC_NAMES = ("att_rms_deg", "att_p50_deg", "att_p90_deg", "att_p99_deg", "rate_rms_dps", "rate_p50_dps",
                "rate_p90_dps", "rate_p99_dps", "stick_rms", "stick_p99", "saturation")
"""Scalar metrics of :func:`error_metrics`, in report order."""
SATURATION_TOL = 1e-6
"""|stick| >= 1 - SATURATION_TOL counts as saturated when no explicit mask is given."""


def histogram_edges(max_deg: float = 30.0, bins: int = 120) -> np.ndarray:
    """Bin edges of |attitude error| [deg]: 0, then ``bins`` geometric edges from :data:`HIST_MIN_DEG` to ``max_deg``.

    With the defaults the bins above 0.01° are about 7 % wide.
    """
    if not (math.isfinite(max_deg) and max_deg > HIST_MIN_DEG) or int(bins) < 2:
        raise ValueError(f"the histogram needs max_deg > {HIST_MIN_DEG} and >= 2 bins, got {max_deg!r}, {bins!r}")
    return np.concatenate([[0.0], np.geomspace(HIST_MIN_DEG, float(max_deg), int(bins))])


def error_metrics(att_err_deg, rate_err_deg_s, actions, saturated=None, hist_edges=None) -> dict:
    """Error-distribution metrics over the last axis of the sample arrays.

    Parameters
    ----------
    att_err_deg : array_like, shape (..., n)
        Attitude error samples [deg] (signed; absolute values are taken).
    rate_err_deg_s : array_like, shape (..., n)
        Rate error samples [deg/s].
    actions : array_like, shape (..., n)
        Stick offsets from trim applied over each sample's period [stick units, [-1, 1]].
    saturated : array_like of bool, shape (..., n), optional
        Where the command was clipped. Default: ``|actions| >= 1 - SATURATION_TOL``
        (a policy that asks for more than the stick gives is seen at the limit).
    hist_edges : ndarray, optional
        Histogram bin edges [deg] (default :func:`histogram_edges`).

    Returns
    -------
    dict
        :data:`METRIC_NAMES` as floats (scalar input batch ``(n,)``) or arrays of
        shape ``(...)``: ``att_*_deg`` |attitude error| [deg], ``rate_*_dps``
        |rate error| [deg/s], ``stick_rms``, ``stick_p99`` |stick| [stick units],
        ``saturation`` [fraction]; plus ``n_samples``, ``hist_edges`` (nb + 1,),
        ``hist_counts`` (..., nb) and ``hist_overflow`` (...) (samples at or above
        the last edge). Non-finite samples make every metric of their row NaN.

    Raises
    ------
    ValueError
        The arrays do not share one shape, or hold no samples.
    """
    att = np.abs(np.asarray(att_err_deg, dtype=np.float64))
    rate = np.abs(np.asarray(rate_err_deg_s, dtype=np.float64))
    act = np.abs(np.asarray(actions, dtype=np.float64))
    if not (att.shape == rate.shape == act.shape) or att.ndim == 0:
        raise ValueError(f"att_err_deg, rate_err_deg_s and actions must share one shape (..., n), got "
                         f"{att.shape}, {rate.shape}, {act.shape}")
    n = att.shape[-1]
    if n == 0:
        raise ValueError("error_metrics needs at least one sample")
    if saturated is None:
        sat = act >= 1.0 - SATURATION_TOL
    else:
        sat = np.asarray(saturated, dtype=bool)
        if sat.shape != att.shape:
            raise ValueError(f"saturated must have the samples' shape {att.shape}, got {sat.shape}")
    edges = histogram_edges() if hist_edges is None else np.asarray(hist_edges, dtype=float)
    lead = att.shape[:-1]
    counts, overflow = _histogram(att, edges)  # before the rows below are partitioned
    rows = [np.array(a.reshape(-1, n)) for a in (att, rate, act)]  # copies: partitioned in place
    out = {k: v.reshape(lead) for k, v in _statistics(*rows, np.mean(sat, axis=-1).reshape(-1)).items()}
    bad = ~(np.isfinite(att).all(axis=-1) & np.isfinite(rate).all(axis=-1) & np.isfinite(act).all(axis=-1))
    if np.any(bad):
        for k in METRIC_NAMES:
            out[k] = np.where(bad, np.nan, out[k])
    if att.ndim == 1:
        out = {k: float(v) for k, v in out.items()}
        counts, overflow = counts, int(overflow)
    out["n_samples"] = int(n)
    out["hist_edges"] = edges
    out["hist_counts"] = counts
    out["hist_overflow"] = overflow
    return out


def _histogram(values: np.ndarray, edges: np.ndarray):
    """Counts per bin ``[edges[k], edges[k+1])`` along the last axis and the count at or above ``edges[-1]``.

    NaN samples are counted nowhere.
    """
    nb = edges.size - 1
    lead = values.shape[:-1]
    flat = values.reshape(-1, values.shape[-1])
    b = np.searchsorted(edges, flat, side="right") - 1  # bin index; nb means overflow
    b = np.where(np.isnan(flat), nb + 1, np.minimum(b, nb))
    rows = np.arange(flat.shape[0])[:, None] * (nb + 2)
    counts = np.bincount((rows + b).ravel(), minlength=flat.shape[0] * (nb + 2)).reshape(-1, nb + 2)
    return counts[:, :nb].reshape(*lead, nb), counts[:, nb].reshape(lead)


def abs_in_place(records: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """``|records| * scale`` computed in place (float32), as a (rows, samples) view: rows the first axis."""
    out = np.abs(records, out=records).reshape(records.shape[0], -1)
    if scale != 1.0:
        out *= np.float32(scale)
    return out


def percentiles_in_place(data: np.ndarray, qs) -> list:
    """Percentiles along axis 1 (numpy's default "linear" method), partitioning ``data`` in place."""
    m = data.shape[1]
    pos = [q / 100.0 * (m - 1) for q in qs]
    kth = sorted({int(math.floor(v)) for v in pos} | {min(int(math.floor(v)) + 1, m - 1) for v in pos})
    data.partition(kth, axis=1)
    out = []
    for v in pos:
        lo = int(math.floor(v))
        hi = min(lo + 1, m - 1)
        out.append(data[:, lo].astype(np.float64) + (v - lo) * (data[:, hi].astype(np.float64) - data[:, lo]))
    return out


def _geometric_histogram(values: np.ndarray, edges: np.ndarray):
    """Counts per row in the bins of :func:`histogram_edges` by bin index, and the overflow per row.

    Bin 0 is ``[0, edges[1])``; the geometric bins above are found from ``log(v / edges[1])``.
    """
    nb = edges.size - 1
    lo = np.float32(edges[1])
    inv_step = np.float32(1.0 / math.log(edges[2] / edges[1]))
    counts = np.zeros((values.shape[0], nb), dtype=np.int64)
    overflow = np.zeros(values.shape[0], dtype=np.int64)
    for j in range(values.shape[0]):  # slot nb counts the overflow
        with np.errstate(divide="ignore"):
            b = np.floor(np.log(values[j] / lo) * inv_step) + np.float32(1.0)
        c = np.bincount(np.clip(b, 0, nb).astype(np.intp), minlength=nb + 1)
        counts[j], overflow[j] = c[:nb], c[nb]
    return counts, overflow


def error_metrics_inplace(att_deg: np.ndarray, rate_deg_s: np.ndarray, actions: np.ndarray, saturation,
                          hist_edges: np.ndarray) -> dict:
    """:func:`error_metrics` of float32 rows of absolute samples, computed in place.

    Parameters
    ----------
    att_deg, rate_deg_s, actions : ndarray of float32, shape (rows, n)
        |attitude error| [deg], |rate error| [deg/s], |stick offset| [stick]; partitioned in place.
    saturation : ndarray, shape (rows,)
        Fraction of the samples at the stick limit (the caller knows where the command was clipped).
    hist_edges : ndarray
        Edges of :func:`histogram_edges` (0, then geometric).

    Returns
    -------
    dict
        :data:`METRIC_NAMES` as arrays (rows,) plus ``hist_counts`` (rows, nb) and ``hist_overflow`` (rows,).
    """
    counts, overflow = _geometric_histogram(att_deg, hist_edges)
    return {"hist_counts": counts, "hist_overflow": overflow,
            **_statistics(att_deg, rate_deg_s, actions, saturation)}


def _statistics(att: np.ndarray, rate: np.ndarray, act: np.ndarray, saturation) -> dict:
    """:data:`METRIC_NAMES` of rows (rows, n) of absolute samples, partitioning them in place: the one
    definition of the metrics, which the evaluator (:func:`error_metrics`) and the sweep
    (:func:`error_metrics_inplace`) both report."""
    out = {}
    for name, unit, data in (("att", "deg", att), ("rate", "dps", rate)):
        out[f"{name}_rms_{unit}"] = np.sqrt(np.mean(data * data, axis=1, dtype=np.float64))
        for q, row in zip(QUANTILES, percentiles_in_place(data, QUANTILES)):
            out[f"{name}_p{q}_{unit}"] = row
    out["stick_rms"] = np.sqrt(np.mean(act * act, axis=1, dtype=np.float64))
    out["stick_p99"] = percentiles_in_place(act, (99,))[0]
    out["saturation"] = np.asarray(saturation, dtype=np.float64)
    return out
