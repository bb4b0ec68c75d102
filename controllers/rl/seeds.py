"""Training PPO or SAC agents on many seeds (and hyperparameter sets), each seed one task of a backend.

:func:`train_seeds` runs :func:`controllers.rl.train.train_agent` once per
(config, seed) on :mod:`heli_core.backends`: each task trains in a scratch
folder and sends its files back with its result, so a worker on another node
needs no shared file system; the files are then written here, atomically.
"""

from __future__ import annotations

import dataclasses
import json
import numbers
from pathlib import Path

from ..errors import AgentError
from .config import TrainConfig, make_config
from .train import TrainingResult, _out_paths, train_agent

WATCH_OPTIONS = ("progress", "verbose")
"""Keywords of :func:`train_agent` that say how a run is watched, not what is trained (no TrainConfig field)."""


def _run_name(out, key) -> Path:
    stem = _out_paths(out)[0].with_suffix("")
    name, seed = key if isinstance(key, tuple) else (None, key)
    return stem.with_name(stem.name + (f"_{name}" if name is not None else "") + f"_seed{seed}")


def _train_task(item, shared):
    """One backend task: train one (config, seed) in a scratch folder; return the result and the files' bytes.

    The files travel back with the result, so a worker on another node needs no
    shared file system, and a task rerun after a dead worker leaves nothing behind.
    """
    import tempfile

    key, overrides = item
    env_model, out, config, watch = shared
    seed = key[1] if isinstance(key, tuple) else key
    name = _run_name(out, key).name
    with tempfile.TemporaryDirectory(prefix="heli-train-") as tmp:
        res = train_agent(model=env_model, out=Path(tmp) / name, config=config,
                          **{"seed": seed, "progress": False, **watch, **overrides})
        files = {str(p.relative_to(tmp)): p.read_bytes() for p in sorted(Path(tmp).rglob("*")) if p.is_file()}
        res.agent = None  # the zip carries it; a live SB3 model does not travel well
        return res, str(Path(tmp)), files


def train_seeds(algo: str | None = None, model=None, timesteps: int | None = None, out="agent", seeds=(0,),
                configs: dict | None = None, backend=None, progress: bool = True, *,
                config: TrainConfig | None = None, **train_kwargs) -> dict:
    """Train one agent per seed (and per hyperparameter set), each as one task of a backend.

    Parameters
    ----------
    algo, model, timesteps, config :
        As :func:`train_agent`: the settings shared by all tasks (``config.seed`` is replaced by each seed).
    out : str or Path
        Stem of the agents: seed ``s`` is written to ``<out>_seed<s>.zip`` and
        ``<out>_seed<s>_training/`` (``<out>_<name>_seed<s>`` with ``configs``).
    seeds : sequence of int
        One agent per seed, each seeded as :func:`train_agent` with that seed.
    configs : dict of str -> dict, optional
        Named overrides of :class:`TrainConfig` fields (or ``verbose``) (e.g.
        ``{"lr1e-3": {"algo_kwargs": {"learning_rate": 1e-3}}}``); every config is
        trained with every seed.
    backend : None, {"local", "ray"} or heli_core.backends.Backend
        Where the tasks run (None: the local cores). Each task trains with the
        config's torch threads (one by default), so a seed trains to the same agent
        on any backend and worker count.
    progress : bool
        tqdm bar of finished tasks (per-task bars are off).
    **train_kwargs
        :class:`TrainConfig` fields replacing the config's, and ``verbose``, shared by all tasks.

    Returns
    -------
    dict
        ``{seed: TrainingResult}``, or ``{(name, seed): TrainingResult}`` with ``configs``,
        in the order of ``configs`` and ``seeds``. Paths point at the files written
        here; ``agent`` is None (``load_agent(result.path)``).

    Raises
    ------
    AgentError
        No or repeated seeds, bad configs (checked before any task runs), or what :func:`train_agent` raises.
    heli_core.errors.MissingDependency
        ``backend="ray"`` without the ``cluster`` extra.
    """
    from heli_core.backends import make_backend

    seeds = list(seeds)
    if not seeds or len(set(seeds)) != len(seeds) or not all(
            isinstance(s, numbers.Integral) and not isinstance(s, bool) for s in seeds):
        raise AgentError(f"seeds must be distinct whole numbers, at least one, got {seeds!r}")
    for bad in ("seed", "callbacks"):
        if bad in train_kwargs:
            raise AgentError(f"train_seeds takes seeds=, not {bad}= (callbacks do not travel to workers)")
    if configs is not None and (not isinstance(configs, dict) or not configs or not all(
            isinstance(k, str) and isinstance(v, dict) and "seed" not in v for k, v in configs.items())):
        raise AgentError("configs must be a non-empty dict of name -> dict of train_agent arguments (no seed)")
    watch = {k: v for k, v in train_kwargs.items() if k in WATCH_OPTIONS}
    config = make_config(config, algo, timesteps, **{k: v for k, v in train_kwargs.items() if k not in watch})
    for over in (configs or {}).values():  # a bad named config fails here, not in a worker
        make_config(config, **{k: v for k, v in over.items() if k not in WATCH_OPTIONS})
    from heli_env.env_model import as_env_model

    env_model = as_env_model(model)
    if configs is None:
        items = [(int(s), {}) for s in seeds]
    else:
        items = [((name, int(s)), dict(over)) for name, over in configs.items() for s in seeds]
    be = make_backend(backend)
    try:
        parts = be.map(_train_task, items, (env_model, out, config, watch), progress=progress,
                       desc=f"train {config.algo}")
    finally:
        if be is not backend:
            be.close()
    results = {}
    for (key, _), (res, tmp, files) in zip(items, parts):
        results[key] = _place(res, tmp, files, _run_name(out, key).parent)
    return results


def _place(res: TrainingResult, tmp: str, files: dict, folder: Path) -> TrainingResult:
    """Write a task's files under ``folder`` (atomically, file by file) and point ``res`` at them."""
    from heli_core.files import write_bytes

    def moved(p):
        return None if p is None else folder / Path(p).relative_to(tmp)

    for rel, data in files.items():
        if rel.endswith("training.json"):  # its paths name the scratch folder
            data = data.decode().replace(json.dumps(tmp)[1:-1], json.dumps(str(folder))[1:-1]).encode()
        write_bytes(folder / rel, data)
    return dataclasses.replace(res, path=moved(res.path), run_dir=moved(res.run_dir),
                               checkpoints=[moved(p) for p in res.checkpoints], best_model=moved(res.best_model))

