"""Which physical effect a model misses (issue 6): the catalogue of candidate effects and the two diagnosers.

:mod:`~identification.diagnosis.effects` names the candidates; the default diagnoser is by likelihood
(:mod:`~identification.diagnosis.likelihood_diagnoser`), the other by held-out forward simulation of the
integral method (:mod:`~identification.diagnosis.heldout_diagnoser`, with
:mod:`~identification.diagnosis.heldout` and :mod:`~identification.diagnosis.residual_tests`).
:mod:`~identification.diagnosis.alignment_check` tests whether a log's input column is late.
"""
