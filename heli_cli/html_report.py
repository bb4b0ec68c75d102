"""One self-contained HTML file beside each Markdown report (``report.md`` -> ``report.html``).

``heli identify``, ``diagnose``, ``sweep`` and ``evaluate`` write a Markdown report with PNG figures beside
it. :func:`write_html_report` turns such a report into a single HTML file a browser opens from the path the
command prints, with nothing else to carry along:

* the Markdown is converted by the ``markdown`` package (extensions ``tables`` and ``fenced_code``);
* every local image the report links (``![...](rates.png)``) is embedded as a base64 ``data:`` URI; an image
  that is not there becomes a visible note, never an error, so a report written with ``--no-plots`` or
  before its figures were drawn still converts;
* figures a command writes beside the report without linking them (``sweep``'s heat map, ``evaluate``'s
  episode) can be passed as ``figures`` and are appended under "Figures";
* a short inline style sheet: readable tables, images at most the page's width;
* ``<meta name="heli-source">`` and one ``<meta name="heli-figure">`` per embedded figure record the SHA-256 of
  what the page was made from, so :func:`stale_reasons` (``heli check``) can tell a page that shows an older
  report (``heli refresh`` rewrote ``report.md`` and the figures) from a current one.

The file is written atomically (:func:`heli_core.files.write_text`). ``markdown`` is imported when a
report is converted, not when the ``heli`` parser is built, so ``heli --help`` stays fast.
"""

from __future__ import annotations

import base64
import hashlib
import html
import mimetypes
import re
from pathlib import Path
from urllib.parse import unquote

__all__ = ["markdown_to_html", "rewrite_stale_html", "stale_reasons", "write_html_report"]

MARKDOWN_EXTENSIONS = ("tables", "fenced_code")
"""Extensions of the ``markdown`` package the reports need: pipe tables and fenced code blocks."""

IMAGE_TYPES = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".gif": "image/gif",
               ".svg": "image/svg+xml", ".webp": "image/webp"}
"""Image files embedded, by suffix, with their MIME type."""

STYLE = """\
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; line-height: 1.5; color: #1b1b1b;
       max-width: 72rem; margin: 2rem auto; padding: 0 1rem; }
h1, h2, h3 { line-height: 1.25; }
h2 { border-bottom: 1px solid #ddd; padding-bottom: .2rem; margin-top: 2rem; }
table { border-collapse: collapse; margin: 1rem 0; font-size: .9rem; display: block; overflow-x: auto; }
th, td { border: 1px solid #ccc; padding: .25rem .6rem; }
th { background: #f0f0f0; }
tr:nth-child(even) td { background: #fafafa; }
img { max-width: 100%; height: auto; display: block; margin: 1rem 0; }
code { font-family: ui-monospace, "SFMono-Regular", Menlo, Consolas, monospace; font-size: .9em; background: #f4f4f4;
       padding: 0 .2rem; }
pre { background: #f4f4f4; padding: .6rem; overflow-x: auto; }
pre code { padding: 0; }
.missing-figure { display: inline-block; border: 1px dashed #b00; color: #b00; padding: .3rem .6rem; margin: .5rem 0; }
"""


def write_html_report(markdown_path, figures=(), title: str | None = None) -> Path:
    """Write ``<stem>.html`` beside the Markdown report ``markdown_path``, self-contained; its path.

    Parameters
    ----------
    markdown_path : str or Path
        A Markdown report written by a ``heli`` command (``report.md``, ``diagnosis.md``, ``sweep.md``,
        ``evaluation.md``). Relative image links are read from its folder.
    figures : sequence of str or Path
        Figures to show although the report does not link them, appended under "Figures" in this order
        (a figure the report already links is not repeated; one that is missing becomes a note). Paths as a
        command holds them: absolute or relative to the current directory (``sweep/heatmap.png``), not to the
        report's folder.
    title : str, optional
        The page's ``<title>`` (default: the report's first level-1 heading, else the file's stem).

    Returns
    -------
    Path
        The HTML file, ``markdown_path`` with the suffix ``.html``.

    Raises
    ------
    heli_core.errors.MissingDependency
        The ``markdown`` package is not installed.
    FileNotFoundError
        ``markdown_path`` does not exist.
    """
    from heli_core.files import write_text

    markdown_path = Path(markdown_path)
    text = markdown_path.read_text(encoding="utf-8")
    figures = [Path(f).resolve() for f in figures]  # against the current directory: the report's folder is not theirs
    page = markdown_to_html(text, markdown_path.parent, title=title, figures=figures, default_title=markdown_path.stem,
                            source=markdown_path.name)
    return write_text(markdown_path.with_suffix(".html"), page)


