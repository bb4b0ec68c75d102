"""Tune a firmware's own gains in the identified gusts: current, default and proposed sets, flown and compared.

:func:`tune_gains` takes the identified model with its disturbance library, the gains the aircraft flew and
the command scale, and:

1. sweeps, per axis, the firmware's own gains in the frequency domain
   (:mod:`controllers.firmware.tune_sweep`; :mod:`controllers.firmware.firmwares` says which gains) and
   keeps the sets with a gain margin of at least 6 dB, a phase margin of at least 45° and a delay margin of
   25 ms by default (``TuneConfig.delay_margin_s``; the loop broken at the axis' stick, at the loop's tick),
   best predicted p90 first;
2. flies, in the time domain, the current gains, the firmware's defaults and the best few robust candidates
   through the one batched closed loop (:func:`controllers.replay.fly` via
   :func:`controllers.firmware.autopilot.fly_firmware`): the firmware's loop at its own rate, the physics
   sub-stepped to it, against windows that tile the whole library (the identified wind replayed, with the
   model's sensors), every set flying all three axes at once;
3. proposes per axis (Rotorflight's roll and pitch together: they share ``angle_level_strength``) the
   candidate with the lowest time-domain p90 |attitude error|, and reports every set's p50/p90/p99 with
   their 90 % intervals (Woodruff's, over blocks of library time: :mod:`controllers.sweep_interval`), its
   margins, its frequency-domain p90 and, for the current and proposed sets, the response to a 10° step
   of the attitude reference (:mod:`controllers.firmware.step_response`, the flight-test card's raps).

An axis' time-domain figures of the proposed set come from the flown candidate whose gains it takes on that
axis (the candidates differ on every axis at once); the other axes' gains of that flight matter only through
the model's coupling terms. Where no candidate keeps the margins, the axis keeps its current gains and the
result says so.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from heli_core.terms import AXES

from ..closed_loop import disturbance_spectrum
from ..sweep_inputs import prepare
from ..sweep_interval import quantiles_at, woodruff_levels
from .autopilot import FirmwareAutopilot, fly_firmware
from .errors import FirmwareMappingError
from .step_response import step_response
from .tune_sweep import ROBUST_DELAY_MARGIN_S, AxisSweep, evaluate_sets, joint_choices, sweep_axis

_DEG = 180.0 / math.pi
QUANTILES = (50, 90, 99)
MAX_ANGLE_DEG = 60.0
NEAR_BEST = 0.10
"""The defaults are "already near best" on an axis when their p90 is within 10 % of the proposed one's."""


@dataclass(frozen=True)
class TuneConfig:
    """Settings of :func:`tune_gains`.

    Attributes
    ----------
    window_s : float
        Length of the gust windows flown in the time domain [s]; they tile every library trace.
    candidates : int
        Robust candidates per axis flown in the time domain.
    seed : int
        Seed of the windows' offsets and the sensor errors.
    sensors : bool
        The loop reads the state through the model's identified sensors.
    progress : bool
        A bar over the time-domain flights (on a terminal).
    max_batch : int
        Set × window states stepped at once.
    delay_margin_s : float
        Delay margin a robust set keeps besides 6 dB and 45° [s], >= 0 (0: none;
        :data:`controllers.firmware.tune_sweep.ROBUST_DELAY_MARGIN_S` by default, where it is measured).
    """

    window_s: float = 20.0
    candidates: int = 3
    seed: int = 0
    sensors: bool = True
    progress: bool = True
    max_batch: int = 4096
    delay_margin_s: float = ROBUST_DELAY_MARGIN_S

    def __post_init__(self):
        if not (math.isfinite(self.delay_margin_s) and 0.0 <= self.delay_margin_s <= 1.0):
            raise ValueError(f"delay_margin_s must be in [0, 1] s, got {self.delay_margin_s!r}")
        if not (math.isfinite(self.window_s) and self.window_s > 0):
            raise ValueError(f"window_s must be a positive number of seconds, got {self.window_s!r}")
        if int(self.candidates) != self.candidates or self.candidates < 1:
            raise ValueError(f"candidates must be a whole number >= 1, got {self.candidates!r}")


