"""``heli design --lqg``: the per-axis LQG of an identified model and its wind model (:mod:`controllers.lqg`).

Writes the controller that ``heli evaluate`` flies (``lqg.json``) and ``lqg.md``: the rule the weights follow
and, per axis, the loop-transfer-recovery weight the design chose, the margins at the plant input, the
crossover and the predicted p90 |attitude error|; unless ``--no-plots``, the figures a control engineer
looks at first (``bode_<axis>.png``: each loop at the plant input with its margins; ``recovery.png``: the
recovery from a 2° attitude error, :mod:`controllers.lqg.figures`) and ``lqg.html``, the report with its
figures inside, as ``heli design`` writes for a PD. ``--phase-margin`` and ``--dt`` mean what they mean for
the PD; the gain margin kept is 6 dB; ``--bandwidth`` and ``--d-filter-hz`` are the PD's and are refused.
"""

from __future__ import annotations

from pathlib import Path

LQG_RULE = (
    "Per axis: the identified airframe with its Padé servo (eq. 31), the Gauss-Markov gust states the "
    "maximum-likelihood identification fitted (model.json fit_statistics.axes.<axis>.wind), the sensors' noise "
    "and each gyro vibration line as an oscillator state, sampled at the control period. Regulator: "
    "control.dlqr with Bryson's weights (an attitude error of {att:g} deg, a rate error of {rate:g} deg/s and "
    "{stick:g} stick each cost 1). Estimator: the steady-state Kalman filter of control.dlqe, current form, "
    "with the smallest loop-transfer-recovery weight q (fictitious stick noise) whose sampled loop keeps "
    "{gm:g} dB and {pm:g} deg at the plant input."
)


def lqg_markdown(design, plots: bool = True) -> str:
    """``lqg.md``: the model, the rule, the design's table (:meth:`controllers.lqg.LQGDesign.markdown`) and,
    with ``plots``, the figures :func:`draw_figures` writes beside it."""
    from controllers.lqg.figures import RECOVERY_DEG

    w, st = design.weights, design.settings
    rule = LQG_RULE.format(att=w.attitude_deg, rate=w.rate_deg_s, stick=w.stick, gm=st["min_gain_margin_db"],
                           pm=st["min_phase_margin_deg"])
    lines = ["# LQG attitude controller", "", f"Model: `{st['model']}`; control period {design.dt:g} s.",
             "", rule, "", design.markdown(), "",
             "Predicted p90: the stationary closed loop under the design model's own noises (Gaussian). "
             "Fly it with `heli evaluate lqg.json`."]
    if plots:
        lines += ["", "## Figures", "",
                  f"The recovery from a {RECOVERY_DEG:g}° attitude error, without gusts or noise, the filter starting "
                  "from its prior as at an episode's start (the stick is drawn unclipped; in flight it is clipped at "
                  "±1):", "",
                  "![recovery](recovery.png)", "",
                  "Each axis' loop broken at the plant input (the loop whose margins the design keeps):", ""]
        lines += [f"![Bode {a.model.axis}](bode_{a.model.axis}.png)" for a in design.axes]
    return "\n".join(lines) + "\n"


def draw_figures(design, out: Path) -> list:
    """``recovery.png`` and ``bode_<axis>.png`` of ``design`` in ``out``; their paths."""
    from controllers.lqg.figures import plot_loop_bode, plot_recovery

    paths = [plot_recovery(design, out / "recovery.png")]
    return paths + [plot_loop_bode(a, out / f"bode_{a.model.axis}.png") for a in design.axes]


def run_lqg(args) -> int:
    """The ``--lqg`` branch of ``heli design`` (the model was checked by the caller)."""
    from controllers.errors import DesignError
    from controllers.lqg import design_lqg
    from heli_env.env_model import load_env_model
    from heli_core.files import write_text

    from .control_period import control_period
    from .progress import progress_of

    if args.bandwidth is not None:
        raise DesignError("--bandwidth sets a PD's bandwidth; an LQG's follows from its weights and the margins "
                          "(leave --bandwidth out with --lqg)")
    with progress_of(args) as progress:
        progress.stage("designing the LQG: Kalman filter and LQR per axis, margins at the plant input")
        env_model = load_env_model(args.model)
        if args.dt is None:
            args.dt, note = control_period(env_model.sample_rate)
            if note:
                progress.done()
                print(note)
        design = design_lqg(env_model, dt=args.dt, phase_margin_deg=args.phase_margin)
        out = Path(args.out)
        paths = [design.controller().save(out / "lqg.json", {"model": str(env_model.path), "how": "heli design --lqg",
                                                              "design": design.summary()})]
        if not args.no_plots:
            progress.stage("drawing the recovery and the loops' Bode figures")
            paths += draw_figures(design, out)
        paths.append(write_text(out / "lqg.md", lqg_markdown(design, plots=not args.no_plots)))
        progress.done()
    for a in design.axes:
        print(f"  {a.model.axis:5s}: {a.model.n} states, recovery q {a.recovery:.3g}; phase margin "
              f"{a.phase_margin_deg:.1f} deg, gain margin {a.gain_margin_db:.1f} dB, crossover "
              f"{a.crossover_rad_s:.3g} rad/s; predicted p90 {a.predicted_att_p90_deg:.3f} deg")
    from .html_report import write_html_report  # after the figures: it embeds them

    for path in [*paths, write_html_report(out / "lqg.md")]:
        print(f"wrote {path}")
    return 0
