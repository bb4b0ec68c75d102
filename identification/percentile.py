"""The percentile convention of every error table: Matlab's ``prctile``, as the paper computed its 90th
percentiles.

One constant, shared by the validation of identified models (:mod:`identification.validation.forward_simulation`)
and the single-axis baselines (:mod:`identification.baselines.single_axis`), so that both tables rank errors
the same way.
"""

from __future__ import annotations

PERCENTILE_METHOD = "hazen"
"""``numpy.percentile`` method matching Matlab's ``prctile`` (sample k sits at (k - 0.5)/n)."""
