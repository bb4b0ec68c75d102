"""Identify minimal attitude models of an RC helicopter from flight logs.

Implements the integral-based method of *Minimal Models to Capture the Dynamics
of a Rotary Unmanned Aerial Vehicle* (eqs. 18, 21, 31-47): flights in
(:mod:`identification.flight`, :mod:`identification.io`), the one physics core
(:mod:`identification.model`), the term library (:mod:`identification.terms`),
the identifier (:mod:`identification.integral_method`) and validation
(:mod:`identification.validation`).
"""
