"""Branch-free ``atan2`` and ``asin`` that a numba loop over copies runs 4 or 8 at a time (AVX2 / AVX-512).

The vector environment turns each copy's quaternion into Euler angles (eqs. 27-29) every step. A call
of the C library's ``atan2`` inside a compiled loop keeps the loop scalar (tens of nanoseconds per copy),
and numpy's SIMD ``arctan2`` needs a pass of its own over memory outside the loop. The functions here are
Cephes' ``atan`` (S. L. Moshier, *Methods and Programs for Mathematical Functions*, 1989: a rational
approximation on ``|t| <= tan(pi/8)`` after reducing by ``pi/4`` or ``pi/2``) written with selects
instead of branches, so that LLVM vectorises them inside the step's loop. numba compiles them apart
(``error_model="numpy"``: a division by zero is IEEE's, not an exception to check) and LLVM inlines them
into the loop; numba's own inlining (``inline="always"``) gave the same machine code and made the step
compile a second longer. Error against the C library's
correctly rounded-ish ``math.atan2`` / ``math.asin``: at most 1 ulp for ``atan2`` and 2 ulp for ``asin``
over unit quaternions of every size (``tests/test_vector_math.py``), numpy's ``arctan2`` / ``arcsin``
being within 1 ulp there too.

Special values follow C99 for the arguments the env produces (finite, not both infinite): ``atan2(±0, x)``
is ``±0`` for ``x >= +0`` and ``±pi`` for ``x <= -0``; ``asin(±1) = ±pi/2``. NaN in gives NaN out.
"""

from __future__ import annotations

import math

import numba

_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1, -7.500855792314704667340e1,
      -1.228866684490136173410e2, -6.485021904942025371773e1)
_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
      4.853903996359136964868e2, 1.945506571482613964425e2)
"""Cephes ``atan``: ``atan(t) = t + t z P(z) / Q(z)``, ``z = t**2``, ``|t| <= tan(pi/8)``; ``Q`` monic."""
_TAN_3PI_8 = 2.41421356237309504880
_MID = 0.66
"""Above ``tan(3 pi / 8)`` the argument is reduced by ``pi/2``, above 0.66 by ``pi/4`` (Cephes' split)."""
_PI_2 = 1.57079632679489661923
_PI_4 = 7.85398163397448309616e-1
_PI = 3.14159265358979323846
_MOREBITS = 6.123233995736765886130e-17
"""``pi/2`` less its float64 value: added back so that the reduction by ``pi/2`` (or half of it, ``pi/4``)
loses nothing."""


@numba.njit(error_model="numpy")
def atan2v(y, x):
    """``atan2(y, x)`` [rad] in (-pi, pi], branch-free (module docstring)."""
    ax = abs(x)
    ay = abs(y)
    big = ay > _TAN_3PI_8 * ax
    mid = ay > _MID * ax
    num = -ax if big else (ay - ax if mid else ay)
    den = ay if big else (ay + ax if mid else ax)
    t = num / (1.0 if den == 0.0 else den)  # den is 0 only where y and x are: atan2(±0, ±0) from t = 0
    base = _PI_2 if big else (_PI_4 if mid else 0.0)
    extra = _MOREBITS if big else (0.5 * _MOREBITS if mid else 0.0)
    z = t * t
    p = (((_P[0] * z + _P[1]) * z + _P[2]) * z + _P[3]) * z + _P[4]
    q = ((((z + _Q[0]) * z + _Q[1]) * z + _Q[2]) * z + _Q[3]) * z + _Q[4]
    r = base + ((t * (z * p / q) + extra) + t)  # atan(|y| / |x|) in [0, pi/2]
    r = _PI - r if math.copysign(1.0, x) < 0.0 else r
    return math.copysign(r, y)


@numba.njit(error_model="numpy")
def asinv(s):
    """``asin(s)`` [rad] for ``s`` in [-1, 1], as ``atan2(s, sqrt((1 - s)(1 + s)))`` (exact factors near ±1)."""
    return atan2v(s, math.sqrt((1.0 - s) * (1.0 + s)))
