"""Markdown tables of the identification reports (``report.md``, ``comparison.md``, ``refresh.md``)."""

from __future__ import annotations


def markdown_cell(text) -> str:
    """``text`` as a table cell: a ``|`` inside it is escaped."""
    return str(text).replace("|", "\\|")


def markdown_table(header, rows, right_align: bool = True) -> str:
    """A Markdown table of ``header`` and ``rows`` (lists of cells), one line a row.

    Parameters
    ----------
    header : sequence of str
        Column headings.
    rows : sequence of sequence
        The cells of each row (converted with ``str``; ``|`` escaped).
    right_align : bool
        Right-align every column but the first (columns of numbers beside a
        label), else leave every column to the renderer's default.

    Returns
    -------
    str
        The table, without a trailing newline.
    """
    rule = ["---"] + ["---:" if right_align else "---"] * (len(header) - 1)
    lines = ["| " + " | ".join(markdown_cell(h) for h in header) + " |", "|" + "|".join(rule) + "|"]
    lines += ["| " + " | ".join(markdown_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)
