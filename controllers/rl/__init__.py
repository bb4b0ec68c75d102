"""RL attitude agents with stable-baselines3: training on the vector env, checkpoints, loading any agent.

One concept per module:

* :mod:`~controllers.rl.config`: :class:`TrainConfig`, the settings of a run, checked once;
* :mod:`~controllers.rl.train`: :func:`train_agent`, one PPO or SAC agent on the
  training gusts, with held-out evaluations, atomic checkpoints and a record;
* :mod:`~controllers.rl.seeds`: :func:`train_seeds`, one agent per seed (and
  hyperparameter set) as tasks of a compute backend;
* :mod:`~controllers.rl.agent_file`: the agent zip and :func:`load_agent`, which
  loads a PD controller JSON or a PPO/SAC zip alike;
* :mod:`~controllers.rl.residual_agent`: residual RL, a bounded learnt correction on a PD (the base PD is
  flown to scale it by :func:`~controllers.rl.train.residual_setup`);
* :mod:`~controllers.rl.vec_env`: the native vector env seen through SB3's ``VecEnv``.

The stable-baselines3 callbacks and the observation scaler stay in
:mod:`controllers.sb3_training`: saved agents name that module. stable-baselines3
and torch are the ``rl`` extra, imported when an agent is trained or loaded.
"""

from ..trace_split import TraceSegment, TraceSplit, WindowSampler, as_segments, split_traces
from .agent_file import AGENT_SCHEMA, AGENT_SCHEMA_VERSION, ALGOS, METADATA_FILE, agent_metadata, load_agent
from .config import (DEFAULT_KWARGS, RESIDUAL_HISTORY, RESIDUAL_KWARGS, RESIDUAL_REWARD_WEIGHTS, RESIDUAL_SDE_KWARGS,
                     TrainConfig, make_config)
from .residual_agent import RESIDUAL_INIT_DEG, RESIDUAL_SCALE, residual_from_metadata, residual_metadata
from .seeds import train_seeds
from .train import TrainingResult, train_agent

__all__ = ["AGENT_SCHEMA", "AGENT_SCHEMA_VERSION", "ALGOS", "DEFAULT_KWARGS", "METADATA_FILE",
           "RESIDUAL_HISTORY", "RESIDUAL_INIT_DEG", "RESIDUAL_KWARGS", "RESIDUAL_REWARD_WEIGHTS", "RESIDUAL_SCALE",
           "RESIDUAL_SDE_KWARGS", "TraceSegment", "TraceSplit", "TrainConfig", "TrainingResult", "WindowSampler",
           "agent_metadata", "as_segments", "load_agent", "make_config", "residual_from_metadata",
           "residual_metadata", "split_traces", "train_agent", "train_seeds"]
