"""Write a firmware tune: the parameter files, ``tune.json``, ``tune.md`` and its figures, each atomically.

Files in the output folder:

* ``ardupilot.param`` or ``rotorflight.txt`` — the proposed gains, every parameter the loop models (the
  unchanged ones too, so the file alone says what was predicted), values outside the firmware's documented
  ranges clamped (and said);
* ``ardupilot.current.param`` or ``rotorflight.current.txt`` — the gains the log flew, to revert to;
* ``tune.json`` — :meth:`~controllers.firmware.tune.TuneResult.to_dict`, with the files' names, the clamps,
  and what the log flew;
* ``tune.md`` and its figures ``tune_p90.png``, ``tune_sweep.png``, ``tune_steps.png`` (``heli tune`` adds
  ``tune.html``).
"""

from __future__ import annotations

import json
from pathlib import Path

from heli_core.files import jsonable, write_text

from .tune_report import plot_comparison, plot_steps, plot_sweeps, to_markdown


def file_names(spec) -> dict:
    """``{"proposed": name, "current": name}`` of the parameter files."""
    stem, dot, ext = spec.filename.rpartition(".")
    return {"proposed": spec.filename, "current": f"{stem}.current.{ext}"}


def written_values(result) -> tuple[dict, dict, list]:
    """``(proposed, current, clamp notes)``: the firmware's names and values as the files hold them."""
    spec = result.spec
    proposed, notes = spec.clamp(spec.names(result.proposed))
    current, _ = spec.clamp(spec.names(result.current)) if spec.name == "rotorflight" else (
        spec.names(result.current), [])
    return proposed, current, notes


def write_outputs(result, out, flown=None, context=(), plots: bool = True, command: str = "") -> dict:
    """Write every file of the tune into ``out`` (module docstring); their paths by kind."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    spec = result.spec
    names = file_names(spec)
    proposed, current, clamp_notes = written_values(result)
    header = [f"{spec.name} gains proposed by heli tune{': ' + command if command else ''}",
              f"loop rate {result.loop_rate_hz:g} Hz; command scale {', '.join(f'{v:.4g}' for v in result.scale.scale)} "
              "(roll, pitch, yaw)", "every gain the loop models is listed; unchanged ones as the log flew them"]
    paths = {"proposed": spec.write(out / names["proposed"], proposed, header),
             "current": spec.write(out / names["current"], current,
                                   [f"{spec.name} gains the log flew (read by heli tune), to revert to"])}
    figures = []
    if plots:
        figures = [plot_comparison(result, out / "tune_p90.png"), plot_sweeps(result, out / "tune_sweep.png"),
                   plot_steps(result, out / "tune_steps.png")]
        paths["figures"] = figures
    doc = result.to_dict()
    doc["files"] = {k: str(Path(v).name) for k, v in paths.items() if k in ("proposed", "current")}
    doc["clamped"] = clamp_notes
    doc["flown_log"] = None if flown is None else flown.to_dict()
    doc["written_values"] = proposed
    paths["json"] = write_text(out / "tune.json", json.dumps(jsonable(doc), indent=2, allow_nan=False) + "\n")
    md = to_markdown(result, {k: Path(v).name for k, v in paths.items() if k in ("proposed", "current")}, flown,
                     figures, list(context) + ([""] if context else []))
    if clamp_notes:
        md += "\n" + "\n".join(f"- clamped: {n}" for n in clamp_notes) + "\n"
    paths["report"] = write_text(out / "tune.md", md)
    return paths
