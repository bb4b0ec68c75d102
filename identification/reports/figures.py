"""The figures' common ground: matplotlib on the Agg backend and the styles every report shares.

The plotting modules (:mod:`identification.reports.validation`,
:mod:`identification.reports.disturbance`, the diagnosis reports) draw with the
pyplot of :func:`pyplot`, imported only when a figure is drawn (matplotlib is
heavy and a fit needs none of it), and write PNGs at :data:`DPI` with
:func:`heli_core.files.save_figure`. A run whose figures may be drawn after its
report is written mixes in :class:`PendingFigures`.
"""

from __future__ import annotations

from heli_core.errors import MissingDependency

DPI = 110
"""Resolution of every PNG figure of the identification reports [dots per inch]."""

MEASURED_STYLE = {"color": "black", "lw": 0.9, "label": "measured"}
"""Line style of a measured history (black, drawn under the models)."""


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend.

    Raises
    ------
    MissingDependency
        matplotlib is not installed.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - matplotlib is a core dependency
        raise MissingDependency("matplotlib is needed to plot; install it with: pip install matplotlib") from e
    return plt


def model_styles(labels) -> dict[str, dict]:
    """Colour and dash per model label, so that overlapping models stay visible."""
    dashes = ("-", "--", ":", "-.")
    return {lab: {"color": f"C{i}", "ls": dashes[i % len(dashes)]} for i, lab in enumerate(labels)}


class PendingFigures:
    """A run whose report links figures drawn later: :attr:`figures` holds callables each returning
    ``{key: path}``, :attr:`paths` the files written (both fields of the dataclass that mixes this in)."""

    def draw_figures(self) -> dict:
        """Draw the figures left for later (:attr:`figures`); add them to :attr:`paths` and return them."""
        drawn = {}
        while self.figures:
            drawn.update(self.figures.pop(0)())
        self.paths.update(drawn)
        return drawn
