"""Fixtures shared by the test files.

``shipped`` is the model that ships with heli-env (``heli_env/data``), loaded once per session.
"""

import pytest

from heli_env.model_dir import load_env_model


@pytest.fixture(scope="session")
def shipped():
    """The shipped model as the env loads it (an :class:`heli_env.spec.EnvModel`)."""
    return load_env_model()

