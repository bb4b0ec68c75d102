"""Tests of :mod:`heli_cli.html_report`: one self-contained HTML file beside each workflow's Markdown report.

The converter is tested on a small report with a 2x2 PNG; each of ``heli identify``, ``diagnose``, ``sweep``
and ``evaluate`` is run once with the fastest settings of the other CLI tests; the sweep's HTML (two figures)
is rendered in a headless chromium when one is installed.
"""

from __future__ import annotations

import re
import shutil
import struct
import subprocess
import zlib
from pathlib import Path

import pytest

from heli_cli.html_report import markdown_to_html, write_html_report
from heli_cli.main import main


def _png(width: int = 2, height: int = 2) -> bytes:
    """A valid RGB PNG of ``width`` x ``height`` red pixels (no imaging package needed)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    raw = b"".join(b"\x00" + b"\xff\x00\x00" * width for _ in range(height))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


REPORT = """# Identification report

Some text with `code`.

| parameter | value |
|---|---:|
| k1 | 1.5 |

![Measured vs modelled body rates](rates.png)

![Detrended attitude](attitude.png)
"""


@pytest.fixture()
def report(tmp_path):
    (tmp_path / "rates.png").write_bytes(_png())
    path = tmp_path / "report.md"
    path.write_text(REPORT, encoding="utf-8")
    return path


def _img_sources(page: str) -> list[str]:
    return re.findall(r'<img[^>]*\ssrc="([^"]*)"', page)


# ------------------------------------------------------------------------------------------ the converter
def test_the_html_is_written_beside_the_markdown_with_its_images_embedded(report):
    html = write_html_report(report)
    assert html == report.with_suffix(".html")
    page = html.read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>") and "<title>Identification report</title>" in page
    (src,) = _img_sources(page)
    assert src.startswith("data:image/png;base64,")
    assert 'src="rates.png"' not in page and "(rates.png)" not in page  # nothing left to fetch beside it
    assert "max-width: 100%" in page  # images fit the page
    assert not [p.name for p in report.parent.iterdir() if p.name.startswith(".")]  # no temporary file left


def test_tables_become_html_tables(report):
    page = write_html_report(report).read_text(encoding="utf-8")
    assert "<table>" in page and "<th>parameter</th>" in page and ">1.5</td>" in page


def test_a_missing_image_is_a_visible_note_not_an_error(report):
    page = write_html_report(report).read_text(encoding="utf-8")
    note = re.search(r'<span class="missing-figure">([^<]*)</span>', page)
    assert note and "Detrended attitude" in note.group(1) and "attitude.png: not found" in note.group(1)
    assert 'src="attitude.png"' not in page


def test_figures_the_markdown_does_not_link_are_appended_once(report, tmp_path):
    (tmp_path / "heatmap.png").write_bytes(_png(3, 1))
    page = write_html_report(report, figures=[tmp_path / "heatmap.png", tmp_path / "rates.png"]).read_text()
    assert "<h2>Figures</h2>" in page
    assert len(_img_sources(page)) == 2  # rates.png, linked already, is not repeated
    assert all(src.startswith("data:image/png;base64,") for src in _img_sources(page))


def test_figures_given_relative_to_the_current_directory_are_found(report, tmp_path, monkeypatch):
    """A command with a relative ``--out`` holds ``out/heatmap.png``: not to be joined to ``out/`` again."""
    (tmp_path / "heatmap.png").write_bytes(_png(3, 1))
    monkeypatch.chdir(tmp_path.parent)
    folder = Path(tmp_path.name)
    page = write_html_report(folder / "report.md", figures=[folder / "heatmap.png", folder / "rates.png"]).read_text()
    sources = _img_sources(page)
    assert len(sources) == 2 and all(src.startswith("data:image/png;base64,") for src in sources)


def test_a_page_knows_when_its_report_or_a_figure_changed(report):
    from heli_cli.html_report import stale_reasons

    page = write_html_report(report)
    assert stale_reasons(page) == []
    (report.parent / "rates.png").write_bytes(_png(4, 4))
    assert stale_reasons(page) == ["rates.png changed since report.html was written"]
    report.write_text(REPORT + "\nmore\n", encoding="utf-8")
    assert len(stale_reasons(page)) == 2
    assert stale_reasons(write_html_report(report)) == []


def test_remote_images_and_the_title_are_left_alone():
    page = markdown_to_html("no heading\n\n![logo](https://example.org/logo.png)\n", ".", default_title="sweep")
    assert "<title>sweep</title>" in page
    assert _img_sources(page) == ["https://example.org/logo.png"]
    assert "<title>a &lt; b</title>" in markdown_to_html("# x\n", ".", title="a < b")


# -------------------------------------------------------------------------------------- the four commands
@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """``heli sweep`` on a 2 x 2 grid of 5 s windows (as tests/test_sweep.py); it draws two figures."""
    out = tmp_path_factory.mktemp("sweep") / "sw"
    assert main(["sweep", "--kp", "1:4:2", "--kd", "0:1:2", "--duration", "5", "--out", str(out),
                 "--no-progress"]) == 0
    return out


def _printed_and_written(capsys, html: Path) -> str:
    assert f"wrote {html}" in capsys.readouterr().out.splitlines()
    return html.read_text(encoding="utf-8")


def test_identify_writes_report_html(flight_csv, tmp_path, capsys):
    out = tmp_path / "DIR"
    assert main(["identify", str(flight_csv), "--out", str(out), "--method", "integral", "--no-plots",
                 "--no-disturbances"]) == 0
    page = _printed_and_written(capsys, out / "report.html")
    assert "<title>Identification report</title>" in page and "<table>" in page
    assert "<img" not in page  # --no-plots: no figure, and none missing


def test_diagnose_writes_diagnosis_html(flight_csv, tmp_path, capsys):
    out = tmp_path / "diag"
    assert main(["diagnose", str(flight_csv), "--out", str(out), "--no-plots"]) == 0
    page = _printed_and_written(capsys, out / "diagnosis.html")
    assert "Diagnosis" in page and "<img" not in page


def test_sweep_writes_sweep_html_with_both_figures(swept):
    page = (swept / "sweep.html").read_text(encoding="utf-8")
    assert "<table>" in page and "Gain sweep" in page
    sources = _img_sources(page)
    assert len(sources) == 2 and all(s.startswith("data:image/png;base64,") for s in sources)
    assert not re.search(r'(src|href)="[^"]*(heatmap|histograms)\.png"', page)  # nothing left to fetch beside it


@pytest.mark.slow
def test_sweep_and_evaluate_embed_their_figures_with_a_relative_out(tmp_path, monkeypatch, capsys):
    """As the README and the demo run them (``--out sweep/``): the figures were once looked for in sweep/sweep/."""
    from controllers.pd import PDController, design_gains
    from heli_env import load_env_model

    monkeypatch.chdir(tmp_path)
    assert main(["sweep", "--kp", "1:4:2", "--kd", "0:1:2", "--duration", "5", "--out", "sw", "--no-progress"]) == 0
    sources = _img_sources((tmp_path / "sw" / "sweep.html").read_text(encoding="utf-8"))
    assert len(sources) == 2 and all(s.startswith("data:image/png;base64,") for s in sources)
    shipped = load_env_model()
    PDController.from_model(shipped.params, design_gains(shipped.params)).save(tmp_path / "pd.json")
    assert main(["evaluate", "pd.json", "--out", "ev", "--episode-seconds", "5", "--episodes-per-trace", "1"]) == 0
    page = _printed_and_written(capsys, Path("ev") / "evaluation.html")
    sources = _img_sources(page)  # the episode and the servo activity
    assert len(sources) == 2 and all(s.startswith("data:image/png;base64,") for s in sources)


def test_evaluate_writes_evaluation_html_with_the_episode(tmp_path, capsys):
    from controllers.pd import PDController, design_gains
    from heli_env import load_env_model

    shipped = load_env_model()
    agent = PDController.from_model(shipped.params, design_gains(shipped.params)).save(tmp_path / "pd.json")
    out = tmp_path / "ev"
    assert main(["evaluate", str(agent), "--out", str(out), "--episode-seconds", "5",
                 "--episodes-per-trace", "1"]) == 0
    page = _printed_and_written(capsys, out / "evaluation.html")
    sources = _img_sources(page)  # the episode and the servo activity
    assert len(sources) == 2 and all(s.startswith("data:image/png;base64,") for s in sources)
    assert not re.search(r'(src|href)="[^"]*(episode|servo)\.png"', page)


# ------------------------------------------------------------------------------------ a headless browser
def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    return None


DECODE_CHECK = """<script>
window.addEventListener("load", () => {
  const ok = Array.from(document.images).filter(i => i.complete && i.naturalWidth > 0).length;
  document.body.setAttribute("data-decoded", ok + "/" + document.images.length);
});
</script>
"""


@pytest.mark.skipif(_chromium() is None, reason="no chromium installed to render the HTML report in a headless "
                    "browser (Debian: apt-get install chromium)")
@pytest.mark.slow
def test_the_sweep_report_renders_in_headless_chromium(swept, tmp_path):
    # a copy of the report with a script that counts the images the browser decoded
    page = (swept / "sweep.html").read_text(encoding="utf-8").replace("</body>", DECODE_CHECK + "</body>")
    probe = tmp_path / "probe.html"
    probe.write_text(page, encoding="utf-8")
    shot = tmp_path / "shot.png"
    base = [_chromium(), "--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars",
            f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=10000", "--window-size=1200,1600"]
    dom = subprocess.run(base + ["--dump-dom", probe.as_uri()], capture_output=True, text=True, timeout=120)
    assert dom.returncode == 0, dom.stderr[-2000:]
    assert len(re.findall(r'<img[^>]*src="data:image/png;base64,', dom.stdout)) == 2
    assert 'data-decoded="2/2"' in dom.stdout, "the browser did not decode both embedded figures"
    done = subprocess.run(base + [f"--screenshot={shot}", (swept / "sweep.html").as_uri()], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 10_000