def stale_reasons(html_path) -> list[str]:
    """Why the HTML report ``html_path`` no longer shows its Markdown report and figures; empty when it does.

    The page's ``heli-source`` and ``heli-figure`` metas are compared with the SHA-256 of the files now
    beside it. A page written before these metas existed is judged by modification time: older than its
    Markdown report is stale.

    Parameters
    ----------
    html_path : str or Path
        A page written by :func:`write_html_report`.

    Returns
    -------
    list of str
        One sentence per difference ("report.md changed since report.html was written"); [] when current or when
        the page has no Markdown report beside it.
    """
    html_path = Path(html_path)
    page = html_path.read_text(encoding="utf-8", errors="replace")
    metas = {kind: _recorded(page, kind) for kind in ("source", "figure")}
    if not metas["source"]:
        md = html_path.with_suffix(".md")
        if md.is_file() and md.stat().st_mtime > html_path.stat().st_mtime:
            return [f"{html_path.name} is older than {md.name}"]
        return []
    reasons = []
    for kind, entries in metas.items():
        for name, digest in entries:
            path = html_path.parent / name
            if not path.is_file():
                if kind == "source":
                    reasons.append(f"{name}, the report {html_path.name} was made from, is gone")
                continue  # a figure deleted since: the page still shows it, nothing newer to show
            if _sha256(path) != digest:
                reasons.append(f"{name} changed since {html_path.name} was written")
    return reasons


def rewrite_stale_html(folder) -> list[str]:
    """Rewrite every HTML report in ``folder`` that :func:`stale_reasons` finds stale; one line per page rewritten.

    The page is made again from its Markdown report and the figures it embedded (those the report does not link,
    such as a sweep's heat map, are appended again).

    Parameters
    ----------
    folder : str or Path

    Returns
    -------
    list of str
        "report.html rewritten from report.md (report.md changed since report.html was written)" per page.
    """
    done = []
    for page in sorted(Path(folder).glob("*.html")):
        md = page.with_suffix(".md")
        reasons = stale_reasons(page) if md.is_file() else []
        if not reasons:
            continue
        text = page.read_text(encoding="utf-8", errors="replace")
        figures = [page.parent / name for name, _ in _recorded(text, "figure")]
        write_html_report(md, figures=[f for f in figures if f.is_file()])
        done.append(f"{page.name} rewritten from {md.name} ({'; '.join(reasons)})")
    return done


