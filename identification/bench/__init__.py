"""The test bench: synthetic flights from a known truth, the named conditions they are flown in, and the
paper's comparison of the integral method with NLR and the EKF (Tables 3-5).
"""


def __getattr__(name):
    """The names of the module this folder replaced (deprecated: :mod:`identification._deprecated`)."""
    from .._deprecated import moved_name

    return moved_name(__name__, name)
