"""The test bench: synthetic flights from a known truth, the named conditions they are flown in, and the
paper's comparison of the integral method with NLR and the EKF (Tables 3-5).
"""

from heli_core.deprecation import module_getattr

__getattr__ = module_getattr(__name__)
"""The names of the module this folder replaced (deprecated: :mod:`identification._deprecated`)."""
