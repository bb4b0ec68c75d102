"""Gymnasium environments driven by identified helicopter attitude models.

The environment (``HeliAttitude-v0``) is built on the physics core of
:mod:`identification.model` and replays the disturbance library that
``heli identify`` writes.
"""
