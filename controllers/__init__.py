"""Controllers for the identified models: PD designs (python-control), RL agents, sweeps and evaluation."""
