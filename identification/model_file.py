"""Moved to :mod:`model_store.model_file`; this module re-exports it so that existing imports keep working."""

from model_store.model_file import (  # noqa: F401
    MODEL_FILENAME,
    SCHEMA,
    SCHEMA_VERSION,
    encode_model,
    load_model,
    model_document,
    params_from_document,
    save_model,
)
