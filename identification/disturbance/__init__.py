"""The wind the model is missing, with the intrinsic parameters fixed (eqs. 41-47, Sections 2.5.3, 3.3, 3.4).

:mod:`~identification.disturbance.equivalent_input` identifies a flight's profile (eq. 46's equivalent
input, smoothed by :mod:`~identification.disturbance.smoothing`); a maximum-likelihood model's wind is drawn
from its smoother's posterior by :mod:`~identification.disturbance.wind_posterior`.
"""

from heli_core.deprecation import module_getattr

__getattr__ = module_getattr(__name__)
"""The names of the module this folder replaced (deprecated: :mod:`identification._deprecated`)."""
