"""The test bench: synthetic flights from a known truth, the named conditions they are flown in, and the
paper's comparison of the integral method with NLR and the EKF (Tables 3-5).
"""

from .._deprecated import DEPRECATIONS

__getattr__ = DEPRECATIONS.module_getattr(__name__)
"""The names of the module this folder replaced (deprecated: :mod:`identification._deprecated`)."""
