"""The base layer of heli-env: model parameters, the one physics core, terms, errors, files and backends.

``identification``, ``heli_env`` and ``controllers`` stand on it; it imports none of them.
"""
