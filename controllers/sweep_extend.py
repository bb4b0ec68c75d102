"""A grid sweep that grows until its best pair is interior: the edges, their continuation, the grown grid.

A sweep's best pair (the smallest p90 |attitude error| among the stable pairs,
:func:`best_index`) on an edge of the Kp × Kd grid says that the best gains may
lie beyond the grid. :func:`extend_grid` then continues the grid past that edge
— :data:`EXTENSION_VALUES` more values per round, the grid's last ratio continued
geometrically (:func:`continuation`) — sweeps the new pairs on the same gust
windows, and repeats until one of these holds (the *stop* of the result's
``settings["extension"]``):

* ``"interior"`` — the best pair has neighbours on every side;
* ``"unstable beyond"`` — on each edge the best pair lies on, the pair just beyond
  it is unstable (closed-loop poles) or keeps no gain or phase margin: the best
  pair sits at the stability boundary, a limit of the gains, not of the grid;
* ``"bound"`` — an edge that cannot be continued: gain 0 on it, or an axis given
  as one value or not increasing (where one edge is bound and another held by
  instability, the stop is ``"unstable beyond"``);
* ``"limit"`` — ``max_extensions`` rounds ran and the best pair still lies on an
  edge that could grow;
* ``"no stable pair"`` — nothing to grow from;
* ``"disabled"`` — no extension asked (``extend=False``, ``heli sweep --no-extend``)
  or a list of pairs, which is no grid.

Every pair's row is computed on its own (the replay and the frequency-domain
prediction are per pair, the windows are drawn once), so the grown grid's table
equals a sweep of the final grid at once, bit for bit (``tests/test_sweep.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

EXTENSION_VALUES = 3
"""Values added beyond an edge per round."""
MAX_EXTENSIONS = 4
"""Rounds of extension at most, by default."""
STOPS = ("interior", "unstable beyond", "bound", "limit", "no stable pair", "disabled")
"""Why the extension of a grid stopped (see the module docstring)."""

_GAIN_NAME = {"kp": "Kp", "kd": "Kd"}


def best_index(table: dict, by: str = "att_p90_deg", among=None) -> int | None:
    """Row of the stable pair with the smallest ``by`` (optionally only ``among`` a boolean mask), or None."""
    ok = np.asarray(table["status"]) == "stable"
    if among is not None:
        ok &= np.asarray(among, dtype=bool)
    v = np.where(ok, np.asarray(table[by], dtype=float), np.nan)
    if not np.any(np.isfinite(v)):
        return None
    return int(np.nanargmin(v))


def continuation(values, side: str, n: int = EXTENSION_VALUES):
    """``n`` gains beyond the ``"low"`` or ``"high"`` edge of a grid axis, ascending; None where it cannot grow.

    Upwards: ``v[-1]·r^k`` with ``r = v[-1]/v[-2]``: a geometric grid goes on as it was, a linear
    one at the ratio of its last two values (its steps grow); ``r = 2`` when ``v[-2] = 0``. Downwards:
    ``v[0]/r^k`` with ``r = v[1]/v[0]``; none below a gain of 0.

    Returns
    -------
    (ndarray (n,) or None, str)
        The gains, or None and why the axis cannot grow on that side.
    """
    v = np.asarray(values, dtype=float)
    if v.size < 2:
        return None, "the axis was given as one value"
    if np.any(np.diff(v) <= 0):
        return None, "the axis' values do not increase"
    k = np.arange(1, n + 1)
    if side == "high":
        r = v[-1] / v[-2] if v[-2] > 0 else 2.0
        return v[-1] * r**k, ""
    if v[0] == 0:
        return None, "no gain below 0"
    return (v[0] / (v[1] / v[0]) ** k)[::-1], ""


@dataclass(frozen=True)
class Edge:
    """One edge of the grid a pair lies on, with the gains that would continue the grid past it."""

    gain: str
    """"kp" or "kd"."""
    side: str
    """"low" or "high", or "only" for an axis of one value (both its edges)."""
    values: object
    """ndarray (n,) ascending, or None when the edge cannot be continued."""
    why: str = ""
    """Why it cannot be continued ("no gain below 0", ...)."""

    @property
    def name(self) -> str:
        if self.side == "only":
            return f"only {_GAIN_NAME[self.gain]} value"
        return f"{'lower' if self.side == 'low' else 'upper'} {_GAIN_NAME[self.gain]} edge"

    def beyond(self, kp: float, kd: float) -> tuple[float, float]:
        """The pair just past the edge from ``(kp, kd)``."""
        nxt = float(self.values[0] if self.side == "high" else self.values[-1])
        return (nxt, kd) if self.gain == "kp" else (kp, nxt)


def grid_edges(kp_values, kd_values, i_kp: int, i_kd: int, n: int = EXTENSION_VALUES) -> list:
    """The :class:`Edge` s of the grid that the pair ``(kp_values[i_kp], kd_values[i_kd])`` lies on."""
    edges = []
    for gain, values, i in (("kp", kp_values, i_kp), ("kd", kd_values, i_kd)):
        if len(values) == 1:
            edges.append(Edge(gain, "only", None, "the axis was given as one value"))
            continue
        for side, on in (("low", i == 0), ("high", i == len(values) - 1)):
            if on:
                edges.append(Edge(gain, side, *continuation(values, side, n)))
    return edges


@dataclass
class PairBlock:
    """Results of a batch of gain pairs, row by row: table columns, histograms, kept samples."""

    table: dict
    hist: np.ndarray
    overflow: np.ndarray
    samples: dict = field(default_factory=dict)

    def placed(self, positions: np.ndarray, other: PairBlock, other_positions: np.ndarray) -> PairBlock:
        """This block's rows at ``positions`` and ``other``'s at ``other_positions`` of one larger block."""
        n = positions.size + other_positions.size

        def merge(a, b):
            dtype = object if object in (a.dtype, b.dtype) else np.result_type(a, b)
            out = np.empty((n,) + a.shape[1:], dtype=dtype)
            out[positions], out[other_positions] = a, b
            return out

        table = {c: merge(np.asarray(v), np.asarray(other.table[c])) for c, v in self.table.items()}
        samples = {int(positions[k]): v for k, v in self.samples.items()}
        samples.update({int(other_positions[k]): v for k, v in other.samples.items()})
        return PairBlock(table, merge(self.hist, other.hist), merge(self.overflow, other.overflow), samples)


def _grow(kp_values, kd_values, block, edges, evaluate, round_no):
    """The grid continued past ``edges``, with the new pairs evaluated; ``(kp, kd, block, round record)``."""
    low, high = {"kp": np.empty(0), "kd": np.empty(0)}, {"kp": np.empty(0), "kd": np.empty(0)}
    for e in edges:
        (low if e.side == "low" else high)[e.gain] = e.values
    kp_new = np.concatenate([low["kp"], kp_values, high["kp"]])
    kd_new = np.concatenate([low["kd"], kd_values, high["kd"]])
    rows = low["kp"].size + np.arange(kp_values.size)
    cols = low["kd"].size + np.arange(kd_values.size)
    old = (rows[:, None] * kd_new.size + cols[None, :]).ravel()
    new = np.setdiff1d(np.arange(kp_new.size * kd_new.size), old)
    KP, KD = np.meshgrid(kp_new, kd_new, indexing="ij")
    added = evaluate(KP.ravel()[new], KD.ravel()[new])
    added.table["extension_round"] = np.full(new.size, round_no)
    record = {"round": round_no, "edges": [e.name for e in edges],
              "kp_added": np.concatenate([low["kp"], high["kp"]]).tolist(),
              "kd_added": np.concatenate([low["kd"], high["kd"]]).tolist(), "pairs_added": int(new.size)}
    return kp_new, kd_new, block.placed(old, added, new), record


def _best_summary(table, i) -> dict:
    return {"kp": float(table["kp"][i]), "kd": float(table["kd"][i]), "att_p90_deg": float(table["att_p90_deg"][i])}


def _open_edges(edges, kp, kd, beyond_fault):
    """The edges the grid can grow past from ``(kp, kd)``, and ``(stop, words)`` for each held one."""
    open_edges, held = [], []
    for e in edges:
        fault = e.why if e.values is None else beyond_fault(*e.beyond(kp, kd))
        if fault is None:
            open_edges.append(e)
        elif e.values is None:
            held.append(("bound", f"the {e.name} ({fault})"))
        else:
            held.append(("unstable beyond", "the {} (Kp {:.4g}, Kd {:.4g} beyond it is {})".format(
                e.name, *e.beyond(kp, kd), fault)))
    return open_edges, held


def extend_grid(kp_values, kd_values, block: PairBlock, evaluate, beyond_fault, max_extensions: int,
                n: int = EXTENSION_VALUES):
    """Grow a swept grid until its best pair is interior or a limit holds (see the module docstring).

    Parameters
    ----------
    kp_values, kd_values : ndarray (n_kp,), (n_kd,)
        The swept grid [stick/rad], [stick/(rad/s)].
    block : PairBlock
        Its results in Kp-major order, with an ``extension_round`` column.
    evaluate : callable (kp (m,), kd (m,)) -> PairBlock
        Sweeps new pairs on the same windows.
    beyond_fault : callable (kp, kd) -> str or None
        What stops the grid growing towards a pair ("unstable", ...), or None when nothing does.
    max_extensions : int
        Rounds at most.
    n : int
        Values added beyond an edge per round.

    Returns
    -------
    kp_values, kd_values, block, record
        The grown grid, its results and the record kept in ``settings["extension"]``: the rounds
        (edges, gains and number of pairs added, the best pair before), ``stop`` (one of :data:`STOPS`)
        and ``stop_detail`` in words.
    """
    rounds = []
    while True:
        i = best_index(block.table)
        if i is None:
            stop, detail = "no stable pair", "no stable pair to grow the grid from"
            break
        i_kp, i_kd = divmod(i, kd_values.size)
        kp, kd = float(kp_values[i_kp]), float(kd_values[i_kd])
        edges = grid_edges(kp_values, kd_values, i_kp, i_kd, n)
        if not edges:
            stop, detail = "interior", f"the best pair (Kp {kp:.4g}, Kd {kd:.4g}) is inside the grid"
            break
        open_edges, held = _open_edges(edges, kp, kd, beyond_fault)
        where = f"the best pair (Kp {kp:.4g}, Kd {kd:.4g}) lies on " + " and ".join(
            [f"the {e.name}" for e in open_edges] + [h[1] for h in held])
        if not open_edges:
            stop = "unstable beyond" if any(h[0] == "unstable beyond" for h in held) else "bound"
            detail = where
            break
        if len(rounds) >= max_extensions:
            stop, detail = "limit", where + (f", after {len(rounds)} extension{'s' * (len(rounds) != 1)}"
                                             if rounds else "")
            break
        before = _best_summary(block.table, i)
        kp_values, kd_values, block, record = _grow(kp_values, kd_values, block, open_edges, evaluate,
                                                    len(rounds) + 1)
        rounds.append({**record, "best_before": before})
    return kp_values, kd_values, block, {"rounds": rounds, "stop": stop, "stop_detail": detail}
