"""Drawing of the attitude environments: an artificial horizon, the reference and the gust.

One frame shows, left, an attitude indicator (horizon tilted by roll and shifted
by pitch, the reference attitude as a dashed horizon, heading and its
reference); right, the last seconds of roll/pitch/yaw (or body rates for the
"rate" task) against their references, and the replayed gust u_d. matplotlib
draws it; ``rgb_array`` returns the frame as an (H, W, 3) uint8 array,
``human`` shows it in a window.
"""

from __future__ import annotations

import math

import numpy as np

WINDOW_S = 10.0
SIZE = (8.0, 4.0)
DPI = 80


class Renderer:
    """Draws frames from an environment's history of (t, attitude, ref_att, ref_rate, rates, gust, action)."""

    def __init__(self, mode: str, task: str):
        import matplotlib

        if mode == "rgb_array":
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            self.fig = Figure(figsize=SIZE, dpi=DPI)
            FigureCanvasAgg(self.fig)
            self.plt = None
        else:
            import matplotlib.pyplot as plt

            if matplotlib.get_backend().lower() == "agg":
                import warnings

                warnings.warn("render_mode='human' without an interactive matplotlib backend (no display): "
                              "frames are drawn but not shown; use render_mode='rgb_array' to get them",
                              stacklevel=3)
            plt.ion()
            self.fig = plt.figure(figsize=SIZE, dpi=DPI)
            self.plt = plt
        self.mode = mode
        self.task = task
        gs = self.fig.add_gridspec(3, 2, width_ratios=[1, 1.6], hspace=0.55, wspace=0.3,
                                   left=0.04, right=0.98, top=0.9, bottom=0.12)
        self.ax_h = self.fig.add_subplot(gs[:, 0])
        self.ax_a = self.fig.add_subplot(gs[0:2, 1])
        self.ax_g = self.fig.add_subplot(gs[2, 1], sharex=self.ax_a)

    def draw(self, history):
        if not history:
            return None
        t, att, ref_att, ref_rate, rates, gust, action = history[-1]
        self._horizon(att, ref_att)
        recent = [h for h in history if h[0] >= t - WINDOW_S]
        times = np.array([h[0] for h in recent])
        ax = self.ax_a
        ax.clear()
        colors = ("tab:blue", "tab:orange", "tab:green")
        names = ("p (roll)", "q (pitch)", "r (yaw)") if self.task == "rate" else ("roll", "pitch", "yaw")
        if self.task == "rate":
            meas = np.degrees([h[4] for h in recent])
            refs = np.degrees([h[3] for h in recent])
            ax.set_ylabel("body rate [deg/s]")
        else:
            meas = np.degrees([h[1] for h in recent])
            refs = np.degrees([h[2] for h in recent])
            ax.set_ylabel("attitude [deg]")
        for i in range(3):
            ax.plot(times, meas[:, i], color=colors[i], lw=1.4, label=names[i])
            ax.plot(times, refs[:, i], color=colors[i], lw=1.0, ls="--")
        ax.set_title(f"{self.task}: measured (solid) vs reference (dashed), t = {t:.2f} s", fontsize=9)
        ax.legend(loc="upper left", fontsize=7, ncol=3)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
        g = self.ax_g
        g.clear()
        gusts = np.array([h[5] for h in recent])
        for i in range(3):
            g.plot(times, gusts[:, i], color=colors[i], lw=1.0)
        g.set_ylabel("gust u_d\n[stick]", fontsize=8)
        g.set_xlabel("time [s]", fontsize=8)
        g.grid(alpha=0.3)
        g.tick_params(labelsize=7)
        g.set_xlim(max(0.0, t - WINDOW_S), max(t, WINDOW_S * 0.1))
        if self.mode == "rgb_array":
            self.fig.canvas.draw()
            return np.asarray(self.fig.canvas.buffer_rgba())[..., :3].copy()
        self.fig.canvas.draw_idle()
        self.plt.pause(0.001)
        return None

    def _horizon(self, att, ref_att):
        from matplotlib.patches import Circle

        ax = self.ax_h
        ax.clear()
        ax.set_xlim(-1.2, 1.2)
        ax.set_ylim(-1.2, 1.2)
        ax.set_aspect("equal")
        ax.axis("off")
        phi, theta, psi = att
        # As seen from the cockpit: the horizon turns against the aircraft, so a right roll (phi > 0)
        # turns it anticlockwise (more ground on the right), and nose up (theta > 0) lowers it.
        shift = -theta / math.radians(45.0)  # 45° of pitch fills the dial
        c, s = math.cos(phi), math.sin(phi)
        xs = np.array([-3.0, 3.0, 3.0, -3.0])
        ys = np.array([0.0, 0.0, -3.0, -3.0]) + shift
        ax.add_patch(Circle((0, 0), 1.0, color="#87b6e6", zorder=0))
        ground = ax.fill(c * xs - s * ys, s * xs + c * ys, color="#a0744d", zorder=1)[0]
        clip = Circle((0, 0), 1.0, transform=ax.transData)
        ground.set_clip_path(clip)
        heading = f"heading {math.degrees(psi):+.1f}°"
        if self.task != "rate":  # the rate task has no reference attitude
            rphi, rtheta = ref_att[0], ref_att[1]
            rc, rs = math.cos(rphi), math.sin(rphi)
            rshift = -rtheta / math.radians(45.0)  # the reference horizon, rotated about the dial centre
            line = ax.plot([-rc - rs * rshift, rc - rs * rshift], [-rs + rc * rshift, rs + rc * rshift], "w--",
                           lw=1.5, zorder=3)[0]
            line.set_clip_path(clip)
            heading += f" (ref {math.degrees(ref_att[2]):+.1f}°)"
        ax.plot([-0.5, -0.15, 0.0, 0.15, 0.5], [0, 0, -0.08, 0, 0], color="yellow", lw=3, zorder=4)
        ax.add_patch(Circle((0, 0), 1.0, fill=False, lw=2, zorder=5))
        ax.set_title(f"roll {math.degrees(phi):+.1f}°  pitch {math.degrees(theta):+.1f}°\n{heading}", fontsize=8)

    def close(self):
        if self.plt is not None:
            self.plt.close(self.fig)
