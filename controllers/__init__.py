"""Controllers for the identified models: PD designs (python-control), RL agents, sweeps and evaluation."""
from .pd import PDController, PDGains, design_gains, loop_analysis, plant, propose_gains  # noqa: F401
