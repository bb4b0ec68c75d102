"""The one root of every error heli-env raises, and the errors of the core itself.

Each package keeps a small exception module of its own
(:mod:`identification.errors`, :mod:`heli_env.errors`, :mod:`controllers.errors`);
every class there derives from :class:`HeliError` *and* from the standard
exception a caller would otherwise catch (``class FlightLogError(HeliError,
ValueError)``). So ``except HeliError`` catches whatever the package raised on
purpose, and ``except ValueError`` keeps working where it did.

The errors defined here are those of the core's own modules: a missing optional
dependency (:func:`require`) and the compute backends (:mod:`heli_core.backends`).
:mod:`identification.errors` re-exports them under their old names.
"""

from __future__ import annotations


class HeliError(Exception):
    """Root of every exception heli-env raises on purpose.

    Messages say what was expected and what came, so a user can fix the input
    without reading a traceback.
    """


class MissingDependency(HeliError, ImportError):
    """An optional dependency (an extra of ``heli-env``) is not installed."""


class BackendError(HeliError, ValueError):
    """A compute backend cannot be made as asked (unknown name, a worker count < 1, bad retry settings)."""


class TaskFailed(HeliError, RuntimeError):
    """A task of a backend could not finish: its worker died more often than the retries allow.

    Parameters
    ----------
    message : str
    index : int
        The task's position among the mapped items (-1 when unknown).
    """

    def __init__(self, message: str, index: int = -1):
        super().__init__(message)
        self.index = index


#: The one command that installs a module whose extra cannot: orangebox 0.5.0's wheel declares console
#: scripts without a callable (``bb2csv = scripts/bb2csv``), so pip installs the module and then exits with
#: status 1 (and, inside an extra, stops before the packages after it). The command therefore tolerates pip's
#: status and lets the import decide. The Makefile's ``setup`` runs the same line (``LOG_DECODER``); 0.4.0
#: installs cleanly but misreads 25 of the 9407 frames of the Rotorflight fixture log.
BLACKBOX_INSTALL = "python -m pip install 'orangebox>=0.5' || python -c 'import orangebox'"

#: Install commands for modules that are not (or not only) an extra's, keyed by top-level module.
INSTALL_COMMANDS = {"orangebox": BLACKBOX_INSTALL}


def install_advice(module: str, extra: str) -> str:
    """The shell command that installs ``module``, to print after "install it with:".

    Parameters
    ----------
    module : str
        Importable module name; its top-level package selects a special command.
    extra : str
        The ``heli-env`` extra that provides it otherwise.

    Returns
    -------
    str
        A command that exits 0 on a fresh machine with ``heli-env`` installed: ``pip install
        'heli-env[extra]'`` for the extras that install cleanly, :data:`BLACKBOX_INSTALL` for orangebox.
    """
    return INSTALL_COMMANDS.get(module.split(".")[0], f"python -m pip install 'heli-env[{extra}]'")


def require(module: str, extra: str):
    """Import an optional module lazily, naming the extra that provides it.

    Parameters
    ----------
    module : str
        Importable module name, e.g. ``"pyulog"``.
    extra : str
        The ``heli-env`` extra that installs it, e.g. ``"logs"``.

    Returns
    -------
    module

    Raises
    ------
    MissingDependency
        The module cannot be imported; the message names the command that installs it (:func:`install_advice`).
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise MissingDependency(
            f"'{module}' is needed for this and is not installed; "
            f"install it with: {install_advice(module, extra)}"
        ) from e
