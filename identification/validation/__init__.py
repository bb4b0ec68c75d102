"""How good an identified model is: forward simulation against flights, other flights, frequency response,
the verdict stored in ``model.json``, the warnings of a fit and the drift of a refreshed model's parameters.

:mod:`~identification.validation.forward_simulation` simulates models from a flight's sticks (Section 3.2,
Tables 1-2) into a :class:`~identification.validation.result.ValidationResult`.
"""

from heli_core.deprecation import module_getattr

__getattr__ = module_getattr(__name__)
"""The names of the module this folder replaced (deprecated: :mod:`identification._deprecated`)."""
