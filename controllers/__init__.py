"""Controllers for the identified models: PD designs (python-control), RL agents, sweeps and evaluation.

Each name is imported from the module that defines it (``from controllers.pd.controller import
PDController``); the PD names this package re-exported, and modules that only re-exported others, are
deprecated (:mod:`controllers._deprecated`).
"""

from ._deprecated import DEPRECATIONS

DEPRECATIONS.install()
__getattr__ = DEPRECATIONS.module_getattr(__name__)