@dataclass(eq=False)
class TuneResult:
    """What a tune found (plain data; :mod:`controllers.firmware.tune_report` writes it up).

    Attributes
    ----------
    firmware : str
    spec : FirmwareSpec
    current, default, proposed : parameter sets
    scale : CommandScale
    loop_rate_hz, control_dt : float
    axes : dict
        Per axis name: ``{"current"|"default"|"proposed": {gains, p50_deg, p90_deg, p99_deg, their
        intervals, gain_margin_db, phase_margin_deg, fd_p90_deg, stable}, "defaults_near_best": bool,
        "proposed_beats_default": bool, "robust_candidates": int, "kept_current": bool}``.
    sweeps : dict of int to AxisSweep
    flown : list of dict
        Every set flown in the time domain: its label and its per-axis statistics.
    notes : list of str
    settings : dict
    """

    firmware: str
    spec: object
    current: object
    default: object
    proposed: object
    scale: object
    loop_rate_hz: float
    control_dt: float
    axes: dict
    sweeps: dict
    flown: list
    notes: list = field(default_factory=list)
    settings: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The document ``tune.json`` holds (``tune["axes"]["roll"]["proposed"]["p90_deg"]``)."""
        return {"schema": "heli-env/firmware-tune", "schema_version": 1, "firmware": self.firmware,
                "loop_rate_hz": self.loop_rate_hz, "control_dt_s": self.control_dt,
                "command_scale": self.scale.to_dict(), "axes": self.axes,
                "sweeps": {AXES[a]: s.to_dict() for a, s in self.sweeps.items()},
                "flown": self.flown, "notes": list(self.notes), "settings": self.settings}


def control_signs(model_params) -> tuple:
    """Signs of the model's control gains; :class:`FirmwareMappingError` for an axis the sticks cannot move."""
    gains = np.asarray(model_params.control_gains, dtype=float)
    for axis, name, k in zip(AXES, ("k2", "k6", "k10"), gains):
        if k == 0.0 or not math.isfinite(k):
            raise FirmwareMappingError(f"the model's {axis} control gain {name} is {k:g}: the firmware's {axis} "
                                       "loop cannot be mapped to the model's sticks")
    return tuple(float(v) for v in np.sign(gains))


def axis_statistics(values_deg: np.ndarray, blocks) -> dict:
    """p50, p90, p99 of |error| [deg] (samples (N,) in the replay's layout) with their 90 % intervals."""
    A = np.abs(values_deg.astype(np.float64))[None, :]
    ids, adjacent = np.asarray(blocks[0]).ravel(), blocks[1]
    out = {}
    for q in QUANTILES:
        levels = woodruff_levels(A, ids, adjacent, q / 100.0)
        lo, hi = quantiles_at(A.copy(), levels)[0]
        out[f"p{q}_deg"] = float(np.percentile(A[0], q))
        out[f"p{q}_deg_interval"] = [None if not math.isfinite(lo) else float(lo),
                                     None if not math.isfinite(hi) else float(hi)]
    return out


def _fly_sets(env_model, spec, sets, scale, signs, dt, cfg: TuneConfig) -> list:
    """Time-domain statistics per set and axis: a list (per set) of dicts (per axis name)."""
    rp = prepare(env_model, "roll", cfg.window_s, dt, cfg.seed, None, None, sensors=cfg.sensors)
    auto = FirmwareAutopilot(spec.loop_class, tuple(sets), scale, signs, dt)
    per_set = [None] * len(sets)
    for sl, rec in fly_firmware(env_model.params, rp.inputs, auto, cfg.max_batch, cfg.progress,
                                f"{spec.name} loop, {len(sets)} sets"):
        for j in range(sl.stop - sl.start):
            att = rec.axes[:, j] * _DEG  # (3, n, W)
            bad = (not np.all(np.isfinite(att))) or np.max(np.abs(att[:2])) > MAX_ANGLE_DEG
            if bad:
                per_set[sl.start + j] = {a: {"diverged": True} for a in AXES}
                continue
            per_set[sl.start + j] = {AXES[i]: {**axis_statistics(att[i].ravel(), rp.blocks), "diverged": False}
                                     for i in range(3)}
    windows = {"count": len(rp.windows), "window_s": cfg.window_s,
               "library_s": float(len(rp.windows) * rp.steps * dt)}
    return per_set, windows


