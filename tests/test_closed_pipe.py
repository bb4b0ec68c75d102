"""A reader who stops reading (``heli identify ... | head``) does not stop a command from writing its files."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

from heli_cli.closed_pipe import ClosedPipeGuard, guarded_stdout


def _closed_pipe_stream():
    """A text stream on the write end of a pipe whose read end is already closed."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    return io.TextIOWrapper(io.FileIO(write_end, "w"), encoding="utf-8")


def test_a_closed_pipe_silences_the_stream_instead_of_raising():
    stream = _closed_pipe_stream()
    guard = ClosedPipeGuard(stream)
    guard.write("the model\n")
    guard.flush()  # without the guard: BrokenPipeError
    assert guard.reader_gone
    assert guard.write("more\n") == len("more\n")
    guard.flush()
    stream.write("what the stream still holds\n")
    stream.flush()  # its descriptor now leads to os.devnull: the interpreter's last flush cannot fail either
    stream.close()


def test_an_open_stream_is_written_through_and_restored():
    out = io.StringIO()
    saved = sys.stdout
    sys.stdout = out
    try:
        with guarded_stdout() as guard:
            print("a line")
            assert sys.stdout is guard and guard.getvalue() == "a line\n"  # attributes are the stream's
        assert sys.stdout is out and not guard.reader_gone
    finally:
        sys.stdout = saved


def test_identify_whose_reader_has_gone_writes_every_file(flight_csv, tmp_path):
    """The read end closed before the first line: the run ends as a run does (exit 0, report.html written after
    every print), with no error."""
    heli = Path(sys.executable).with_name("heli")
    out = tmp_path / "model"
    env = {**os.environ, "HELI_CLOSED_LOOP": "off"}
    run = subprocess.Popen([str(heli), "identify", str(flight_csv), "--method", "integral", "--no-plots",
                            "--no-disturbances", "--out", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    run.stdout.close()
    _, err = run.communicate(timeout=300)
    assert run.returncode == 0, err.decode()
    assert b"error" not in err and b"Exception ignored" not in err, err.decode()
    for name in ("model.json", "report.md", "report.html"):
        assert (out / name).is_file(), name
