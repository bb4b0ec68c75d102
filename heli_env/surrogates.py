"""Gusts beyond the library: phase-randomised surrogates of its traces, with the same spectra and level.

Replaying a handful of recorded gust traces lets a learning controller overfit them. A surrogate of a
trace keeps the amplitude of every Fourier component of its u_d and draws new phases, so it has the same
power spectrum (and variance) on each axis but is a new gust; the three axes share their phases, which
keeps their cross-spectra too. The collective recorded with the trace is kept as it was (the yaw trim
needs it). :func:`surrogate_model` returns an :class:`~heli_env.env_model.EnvModel` whose library holds
``copies`` surrogates of every trace, which both environments replay as they replay the recorded one
(``HeliAttitudeVectorEnv(model=surrogate_model(load_env_model(DIR)))``); evaluation stays on the
recorded traces. ``scripts/surrogate_gusts.py`` measures how close the error distributions of a PD on
surrogates come to those on the recorded gusts.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .env_model import EnvModel


def phase_randomised(ud: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One surrogate of a (3, n) gust: every Fourier amplitude kept, new uniform phases shared by the axes.

    The mean (zero frequency) and, for even ``n``, the Nyquist component keep their phase, so the surrogate
    is real and has the trace's mean and variance exactly.
    """
    ud = np.asarray(ud, dtype=float)
    n = ud.shape[-1]
    spectrum = np.fft.rfft(ud, axis=-1)
    phases = rng.uniform(0.0, 2.0 * np.pi, spectrum.shape[-1])
    phases[0] = 0.0
    if n % 2 == 0:
        phases[-1] = 0.0
    return np.fft.irfft(spectrum * np.exp(1j * phases)[None, :], n=n, axis=-1)


def surrogate_model(env_model: EnvModel, copies: int = 4, seed: int = 0, pieces=None) -> EnvModel:
    """``env_model`` with its library replaced by ``copies`` phase-randomised surrogates of every trace.

    Parameters
    ----------
    env_model : EnvModel
    copies : int
        Surrogates per recorded trace, >= 1.
    seed : int
        Seeds the phases (``numpy.random.Generator``): same seed, same surrogates.
    pieces : sequence of (trace, first, end), optional
        Surrogates of these stretches of the traces only (samples ``first`` to ``end``, exclusive), e.g. the
        training side of a split, so that nothing of a held-out stretch enters; default every whole trace.

    Raises
    ------
    ValueError
        ``copies`` not a whole number >= 1.
    """
    if isinstance(copies, bool) or not isinstance(copies, (int, np.integer)) or copies < 1:
        raise ValueError(f"copies must be a whole number >= 1, got {copies!r}")
    rng = np.random.default_rng(seed)
    if pieces is None:
        pieces = [(t, 0, int(env_model.lengths[t])) for t in range(env_model.n_traces)]
    ud, gains, col, lengths, ids, sources = [], [], [], [], [], []
    for t, first, end in pieces:
        if not (0 <= t < env_model.n_traces and 0 <= first < end <= env_model.lengths[t]):
            raise ValueError(f"piece ({t}, {first}, {end}) is not a stretch of a library trace")
        s, n = int(env_model.starts[t]) + int(first), int(end) - int(first)
        for c in range(copies):
            ud.append(phase_randomised(env_model.ud[:, s:s + n], rng))
            gains.append(env_model.gains[:, t])
            col.append(env_model.collective[s:s + n])
            lengths.append(n)
            ids.append(f"{env_model.trace_ids[t]}~surrogate{c}")
            sources.append(env_model.sources[t])
    lengths = np.array(lengths, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    arrays = [np.ascontiguousarray(np.concatenate(ud, axis=1)), np.column_stack(gains),
              np.ascontiguousarray(np.concatenate(col)), starts, lengths]
    for a in arrays:
        a.setflags(write=False)
    return dataclasses.replace(env_model, ud=arrays[0], gains=arrays[1], collective=arrays[2], starts=arrays[3],
                               lengths=arrays[4], trace_ids=tuple(ids), sources=tuple(sources))
