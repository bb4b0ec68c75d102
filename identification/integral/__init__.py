"""The integral method of the paper (Section 2.5.2, Fig. 5): the least squares of one axis over intervals.

:mod:`~identification.integral.method` holds the estimator (:class:`IntegralIdentifier`),
:mod:`~identification.integral.axis` the least-squares problem of one axis (eqs. 32-40),
:mod:`~identification.integral.intervals` the sums over the intervals, and
:mod:`~identification.integral.bootstrap` the interval bootstrap of its parameters' uncertainty.
"""
