"""Progress of the ``heli`` commands: what each one is doing while it works.

Every step that can take more than a couple of seconds is announced as a *stage*
through a :class:`Progress` made from the parsed arguments (:func:`progress_of`):

* on a terminal (stderr a TTY) the stage is a transient tqdm status line, replaced
  by the next stage and erased when the command prints its results; the library's
  own tqdm bars (replicates, tasks, timesteps) show beneath it;
* otherwise (a log file, a pipe, CI) one line per stage, e.g.
  ``identify: fitting the decoupled and coupled models by maximum likelihood ...``;
* with ``--quiet`` nothing, and the library's bars are off (:attr:`Progress.bars`).

Stages go to stderr, so stdout carries only the results. The module imports no
numeric package; tqdm is imported on the first stage shown on a terminal.
"""

from __future__ import annotations

import sys


class Progress:
    """Stages of one command run (module docstring).

    Parameters
    ----------
    command : str
        The sub-command's name, prefixed to each line (``"identify"``).
    quiet : bool
        Show nothing (``--quiet``).
    stream : file, optional
        Where stages go (default: ``sys.stderr`` at the time of each stage).
    """

    def __init__(self, command: str, quiet: bool = False, stream=None):
        self.command = command
        self.quiet = bool(quiet)
        self._stream = stream
        self._bar = None

    @property
    def stream(self):
        return self._stream if self._stream is not None else sys.stderr

    @property
    def terminal(self) -> bool:
        """Whether stages are drawn as a status line (the stream is a TTY)."""
        isatty = getattr(self.stream, "isatty", None)
        return bool(isatty and isatty())

    @property
    def bars(self) -> bool:
        """Whether the library's own progress bars may show (they show only on a terminal themselves)."""
        return not self.quiet

    @property
    def items(self):
        """The ``stage`` callback for a library step that draws its own bar over its items on a terminal:
        off a terminal one line per item (the bar is off there), on one None (the bar shows the item)."""
        return None if self.quiet or self.terminal else self.stage

    def stage(self, text: str) -> None:
        """Announce the step that starts now, e.g. ``"fitting roll/pitch/yaw"`` (ends the previous one)."""
        self.done()
        if self.quiet:
            return
        line = f"{self.command}: {text} ..."
        if self.terminal:
            from tqdm import tqdm

            self._bar = tqdm(total=None, desc=line, bar_format="{desc}", file=self.stream, leave=False)
        else:
            print(line, file=self.stream, flush=True)

    def draw_figures(self, run) -> None:
        """Draw the figures a run left for later (``run.draw_figures()``) as one stage, then print each path."""
        if not run.figures:
            return
        self.stage("drawing the figures")
        drawn = run.draw_figures()
        self.done()
        for path in drawn.values():
            print(f"wrote {path}")

    def done(self) -> None:
        """End the current stage (erases its status line on a terminal); call before printing results."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.done()
        return False


def progress_of(args) -> Progress:
    """The :class:`Progress` of a parsed ``heli`` command line (its ``command`` and ``--quiet``)."""
    return Progress(args.command, quiet=getattr(args, "quiet", False))
