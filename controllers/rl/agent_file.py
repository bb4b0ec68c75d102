"""The agent file: what an RL agent's zip holds and how any agent is loaded back.

An agent is a stable-baselines3 zip (PPO or SAC) that carries ``heli_agent.json``
beside SB3's own entries (algo, split, settings; for a residual agent the base PD
and the bound), a PD controller JSON (:meth:`controllers.pd.PDController.save`) or an
LQG controller JSON (:meth:`controllers.lqg.LQGController.save`).
:func:`load_agent` tells them apart by content and returns an object with SB3's
``predict``; :func:`agent_metadata` reads the zip's ``heli_agent.json``.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

from heli_core.errors import require

from ..errors import AgentError
from ..trace_split import TraceSplit
from .residual_agent import residual_from_metadata

ALGOS = ("ppo", "sac")
AGENT_SCHEMA = "heli-env/rl-agent"
AGENT_SCHEMA_VERSION = 1
METADATA_FILE = "heli_agent.json"


def _sb3():
    return require("stable_baselines3", "rl")


def _algo_class(algo: str):
    sb3 = _sb3()
    return {"ppo": sb3.PPO, "sac": sb3.SAC}[algo]



def agent_metadata(path) -> dict | None:
    """The ``heli_agent.json`` an RL agent zip carries (algo, split, settings), or None.

    Raises
    ------
    AgentError
        The entry is not a JSON object, or its ``split`` is not a trace split
        (:meth:`TraceSplit.from_dict`).
    """
    path = _resolve(path)
    if not zipfile.is_zipfile(path):
        return None
    with zipfile.ZipFile(path) as z:
        if METADATA_FILE not in z.namelist():
            return None
        meta = _zip_json(z, METADATA_FILE, path, "the agent's metadata (algo, split, settings)")
    if meta.get("split"):
        try:
            TraceSplit.from_dict(meta["split"])
        except ValueError as e:
            raise AgentError(f"{path}: {METADATA_FILE} entry 'split' is not a trace split ({e})") from e
    return meta


def _zip_json(z: zipfile.ZipFile, entry: str, path: Path, expected: str) -> dict:
    """The JSON object in entry ``entry`` of an open zip; AgentError naming the file if it is anything else."""
    try:
        doc = json.loads(z.read(entry))
    except (ValueError, zipfile.BadZipFile) as e:  # JSONDecodeError, UnicodeDecodeError, a corrupt member
        raise AgentError(f"{path}: zip entry {entry!r} should be a JSON object holding {expected}; "
                         f"it cannot be read as JSON ({e})") from e
    if not isinstance(doc, dict):
        raise AgentError(f"{path}: zip entry {entry!r} should be a JSON object holding {expected}; "
                         f"got a JSON {type(doc).__name__}")
    return doc


def _resolve(path) -> Path:
    path = Path(path)
    if not path.exists() and path.suffix != ".zip" and path.with_name(path.name + ".zip").exists():
        path = path.with_name(path.name + ".zip")
    if not path.exists():
        raise FileNotFoundError(f"agent file {str(path)!r} does not exist")
    if path.is_dir():
        raise AgentError(f"{path} is a folder; expected a PD controller JSON or a PPO/SAC zip")
    return path


def _zip_algo(path: Path) -> str:
    """"ppo" or "sac" from the agent zip's metadata, else from SB3's saved policy class and optimizers."""
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        if METADATA_FILE in names:
            algo = _zip_json(z, METADATA_FILE, path, "the agent's metadata (algo, split, settings)").get("algo")
            if algo in ALGOS:
                return algo
        if "data" not in names:
            raise AgentError(f"{path}: a zip file but not a stable-baselines3 agent (no 'data' entry)")
        data = _zip_json(z, "data", path, "stable-baselines3's saved model data")
    policy_class = data.get("policy_class")
    module = str(policy_class.get("__module__", "")) if isinstance(policy_class, dict) else ""
    if ".sac." in module or "actor.optimizer.pth" in names:
        return "sac"
    if "policy.optimizer.pth" in names and ("common.policies" in module or ".ppo." in module):
        return "ppo"
    raise AgentError(f"{path}: a stable-baselines3 agent of policy {module or 'unknown'}; only PPO and SAC load")


def load_agent(path):
    """Load any agent: a PD or LQG controller JSON (:meth:`controllers.pd.PDController.load`,
    :meth:`controllers.lqg.LQGController.load`) or a PPO/SAC zip.

    The kind is read from the file, not its name: a zip is an SB3 agent (its
    ``heli_agent.json``, else SB3's saved policy class, tells PPO from SAC), a JSON of
    the LQG schema an LQG controller, anything else must be a PD controller JSON.
    ``agents/ppo`` finds ``agents/ppo.zip``.

    Returns
    -------
    PDController, LQGController, stable_baselines3 PPO / SAC, or ResidualAgent (a PPO / SAC residual on a PD)
        Each has ``predict(observation, state=None, episode_start=None, deterministic=False)``.

    Raises
    ------
    FileNotFoundError
        No such file.
    AgentError
        Neither kind, an agent zip whose metadata or model data is not readable JSON,
        an SB3 agent of another algorithm, or an LQG file with bad matrices.
    """
    path = _resolve(path)
    if zipfile.is_zipfile(path):
        algo = _zip_algo(path)
        try:
            policy = _algo_class(algo).load(path, device="cpu")
        except (ValueError, KeyError, RuntimeError) as e:
            raise AgentError(f"{path}: cannot load the {algo.upper()} agent: {e}") from e
        meta = agent_metadata(path) or {}
        return residual_from_metadata(meta, policy, path) if meta.get("residual") else policy
    from ..lqg.controller import SCHEMA as LQG_SCHEMA
    from ..lqg.controller import LQGController
    from ..pd.controller import PDController

    if _json_schema(path) == LQG_SCHEMA:
        return LQGController.load(path)
    try:
        return PDController.load(path)
    except (ValueError, UnicodeDecodeError) as e:
        raise AgentError(f"{path}: neither a PPO/SAC zip nor a PD controller JSON nor an LQG one ({e})") from e


def _json_schema(path: Path):
    """The ``schema`` entry of a JSON object file, or None (not JSON, not an object, no entry)."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError):
        return None
    return doc.get("schema") if isinstance(doc, dict) else None
