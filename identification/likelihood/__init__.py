"""Maximum likelihood with a stochastic wind state (the filter-error method), the default estimator.

:mod:`~identification.likelihood.estimator` holds the estimator (:class:`MaximumLikelihoodIdentifier`);
the likelihood of one axis is computed in :mod:`~identification.likelihood.axis_likelihood` from the
state-space pieces of :mod:`~identification.likelihood.state_space` (discretisation, Kalman filter,
smoother), with the input's hold (:mod:`~identification.likelihood.input_hold`) and the servo lag
(:mod:`~identification.likelihood.servo_lag`) profiled in it. What a fit learned about one axis is
:mod:`~identification.likelihood.axis_fit`; the axes are fitted side by side by
:mod:`~identification.likelihood.axis_pool`; :mod:`~identification.likelihood.ahead_prediction` scores
the model's prediction some time ahead.
"""
