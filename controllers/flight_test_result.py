"""The result of a sweep's flight tests as plain data: :class:`FlightTestResult`, measured against predicted
error distributions per gain pair, and the target it is judged by (:data:`KS_TARGET`).

:mod:`controllers.flight_test` flies the tests and returns it; :func:`controllers.sweep_report.flight_test_markdown`
renders it. It imports neither, as :mod:`controllers.sweep_result` is the sweep's (issue 34: algorithm -> result
<- report).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from heli_core.deprecation import moved_method
from heli_core.files import jsonable, write_text

KS_TARGET = 0.1
"""Largest two-sample KS statistic (|attitude error|, time-domain prediction) a flown pair may show: the
issue's target at stable swept gains."""


@dataclass(eq=False)
class FlightTestResult:
    """Measured against predicted error distributions, per gain pair.

    Attributes
    ----------
    axis : str
    table : dict of str -> ndarray (n_pairs,)
        ``kp``, ``kd``, ``status`` ("flown" or "unstable"), ``ks_att``/``ks_rate`` (two-sample KS
        against the time-domain prediction), ``ks_att_gauss``/``ks_rate_gauss`` (against the
        frequency-domain half-normal), measured ``att_p{50,90,99}_deg``, ``rate_p{...}_dps``,
        predicted ``pred_td_*`` and ``pred_fd_*``, ``saturation``.
    settings : dict
        Truth, wind statistics, flights, duration, seed, sensors.
    samples : dict of int -> (att_err_deg, rate_err_deg_s)
        Measured signed errors per flown pair, all flights concatenated.
    """

    axis: str
    table: dict
    settings: dict
    samples: dict

    @property
    def flown(self) -> np.ndarray:
        return self.table["status"] == "flown"

    @property
    def max_ks(self) -> float:
        """Largest KS statistic (|attitude error|, time-domain prediction) over the flown pairs."""
        v = np.asarray(self.table["ks_att"], dtype=float)[self.flown]
        return float(v.max()) if v.size else float("nan")

    @property
    def target_met(self) -> bool:
        return bool(self.max_ks <= KS_TARGET)

    def rows(self) -> list:
        keys = list(self.table)
        out = []
        for i in range(self.table["kp"].size):
            row = {}
            for k in keys:
                v = self.table[k][i]
                row[k] = v.item() if hasattr(v, "item") else v
            out.append(row)
        return out

    def to_markdown(self) -> str:
        """Deprecated: :func:`controllers.sweep_report.flight_test_markdown` renders the report section."""
        return moved_method("FlightTestResult.to_markdown", "controllers.sweep_report", "flight_test_markdown", self)

    def to_json(self, path):
        import json

        doc = {"schema": "heli-env/flight-test", "schema_version": 1, "axis": self.axis,
               "settings": self.settings, "ks_target": KS_TARGET, "target_met": self.target_met,
               "rows": self.rows()}
        return write_text(path, json.dumps(jsonable(doc), indent=1, allow_nan=False) + "\n")
