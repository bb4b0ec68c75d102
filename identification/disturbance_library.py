"""Moved to :mod:`model_store.disturbance_library`; this module re-exports it so that existing imports keep working."""

from model_store.disturbance_library import (  # noqa: F401
    COLUMNS,
    LIBRARY_DIRNAME,
    SAMPLE_RATE_RTOL,
    SCHEMA,
    SCHEMA_VERSION,
    TRACES_DIRNAME,
    UNITS,
    DisturbanceLibrary,
    Trace,
    manifest_name,
)
