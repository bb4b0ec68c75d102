"""Identify minimal attitude models of an RC helicopter from flight logs.

Implements the method of *Minimal Models to Capture the Dynamics of a Rotary Unmanned Aerial Vehicle*
(eqs. 18, 21, 31-47) on flights (:mod:`identification.flight`, read by :mod:`identification.io` and
prepared by :mod:`identification.preprocess`), one folder per stage:

* :mod:`identification.integral` -- the paper's integral method (Fig. 5);
* :mod:`identification.likelihood` -- maximum likelihood with a stochastic wind state (the default);
* :mod:`identification.disturbance` -- the wind the model misses (eqs. 41-47);
* :mod:`identification.validation` -- forward simulation, other flights, frequency response, the verdict;
* :mod:`identification.diagnosis` -- which physical effect a model misses;
* :mod:`identification.baselines` -- NLR and the EKF of the paper's comparison;
* :mod:`identification.bench` -- synthetic flights, bench cells and the method comparison;
* :mod:`identification.reports` -- Markdown and figures drawn from the stages' results;
* :mod:`identification.workflows` -- identify, diagnose, refresh: the only writers of a model folder.

The physics core and the term library are :mod:`heli_core`'s, the model folder :mod:`model_store`'s. Names
of the flat layout before issue 34 still import, with a ``DeprecationWarning`` (:mod:`identification._deprecated`).
"""

from heli_core.deprecation import install, module_getattr

install(__name__)
__getattr__ = module_getattr(__name__)
