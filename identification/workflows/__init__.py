"""The commands' work from flights to a model folder: identify, diagnose, refresh, and many flights at once.

These are the only modules of :mod:`identification` that write a model folder, each through one
:meth:`model_store.ModelDir.transaction`; the stages below them compute and the reports render.
"""
