"""What the commands write for a reader: Markdown sections and figures, drawn from the stages' results.

A report only reads: it fits nothing and writes no model folder (the workflows of
:mod:`identification.workflows` do). Figures use :mod:`~identification.reports.figures`' pyplot, imported
only when one is drawn.
"""
