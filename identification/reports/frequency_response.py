"""The frequency-response comparison's figure and table, drawn from a :class:`FrequencyComparison`.

:func:`plot_frequency_response` draws, per axis, the flight's estimate and the model's response as
magnitude, phase and coherence against frequency (a Bode plot with the coherence beneath, CIFER's layout),
the coherent band marked; :func:`frequency_markdown` the per-axis costs of ``report.md``. The estimate and
the cost are computed in :mod:`identification.validation.frequency_response`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from heli_core.files import save_figure

from .figures import DPI, pyplot
from .tables import markdown_table

if TYPE_CHECKING:
    from ..validation.frequency_response import FrequencyComparison

FIGURE_NAME = "frequency_response.png"
"""The figure's file in the model folder."""


def _number(value: float, fmt: str) -> str:
    return "—" if value is None or not math.isfinite(value) else format(value, fmt)


def frequency_markdown(result: FrequencyComparison, figure: str | None = FIGURE_NAME) -> list[str]:
    """The lines of ``report.md``'s frequency-response section: what was compared, the per-axis table
    (coherent band, CIFER's cost J, mean magnitude and phase errors) and the figure's link (``figure``, or
    none)."""
    from ..validation.frequency_response import COST_GOOD, COST_POINTS

    rows = []
    for axis, r in result.axes.items():
        band = r.band_hz
        rows.append([axis, "none" if band is None else f"{band[0]:.2f}–{band[1]:.2f}", str(int(r.coherent.sum())),
                     _number(r.cost, ".1f"), _number(r.magnitude_error_db, ".2f"), _number(r.phase_error_deg, ".1f")])
    table = markdown_table(["Axis", "Coherent band (Hz)", "Points", "Cost J", "Mean |magnitude error| (dB)",
                            "Mean |phase error| (deg)"], rows)
    lines = [
        f"Per axis, the flight's response from its stick to its rate, estimated as H = Pxy/Pxx from Welch spectra "
        f"({result.window_s:g} s Hann segments, half overlapping, {result.segments} segments over "
        f"{result.duration_s:.0f} s of flight), against the identified model linearised about hover at the "
        f"flights' mean collective {result.collective:.2f} (eqs. 18, 21 with its coupling terms and the Padé servo "
        f"of eq. 31). Compared only where the coherence γ² ≥ {result.coherence_min:g} (CIFER's guideline), from "
        f"two periods per segment ({result.f_min_hz:.2f} Hz) up to {result.f_max_hz:g} Hz. Cost J is CIFER's weighted "
        f"cost over {COST_POINTS} frequencies spaced logarithmically across the coherent band (magnitude in dB, "
        f"phase in degrees weighted 0.01745, each weighted by its coherence): J ≤ {COST_GOOD:g} is a good fit, "
        "up to about 200 acceptable.",
        "",
        table,
        "",
        "A pilot who fights gusts moves the stick with the rate, so below the frequencies he sweeps the estimate "
        "leans towards the inverse of his own law while its coherence stays high; on the project's synthetic "
        "flights this, not the model, is most of the cost of the true parameters (docs/method.md).",
        "",
    ]
    if figure is not None:
        lines += [f"![Frequency response: flight and model, with coherence]({figure})", ""]
    return lines


def plot_frequency_response(result: FrequencyComparison, path, title: str | None = None):
    """Magnitude, phase and coherence of the flight's estimate and the model per axis (one column an axis).

    The flight's estimate is drawn as points, solid where the coherence reaches ``result.coherence_min`` and
    faint elsewhere; the model as a line; the coherent band shaded; the threshold dashed on the coherence.

    Parameters
    ----------
    result : FrequencyComparison
    path : str or Path
        Destination PNG, written atomically.
    title : str, optional
        The figure's title.

    Returns
    -------
    Path
        ``path``.
    """
    from ..validation.frequency_response import phase_difference_deg

    plt = pyplot()
    axes = list(result.axes)
    fig, grid = plt.subplots(3, len(axes), figsize=(5.2 * len(axes), 9.5), sharex="col", squeeze=False,
                             gridspec_kw={"height_ratios": [1.2, 1.2, 0.8]})
    for j, name in enumerate(axes):
        r = result.axes[name]
        mag_ax, phase_ax, coh_ax = grid[:, j]
        f, ok = r.freq, r.coherent
        model_phase = np.degrees(np.unwrap(np.angle(r.model)))
        # the flight's phase drawn on the model's branch: the two differ by their wrapped difference
        flight_phase = model_phase - phase_difference_deg(r.model, r.flight)
        for ax, model, flight in ((mag_ax, 20 * np.log10(np.abs(r.model)), 20 * np.log10(np.abs(r.flight))),
                                  (phase_ax, model_phase, flight_phase)):
            ax.plot(f[~ok], flight[~ok], ".", color="0.75", ms=3, label="flight, γ² below threshold")
            ax.plot(f[ok], flight[ok], "o", color="black", ms=3.5, label="flight (H = Pxy/Pxx)")
            ax.plot(f, model, color="C0", lw=1.6, label="identified model")
        coh_ax.plot(f, r.coherence, color="C2", lw=1.2)
        coh_ax.axhline(result.coherence_min, color="C3", ls="--", lw=0.9, label=f"γ² = {result.coherence_min:g}")
        band = r.band_hz
        for ax in (mag_ax, phase_ax, coh_ax):
            if band is not None:
                ax.axvspan(*band, color="0.93", zorder=0)
            ax.set_xscale("log")
            ax.grid(alpha=0.3, which="both")
        cost = "no coherent band" if band is None else f"J = {r.cost:.1f}"
        mag_ax.set_title(f"{name.capitalize()}: stick to rate ({cost})", loc="left", fontsize=11)
        mag_ax.set_ylabel("magnitude [dB, rad/s per stick]")
        phase_ax.set_ylabel("phase [deg]")
        coh_ax.set_ylabel("coherence γ²")
        coh_ax.set_ylim(0.0, 1.02)
        coh_ax.set_xlabel("frequency [Hz]")
    grid[0, 0].legend(fontsize=8, loc="lower left")
    grid[2, 0].legend(fontsize=8, loc="lower left")
    fig.suptitle(title or "Frequency response: flight and identified model, with coherence (shaded: coherent band)",
                 fontsize=13)
    fig.tight_layout()
    return save_figure(fig, path, dpi=DPI)
