"""Controllers for the identified models: PD designs (python-control), RL agents, sweeps and evaluation.

Each name is imported from the module that defines it (``from controllers.pd.controller import
PDController``); the PD names this package re-exported, and modules that only re-exported others, are
deprecated (:mod:`controllers._deprecated`).
"""

from heli_core.deprecation import install, module_getattr

install(__name__)
__getattr__ = module_getattr(__name__)
