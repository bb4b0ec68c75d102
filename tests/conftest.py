"""Fixtures shared by the test files.

``shipped`` is the model that ships with heli-env (``heli_env/data``), loaded once per session: identified
from realistic flights (servo delay, sensor noise and vibration lines). ``ideal_model_dir`` is the model that
shipped before it (identified from flights with no servo delay, measured exactly): tests whose subject is the
machinery of the sweep, the evaluator or the training, rather than the realistic world, fly it.
``load_script`` loads one of ``scripts/`` (not a package) as a module.
"""

import importlib.util
import os
from pathlib import Path

import pytest

if os.environ.get("PYTEST_XDIST_WORKER"):  # one pytest worker per core already: fit the axes one after another
    os.environ.setdefault("HELI_WORKERS", "1")
# ``heli identify``'s closed-loop check costs about 8 fits of the flight, and the CLI tests identify 40-s
# flights some forty times for other reasons: they run without it. The check is the subject of
# tests/test_closed_loop.py, and test_cli.py's test of the default unsets this for its run.
os.environ.setdefault("HELI_CLOSED_LOOP", "off")
# The fit rate's choice (identification.fit_rate) fits each log twice more (2-3 s for a 300 s flight): the suite's
# logs are white gyros, fitted at their rate. The choice is the subject of tests/test_fit_rate.py, which sets 'auto'.
os.environ.setdefault("HELI_FIT_RATE", "log")

from heli_env.env_model import load_env_model


@pytest.fixture(scope="session")
def load_script():
    """``load_script(name)``: ``scripts/<name>.py`` executed as a module, returned."""
    def load(name: str):
        path = Path(__file__).resolve().parents[1] / "scripts" / f"{name}.py"
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load


@pytest.fixture(scope="session")
def shipped():
    """The shipped model as the env loads it (an :class:`heli_env.spec.EnvModel`)."""
    return load_env_model()


IDEAL_MODEL_DIR = Path(__file__).parent / "data" / "ideal_model"


@pytest.fixture(scope="session")
def ideal_model_dir():
    """The model directory of the previous shipped model (no servo delay, no sensors; read only)."""
    return IDEAL_MODEL_DIR


@pytest.fixture(scope="session")
def ideal(ideal_model_dir):
    """:func:`ideal_model_dir` as the env loads it."""
    return load_env_model(ideal_model_dir)


@pytest.fixture(scope="session")
def flight_csv(tmp_path_factory):
    """``heli simulate-flight --duration 40 --seed 3 --out X.csv`` (read only: the CLI tests identify it)."""
    from heli_cli.main import main

    path = tmp_path_factory.mktemp("sim") / "X.csv"
    assert main(["simulate-flight", "--duration", "40", "--seed", "3", "--out", str(path)]) == 0
    return path