def _recorded(page: str, kind: str) -> list[tuple[str, str]]:
    """``(file name, SHA-256)`` of each ``heli-<kind>`` meta of an HTML page (see :func:`markdown_to_html`)."""
    found = re.findall(rf'<meta name="heli-{kind}" content="([^"]*)" data-sha256="([0-9a-f]*)">', page)
    return [(html.unescape(name), digest) for name, digest in found]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def markdown_to_html(text: str, base_dir, title: str | None = None, figures=(), default_title: str = "report",
                     source: str | None = None) -> str:
    """A complete HTML page of the Markdown ``text``, its local images embedded as ``data:`` URIs.

    Parameters
    ----------
    text : str
        Markdown.
    base_dir : str or Path
        Folder relative image links are resolved against.
    title : str, optional
        The page's ``<title>`` (default: the first level-1 heading, else ``default_title``).
    figures : sequence of str or Path
        Figures appended under "Figures" unless the text links them already (see :func:`write_html_report`),
        each absolute or relative to ``base_dir``.
    default_title : str
        Title when ``title`` is None and the text has no level-1 heading.
    source : str, optional
        The Markdown file's name in ``base_dir``: recorded with the SHA-256 of ``text``, and each embedded
        figure with its own, for :func:`stale_reasons`. None: no record.

    Returns
    -------
    str
        The HTML document.
    """
    try:
        import markdown
        from markdown.treeprocessors import Treeprocessor
    except ImportError as e:
        from heli_core.errors import MissingDependency

        raise MissingDependency("the 'markdown' package is needed to write the HTML report; install it with: "
                                "pip install 'markdown>=3.4'") from e

    base_dir = Path(base_dir)
    seen: set[Path] = set()
    embedded: dict[str, str] = {}  # link name -> SHA-256 of the bytes embedded

    class _EmbedImages(Treeprocessor):
        """Replace each local ``<img src>`` by its data URI, or the element by a note when it cannot be read."""

        def run(self, root):
            for img in list(root.iter("img")):
                src = img.get("src", "")
                if not src or _is_remote(src):
                    continue
                path = (base_dir / src).resolve()
                if not path.exists() and "%" in src:  # a link written URL-encoded ("my%20figure.png")
                    path = (base_dir / unquote(src)).resolve()
                seen.add(path)
                uri, problem = _data_uri(path)
                if uri is not None:
                    embedded[_link(path, base_dir)] = _sha256(path)
                    img.set("src", uri)
                    continue
                alt = img.get("alt") or path.name
                img.tag = "span"
                img.attrib.clear()
                img.set("class", "missing-figure")
                img.text = f"Figure not embedded: {alt} ({src}: {problem})"
            return None

    md = markdown.Markdown(extensions=list(MARKDOWN_EXTENSIONS))
    md.treeprocessors.register(_EmbedImages(md), "heli_embed_images", 5)  # after "inline" (20) made the <img>s
    body = md.convert(text)
    extra = [Path(f) for f in figures]
    extra = [f for f in extra if (base_dir / f).resolve() not in seen]
    if extra:
        md.reset()
        body += "\n" + md.convert("## Figures\n\n" + "\n\n".join(f"![{f.stem}](<{_link(f, base_dir)}>)" for f in extra))
    if title is None:
        h1 = re.search(r"<h1[^>]*>(.*?)</h1>", body, re.S)
        title = html.unescape(re.sub(r"<[^>]+>", "", h1.group(1))).strip() if h1 else ""
        title = title or default_title
    record = ""
    if source is not None:
        record = (f'<meta name="heli-source" content="{html.escape(source)}" data-sha256="'
                  f'{hashlib.sha256(text.encode("utf-8")).hexdigest()}">\n'
                  + "".join(f'<meta name="heli-figure" content="{html.escape(name)}" data-sha256="{digest}">\n'
                            for name, digest in embedded.items()))
    return ("<!DOCTYPE html>\n"
            '<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            + record +
            f"<title>{html.escape(title)}</title>\n<style>\n{STYLE}</style>\n</head>\n"
            f"<body>\n{body}\n</body>\n</html>\n")


def _is_remote(src: str) -> bool:
    """Whether an image link is not a local file (a URL or an embedded image already)."""
    return "://" in src or src.startswith(("data:", "//", "mailto:"))


def _link(figure: Path, base_dir: Path) -> str:
    """A Markdown link to ``figure``: relative to ``base_dir`` when inside it, else absolute."""
    try:
        return (base_dir / figure).resolve().relative_to(base_dir.resolve()).as_posix()
    except ValueError:
        return (base_dir / figure).resolve().as_posix()


def _data_uri(path: Path) -> tuple[str | None, str]:
    """``(data URI, "")`` of the image at ``path``, or ``(None, why not)``."""
    mime = IMAGE_TYPES.get(path.suffix.lower()) or mimetypes.guess_type(path.name)[0]
    if mime is None or not mime.startswith("image/"):
        return None, "not an image file"
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None, "not found"
    except OSError as e:
        return None, f"cannot be read: {e.strerror or e}"
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}", ""
