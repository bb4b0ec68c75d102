"""The model directory: ``model.json``, the disturbance library and ``history/``, owned by one class.

:class:`ModelDir` reads a directory as one checked state (:meth:`ModelDir.load`) and changes it as one
transaction (:meth:`ModelDir.transaction`), so that a crash at any instant leaves the old or the new state
and two writers take turns. :mod:`model_store.model_file` is the ``model.json`` format (read as one typed :class:`ModelDocument`),
:mod:`model_store.disturbance_library` the versioned library of wind traces.
"""

from .disturbance_library import DisturbanceLibrary, Trace
from .model_dir import ModelDir, ModelState, Transaction
from .model_file import MODEL_FILENAME, ModelDocument, Source, load_model, model_document, save_model, verdict_of
from .verdict import ModelVerdict

__all__ = ["MODEL_FILENAME", "DisturbanceLibrary", "ModelDir", "ModelDocument", "ModelState", "ModelVerdict", "Source",
           "Trace", "Transaction", "load_model", "model_document", "save_model", "verdict_of"]