def _fd_row(spec, params, axis, model_params, scale, signs, m, freq, psd, collective) -> dict:
    radius, stable, p90, gm, pm, dm = evaluate_sets(spec, [params], axis, model_params, scale, signs, m, freq, psd,
                                                    collective)
    return {"stable": bool(stable[0]), "spectral_radius": float(radius[0]), "fd_p90_deg": float(p90[0]),
            "gain_margin_db": float(gm[0]), "phase_margin_deg": float(pm[0]), "delay_margin_s": float(dm[0])}


def tune_gains(env_model, spec, current, scale, config: TuneConfig | None = None, stage=None) -> TuneResult:
    """Tune ``spec``'s gains for the model (module docstring).

    Parameters
    ----------
    env_model : heli_env.env_model.EnvModel
        The identified model and its disturbance library.
    spec : FirmwareSpec
    current : parameter set
        The gains the aircraft flew.
    scale : CommandScale
    config : TuneConfig, optional
    stage : callable, optional
        ``stage(text)`` announces each step (``heli tune``'s progress).
    """
    cfg = config or TuneConfig()
    say = stage or (lambda text: None)
    t_start = time.perf_counter()
    params = env_model.params
    signs = control_signs(params)
    dt = 1.0 / env_model.sample_rate
    m = spec.loop_class(current, scale.scale, signs).substeps(dt)
    freq, psd = disturbance_spectrum(env_model, dt)
    collective = float(np.mean(env_model.collective))
    defaults = spec.defaults(current)
    sweeps = {}
    for axis in range(3):
        say(f"sweeping {' x '.join(spec.swept[axis])} on {AXES[axis]} (frequency domain, margins at "
            f"{current.loop_rate_hz:g} Hz)")
        sweeps[axis] = sweep_axis(spec, current, axis, params, scale.scale, signs, m, freq, psd, collective,
                                  cfg.delay_margin_s)
    groups = {g: joint_choices(sweeps, g, cfg.candidates) for g in spec.joint}
    n_cand = max([len(c) for c in groups.values()] + [0])
    sets, labels = [current, defaults], ["current", "default"]
    for j in range(n_cand):
        s = current
        for g, choices in groups.items():
            if choices:
                pick = choices[min(j, len(choices) - 1)]
                for ax in g:
                    s = spec.merge(s, sweeps[ax].sets[pick[ax]], (ax,))
        sets.append(s)
        labels.append(f"candidate {j + 1}")
    say(f"flying {len(sets)} gain sets in the identified gusts (the {spec.name} loop at {current.loop_rate_hz:g} Hz, "
        f"physics sub-stepped {m}x per {dt:g} s)")
    flown, windows = _fly_sets(env_model, spec, sets, scale.scale, signs, dt, cfg)
    proposed, chosen, notes = _choose(spec, current, sets, flown, groups, cfg.delay_margin_s)
    notes += _edge_notes(spec, proposed, chosen)
    say("margins, the frequency-domain prediction and the 10 deg step responses of the current, default and "
        "proposed sets")
    axes = {}
    for axis in range(3):
        name = AXES[axis]
        row = {}
        for label, p, j in (("current", current, 0), ("default", defaults, 1), ("proposed", proposed, chosen[axis])):
            fd = _fd_row(spec, p, axis, params, scale.scale, signs, m, freq, psd, collective)
            row[label] = {"gains": spec.axis_gains(p, axis), **flown[j][name], **fd, "flown_set": labels[j]}
            if label != "default":
                row[label]["step"] = step_response(spec, p, params, scale.scale, signs, axis, collective=collective)
        row.update(_verdicts(row, sweeps[axis]))
        row["kept_current"] = chosen[axis] == 0
        axes[name] = row
    settings = {"windows": windows, "seed": cfg.seed, "sensors": cfg.sensors, "substeps": m,
                "min_delay_margin_s": cfg.delay_margin_s,
                "candidates_flown": n_cand, "collective": collective, "seconds": time.perf_counter() - t_start,
                "sets": [{"label": lab, "values": spec.names(s)} for lab, s in zip(labels, sets)]}
    flown_rows = [{"label": lab, "axes": f} for lab, f in zip(labels, flown)]
    return TuneResult(spec.name, spec, current, defaults, proposed, scale, float(current.loop_rate_hz), dt, axes,
                      sweeps, flown_rows, notes + list(scale.notes), settings)


