"""Every HTML report shows every figure, whether ``--out`` is relative or absolute (issue #31's third target).

Each command that writes an HTML report runs once per way of naming its output folder (relative to the working
directory, as the README and the demo do, and absolute): ``heli identify`` (with ``--validate``: the
frequency-response and validation figures), ``diagnose``, ``design``, ``sweep``, ``evaluate``, ``train``,
``tune`` and ``refresh``. For each page, every figure its Markdown links and every PNG the command said it wrote
beside it must be embedded byte for byte, with no missing-figure note and nothing left to fetch; in a headless
chromium (when one is installed) every image must decode. The runs use the fastest settings that still draw
every figure (the integral method, 60 s flights, a tiny PPO run): about 3 minutes per way on two shared cores.
"""

from __future__ import annotations

import base64
import contextlib
import hashlib
import io
import re
import subprocess
from pathlib import Path

import pytest

from heli_cli.main import main
from test_html_report import DECODE_CHECK, _chromium

pytestmark = pytest.mark.slow

PAGES = ("model/report.html", "diag/diagnosis.html", "pd/design.html", "sw/sweep.html", "ev/evaluation.html",
         "agents/ppo_training/report.html", "tune/tune.html", "refreshed/report.html")
"""The HTML report of each command, relative to the run's folder."""


def _run(argv) -> str:
    """``heli argv`` quietly; what it printed (it must succeed)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()) as err:
        code = main([*argv, "-q"])
    assert code == 0, f"heli {' '.join(map(str, argv))}: {err.getvalue()}"
    return out.getvalue()


@pytest.fixture(scope="module", params=["relative", "absolute"])
def reports(request, tmp_path_factory):
    """Every command run in a fresh folder with ``--out`` named ``request.param``ly: (folder, printed text)."""
    root = tmp_path_factory.mktemp(f"html_{request.param}")

    def o(name: str) -> str:
        return name if request.param == "relative" else str(root / name)

    printed = []
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(root)
        for name, seed, seconds in (("f1", 3, 60), ("f2", 4, 40), ("f3", 6, 40)):
            _run(["simulate-flight", "--duration", str(seconds), "--seed", str(seed), "--out", o(f"{name}.csv")])
        (root / "ap.param").write_text("ATC_ANG_RLL_P,4.5\nATC_RAT_RLL_P,0.05\nATC_ANG_PIT_P,4.5\n")
        runs = [
            ["identify", o("f1.csv"), "--method", "integral", "--validate", o("f2.csv"), "--out", o("model")],
            ["diagnose", o("f1.csv"), "--method", "integral", "--out", o("diag")],
            ["design", "--model", o("model"), "--out", o("pd")],
            ["sweep", "--model", o("model"), "--kp", "1:4:2", "--kd", "0:1:2", "--duration", "5", "--out", o("sw")],
            ["evaluate", o("pd/pd.json"), "--model", o("model"), "--episodes-per-trace", "1", "--out", o("ev")],
            ["train", "--algo", "ppo", "--model", o("model"), "--timesteps", "128", "--n-envs", "1", "--eval-freq", "0",
             "--checkpoint-freq", "0", "--episode-seconds", "2", "--out", o("agents/ppo")],
            ["tune", o("f1.csv"), "--firmware", "ardupilot", "--model", o("model"), "--params", o("ap.param"),
             "--window", "5", "--candidates", "1", "--out", o("tune")],
        ]
        printed += [_run(argv) for argv in runs]
        # refresh rewrites a model folder in place: a copy, so that the pages above stay as written
        import shutil

        shutil.copytree(root / "model", root / "refreshed")
        printed.append(_run(["refresh", o("refreshed"), o("f3.csv"), "--bootstrap", "20"]))
    return root, "\n".join(printed)


def _embedded(page: str) -> list[str]:
    """SHA-256 of each image the page carries inside (``data:`` URIs)."""
    sources = re.findall(r'<img[^>]*\ssrc="([^"]*)"', page)
    assert all(s.startswith("data:image/") for s in sources), [s[:60] for s in sources if not s.startswith("data:")]
    return [hashlib.sha256(base64.b64decode(s.split(",", 1)[1])).hexdigest() for s in sources]


def _expected(html: Path, printed: str, root: Path) -> list[Path]:
    """The figures of ``html``: those its Markdown links, and the PNGs a command said it wrote in its folder."""
    folder = html.parent
    linked = [folder / m for m in re.findall(r"!\[[^\]]*\]\(([^)\s]+\.png)\)", html.with_suffix(".md").read_text())]
    written = [Path(w) if Path(w).is_absolute() else root / w
               for w in re.findall(r"^wrote (\S+\.png)$", printed, re.M)]
    return list(dict.fromkeys([*linked, *(w for w in written if w.parent.resolve() == folder.resolve())]))


@pytest.mark.parametrize("page", PAGES)
def test_every_figure_is_inside_the_page(reports, page):
    root, printed = reports
    html = root / page
    text = html.read_text(encoding="utf-8")
    figures = _expected(html, printed, root)
    assert figures, f"{page}: no figure expected (the run draws none?)"
    embedded = set(_embedded(text))
    for figure in figures:
        assert figure.is_file(), f"{page} links {figure.name}, which was not written"
        assert hashlib.sha256(figure.read_bytes()).hexdigest() in embedded, f"{page} lacks {figure.name}"
    assert 'class="missing-figure"' not in text


@pytest.mark.skipif(_chromium() is None, reason="no chromium installed to render the HTML reports in a headless "
                    "browser (Debian: apt-get install chromium)")
def test_every_page_renders_its_figures_in_headless_chromium(reports, tmp_path):
    root, _ = reports
    decoded = {}
    for page in PAGES:
        text = (root / page).read_text(encoding="utf-8")
        n = len(re.findall(r"<img", text))
        probe = tmp_path / (page.replace("/", "_"))
        probe.write_text(text.replace("</body>", DECODE_CHECK + "</body>"), encoding="utf-8")
        dom = subprocess.run([_chromium(), "--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars",
                              f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=10000",
                              "--dump-dom", probe.as_uri()], capture_output=True, text=True, timeout=120)
        assert dom.returncode == 0, dom.stderr[-2000:]
        found = re.search(r'data-decoded="(\d+)/(\d+)"', dom.stdout)
        decoded[page] = found.groups() if found else None
    assert all(d is not None and d[0] == d[1] != "0" for d in decoded.values()), decoded