def _p90(stats: dict) -> float:
    return math.inf if stats.get("diverged", True) else stats["p90_deg"]


def _choose(spec, current, sets, flown, groups, min_delay_s: float = ROBUST_DELAY_MARGIN_S):
    """The proposed set, the flown set each axis' figures come from, and notes."""
    proposed, chosen, notes = current, {0: 0, 1: 0, 2: 0}, []
    for g, choices in groups.items():
        names = "/".join(AXES[a] for a in g)
        if not choices:
            notes.append(f"{names}: no swept set keeps a 6 dB gain margin, a 45 deg phase margin and a "
                         f"{min_delay_s * 1000:g} ms delay margin; the current gains are kept")
            continue
        best_j, best = None, math.inf
        for j in range(2, len(sets)):  # set j carries each group's choice j - 2 (or its last)
            total = sum(_p90(flown[j][AXES[ax]]) for ax in g)
            if total < best:
                best_j, best = j, total
        if best_j is None:
            notes.append(f"{names}: every robust candidate diverged in the time domain; the current gains are kept")
            continue
        proposed = spec.merge(proposed, sets[best_j], g)
        for ax in g:
            chosen[ax] = best_j
    return proposed, chosen, notes


def _edge_notes(spec, proposed, chosen) -> list:
    """A note for each swept gain of the proposal at the end of its grid (the firmware's documented range, or
    the sweep's own end): the optimum may lie beyond."""
    notes = []
    for axis in range(3):
        if chosen[axis] == 0:
            continue
        gains = spec.axis_gains(proposed, axis)
        for name, values in zip(spec.swept[axis], spec.grid(axis)):
            v = gains.get(name)
            if v is not None and (math.isclose(v, values.min(), rel_tol=1e-3) or math.isclose(v, values.max(), rel_tol=1e-3)):
                end = "top" if math.isclose(v, values.max(), rel_tol=1e-3) else "bottom"
                notes.append(f"{AXES[axis]}: {name} = {v:.4g} is at the {end} of the swept range "
                             f"[{values.min():.4g}, {values.max():.4g}] (the firmware's documented range where it "
                             "has one): the best set may lie beyond it")
    return notes


def _verdicts(row: dict, sweep: AxisSweep) -> dict:
    """Whether the proposed set beats the defaults (time domain, keeping the margins) and whether the defaults
    are already near best."""
    from .tune_sweep import robust

    prop, default = row["proposed"], row["default"]
    p_prop, p_def = _p90(prop), _p90(default)
    robust_default = bool(robust(default["stable"], default["gain_margin_db"], default["phase_margin_deg"],
                                 default["delay_margin_s"], sweep.min_delay_margin_s))
    return {"proposed_beats_default": bool(p_prop < p_def), "default_robust": robust_default,
            "defaults_near_best": bool(robust_default and math.isfinite(p_def) and p_def <= (1 + NEAR_BEST) * p_prop),
            "robust_candidates": int(sweep.robust.sum()), "swept_sets": int(sweep.a.size)}
