"""The base layer :mod:`heli_core`: it stands alone, the old module names re-export it, one error root."""

from __future__ import annotations

import argparse
import ast
import importlib
import inspect
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

import heli_core.backends
import heli_core.discrete
import heli_core.errors
import heli_core.files
import heli_core.params
import heli_core.physics
import heli_core.quaternion
import heli_core.servo
import heli_core.terms
from heli_core.errors import HeliError

ROOT = Path(__file__).resolve().parents[1]
CORE_MODULES = ("params", "physics", "discrete", "servo", "terms", "quaternion", "errors", "files", "backends",
                "config")
UPPER_PACKAGES = ("identification", "heli_env", "controllers", "heli_cli", "model_store")


def test_core_imports_no_package_above_it():
    """Importing every module of heli_core loads none of the packages that stand on it."""
    code = (
        "import sys\n"
        + "".join(f"import heli_core.{m}\n" for m in CORE_MODULES)
        + f"print(sorted(m for m in sys.modules if m.split('.')[0] in {UPPER_PACKAGES!r}))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


def _absolute_imports(path):
    """``(line, top-level package)`` of every absolute import statement in ``path``, lazy ones included."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 0:
            yield node.lineno, (node.module or "").split(".")[0]
        elif isinstance(node, ast.Import):
            yield from ((node.lineno, a.name.split(".")[0]) for a in node.names)


def test_core_source_names_no_package_above_it():
    """No import statement in heli_core names identification, heli_env, controllers or the CLI, even a lazy one."""
    for path in sorted((ROOT / "heli_core").glob("*.py")):
        for line, package in _absolute_imports(path):
            assert package not in UPPER_PACKAGES, f"{path.name}:{line}"


def test_the_env_loads_and_steps_a_model_without_identification():
    """heli_env stands on heli_core and model_store only: loading the shipped model folder and stepping the
    single and the vector env import no module of identification or controllers, nor python-control and
    matplotlib (1.4 s of a new process's 1.9 s to its first step when the servo's Padé came from control)."""
    code = (
        "import sys\nimport numpy as np\nimport gymnasium as gym\nimport heli_env\n"
        "env = gym.make('HeliAttitude-v0'); env.reset(seed=0); env.step(np.zeros(3, dtype=np.float32))\n"
        "from heli_env.vector_env import HeliAttitudeVectorEnv\nvenv = HeliAttitudeVectorEnv(2); venv.reset(seed=0); venv.step(np.zeros((2, 3), dtype=np.float32))\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'identification', 'controllers', 'heli_cli', 'control', 'matplotlib'}))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_model_store_source_names_only_the_core():
    """model_store (the model folder) imports heli_core and nothing of the packages that stand on it."""
    for path in sorted((ROOT / "model_store").glob("*.py")):
        for line, package in _absolute_imports(path):
            assert package not in UPPER_PACKAGES[:-1], f"{path.name}:{line}"


@pytest.mark.parametrize("old, new", [
    ("identification.model.ModelParams", "heli_core.params.ModelParams"),
    ("identification.model.derivatives", "heli_core.physics.derivatives"),
    ("identification.model.step", "heli_core.physics.step"),
    ("identification.model.simulate", "heli_core.physics.simulate"),
    ("identification.model.initial_state", "heli_core.physics.initial_state"),
    ("identification.model.trim_sticks", "heli_core.physics.trim_sticks"),
    ("identification.model.forward_rates", "heli_core.physics.forward_rates"),
    ("identification.model.model_source", "heli_core.physics.model_source"),
    ("identification.model.discrete_step", "heli_core.discrete.discrete_step"),
    ("identification.model.discrete_step_statements", "heli_core.discrete.discrete_step_statements"),
    ("identification.model.linear_structure", "heli_core.discrete.linear_structure"),
    ("identification.model.servo_coefficients", "heli_core.servo.servo_coefficients"),
    ("identification.model.quaternion_from_euler", "heli_core.quaternion.quaternion_from_euler"),
    ("identification.model.euler_from_quaternion", "heli_core.quaternion.euler_from_quaternion"),
    ("identification.integral_method.pade_filter", "heli_core.servo.pade_filter"),
    ("identification.terms.TERMS", "heli_core.terms.TERMS"),
    ("identification.terms.AXES", "heli_core.terms.AXES"),
    ("identification.terms.Term", "heli_core.terms.Term"),
    ("identification.files.write_text", "heli_core.files.write_text"),
    ("identification.files.atomic_path", "heli_core.files.atomic_path"),
    ("identification.backends.LocalBackend", "heli_core.backends.LocalBackend"),
    ("identification.backends.make_backend", "heli_core.backends.make_backend"),
    ("identification.errors.ModelFileError", "model_store.errors.ModelFileError"),
    ("identification.ml_estimator.MaximumLikelihoodIdentifier",
     "identification.likelihood.estimator.MaximumLikelihoodIdentifier"),
    ("identification.ml_estimator.BURN_IN", "identification.likelihood.axis_search.BURN_IN"),
    ("identification.synthetic.FlightConfig", "identification.bench.flight_config.FlightConfig"),
    ("identification.disturbance.identify_disturbance", "identification.disturbance.equivalent_input.identify_disturbance"),
    ("identification.validation.ValidationResult", "identification.validation.result.ValidationResult"),
    ("identification.bench.BENCH_CELLS", "identification.bench.cells.BENCH_CELLS"),
    ("identification.report.identify_and_report", "identification.workflows.identify.identify_and_report"),
    ("identification.errors.MissingDependency", "heli_core.errors.MissingDependency"),
    ("identification.errors.BackendError", "heli_core.errors.BackendError"),
    ("identification.errors.TaskFailed", "heli_core.errors.TaskFailed"),
    ("identification.errors.require", "heli_core.errors.require"),
    # controllers' old names, through the same mechanism (heli_core.deprecation)
    ("controllers.backends.RayBackend", "heli_core.backends.RayBackend"),
    ("controllers.residual.ResidualAgent", "controllers.rl.residual_agent.ResidualAgent"),
    ("controllers.residual.residual_setup", "controllers.rl.train.residual_setup"),
    ("controllers.rl.residual.stack_observations", "controllers.rl.residual_agent.stack_observations"),
    ("controllers.sb3_vec_env.GymnasiumVecEnv", "controllers.rl.vec_env.GymnasiumVecEnv"),
    ("controllers.PDController", "controllers.pd.controller.PDController"),
    ("controllers.design_gains", "controllers.pd.design.design_gains"),
    ("controllers.plant", "controllers.pd.linearisation.plant"),
    ("controllers.evaluate.comparison_markdown", "controllers.evaluate_report.comparison_markdown"),
    ("controllers.evaluate.plot_episode", "controllers.evaluate_report.plot_episode"),
    ("controllers.sweep.parse_range", "controllers.sweep_inputs.parse_range"),
    ("controllers.sweep.MAX_ANGLE_DEG", "controllers.sweep_replay.MAX_ANGLE_DEG"),
    ("controllers.sweep_report.write_json", "controllers.sweep_result.write_json"),
    ("controllers.pd.linearisation.control_sign", "controllers.pd.law.control_sign"),
    # heli_env's: the environment's model module took a name of its own (model_store.model_dir is the folder's)
    ("heli_env.model_dir.load_env_model", "heli_env.env_model.load_env_model"),
    ("heli_env.model_dir.EnvModel", "heli_env.env_model.EnvModel"),
    ("heli_env.env.OBS_DIM", "heli_env.observation.OBS_DIM"),
    ("heli_env.spec.observation_space", "heli_env.observation.observation_space"),
])
def test_old_names_warn_and_are_the_new_objects(old, new):
    """An old name of identification's flat layout (or a shim's) is the object of its one home, read through
    identification._deprecated with a DeprecationWarning naming that home: one class for isinstance checks,
    one cache of compiled kernels."""
    def resolve(dotted):
        module, name = dotted.rsplit(".", 1)
        return getattr(importlib.import_module(module), name)

    home = new.rsplit(".", 1)[0]
    with pytest.warns(DeprecationWarning, match=f"import {old.rsplit('.', 1)[1]} from {home} .*0.2.0"):
        found = resolve(old)
    assert found is resolve(new)


@pytest.mark.parametrize("old", ["identification.model._kernel", "identification.model._CMD_INPUT",
                                 "identification.validation.no_such_name"])
def test_private_and_unknown_old_names_are_gone(old):
    module, name = old.rsplit(".", 1)
    with pytest.raises(AttributeError, match=name):
        getattr(importlib.import_module(module), name)


def test_an_old_module_imports_as_its_alias():
    """``import identification.<old module>`` and ``identification.<old module>`` give the alias of
    identification._deprecated, whose names are the new homes' objects (imported by name here: first-party code
    importing an old name fails scripts/structure_report.py)."""
    import identification
    from identification.likelihood.estimator import MaximumLikelihoodIdentifier
    from identification.workflows.fleet import identify_each

    old = importlib.import_module("identification.ml_estimator")
    with pytest.warns(DeprecationWarning):
        assert old.MaximumLikelihoodIdentifier is MaximumLikelihoodIdentifier
    with pytest.warns(DeprecationWarning, match="identification.workflows.fleet"):
        assert identification.fleet.identify_each is identify_each


def test_every_package_shares_one_deprecation_finder():
    """identification's and controllers' old modules are found by one finder of heli_core.deprecation, not by a
    copy per package."""
    import controllers  # noqa: F401 - installs controllers' table
    import heli_env  # noqa: F401 - installs heli_env's table
    import identification  # noqa: F401 - installs identification's table
    from heli_core.deprecation import _Finder

    finders = [f for f in sys.meta_path if isinstance(f, _Finder)]
    assert len(finders) == 1 and {"identification", "controllers", "heli_env"} <= set(finders[0].tables)


def _error_classes():
    """Every exception class defined in the packages' error modules."""
    modules = ("identification.errors", "identification.io.errors", "heli_env.errors", "controllers.errors",
               "heli_core.errors")
    found = []
    for name in modules:
        module = importlib.import_module(name)
        found += [c for _, c in inspect.getmembers(module, inspect.isclass)
                  if issubclass(c, BaseException) and c.__module__ == name]
    return found


@pytest.mark.parametrize("cls", _error_classes(), ids=lambda c: f"{c.__module__}.{c.__name__}")
def test_every_package_error_derives_from_the_one_root(cls):
    from controllers.errors import TrainingInterrupted

    if cls is TrainingInterrupted:  # an interrupt, not an error: `except Exception` must not swallow a Ctrl-C
        assert issubclass(cls, KeyboardInterrupt) and not issubclass(cls, Exception)
    else:
        assert issubclass(cls, HeliError)


@pytest.mark.parametrize("dotted, standard", [
    ("identification.errors.FlightLogError", ValueError),
    ("identification.errors.UnitError", ValueError),
    ("identification.errors.IdentifiabilityError", ValueError),
    ("identification.errors.SimulationDivergedError", ValueError),
    ("model_store.errors.ModelFileError", ValueError),
    ("identification.errors.NotFittedError", ValueError),
    ("identification.errors.NotFittedError", AttributeError),
    ("identification.errors.DisturbanceError", ValueError),
    ("model_store.errors.LibraryError", ValueError),
    ("heli_core.errors.MissingDependency", ImportError),
    ("heli_core.errors.BackendError", ValueError),
    ("heli_core.errors.TaskFailed", RuntimeError),
    ("identification.io.errors.LogFormatError", ValueError),
    ("heli_env.errors.EnvModelError", ValueError),
    ("heli_env.errors.ActionError", ValueError),
    ("controllers.errors.SweepError", ValueError),
    ("controllers.errors.AgentError", ValueError),
    ("controllers.errors.DesignError", ValueError),
    ("controllers.errors.TrainingInterrupted", KeyboardInterrupt),
])
def test_package_errors_keep_their_standard_base(dotted, standard):
    """Callers that catch the standard exception keep working."""
    module, name = dotted.rsplit(".", 1)
    cls = getattr(importlib.import_module(module), name)
    assert issubclass(cls, standard)


def test_task_failed_keeps_its_index():
    e = heli_core.errors.TaskFailed("worker died", index=3)
    assert e.index == 3 and str(e) == "worker died" and isinstance(e, RuntimeError)


def test_cli_counts_every_heli_error_as_a_user_error(capsys, monkeypatch):
    """A HeliError of any package, even one the CLI never heard of, ends in one line and exit status 2."""
    from heli_cli import main as cli

    class Invented(HeliError, ValueError):
        pass

    def fail(args):
        raise Invented("expected a thing, got another")

    class Parser:
        def parse_args(self, argv=None):
            return argparse.Namespace(command="simulate-flight", func=fail, debug=False)

    monkeypatch.setattr(cli, "build_parser", Parser)
    assert cli.main([]) == 2
    assert capsys.readouterr().err.splitlines() == ["heli simulate-flight: error: Invented: expected a thing, got another"]


def test_euler_conversion_is_one_text():
    """The numpy, float and numba paths read the same five expressions (eqs. 27-29)."""
    from heli_env.kernels import _EULER_ARGUMENTS

    rng = np.random.default_rng(0)
    q = rng.normal(size=(4, 200))
    q /= np.linalg.norm(q, axis=0)
    args = heli_core.quaternion.euler_arguments(*q)
    for i in range(q.shape[1]):  # the float path does the numpy path's arithmetic exactly
        assert heli_core.quaternion.euler_arguments(*map(float, q[:, i])) == tuple(a[i] for a in args)
    scalar = np.array([heli_core.quaternion.euler_from_quaternion_scalar(*map(float, q[:, i]))
                       for i in range(q.shape[1])]).T
    assert_allclose(scalar, heli_core.quaternion.euler_from_quaternion(q), rtol=0, atol=1e-15)
    for expr in heli_core.quaternion.EULER_ARGUMENTS:
        assert any(expr.replace("q", "b") in line for line in _EULER_ARGUMENTS)


def test_euler_round_trip():
    euler = np.array([[0.3, -1.2, 2.9], [-0.1, 0.7, -3.0], [1.4, -0.2, 0.01]]).T  # (3, n) inside the ZYX range
    assert_allclose(heli_core.quaternion.euler_from_quaternion(heli_core.quaternion.quaternion_from_euler(*euler)),
                    euler, rtol=0, atol=1e-14)
    assert math.isclose(heli_core.quaternion.euler_from_quaternion_scalar(1.0, 0.0, 0.0, 0.0)[2], 0.0)


def test_stick_rows_name_the_axis_sticks():
    t = heli_core.terms
    assert tuple(t.STICKS[i] for i in t.STICK_ROW) == t.INPUT_FOR_AXIS
    assert t.AXES == ("roll", "pitch", "yaw")


def test_discrete_step_follows_rk4():
    """One exact-ZOH period against 20 RK4 sub-steps of the same model with every effect switched on."""
    from heli_core.params import ModelParams
    from heli_core.physics import initial_state, step

    params = ModelParams(k1=0.8, k2=1.35, k3=2.4, k4=0.8, kd1=0.04, k5=0.9, k6=-0.89, k7=2.5, k8=0.7, kd2=0.01,
                         k9=-0.95, k10=13.5, k11=3.4, k12=-0.56, kd3=0.1, tau_roll=0.08, tau_pitch=0.08, tau_yaw=0.05,
                         extra=(("nld1", 2.0), ("gs1", -0.8)), lag_pitch=0.03, lag_yaw=0.04)
    rng = np.random.default_rng(1)
    x = initial_state(rates=rng.normal(0, 0.5, 3), euler=rng.normal(0, 0.2, 3), sticks=rng.uniform(-0.3, 0.3, 3),
                      batch=())
    u = rng.uniform(-0.5, 0.5, 4)
    d = rng.normal(0, 0.3, 3)
    exact = np.array(heli_core.discrete.discrete_step(tuple(x), tuple(u), tuple(d), params, 0.01))
    reference = np.array(step(tuple(x), tuple(u), tuple(d), params, 0.01, substeps=20))
    assert_allclose(exact[:6], reference[:6], rtol=0, atol=5e-5)  # products held over 10 ms: first order in dt
    assert_allclose(exact[6:], reference[6:], rtol=0, atol=2e-5)  # turned by the mean of two rates


def test_one_linearisation_for_design_and_for_the_sweep():
    """The PD design's axis plant and the sweep's hover plant are blocks of heli_core.linear's one
    linearisation; it holds the decoupled eqs. (18), (21), the Padé servo (31) and the gain the
    collective schedules (u·col), which the previous design-side linearisation left out."""
    from controllers.closed_loop import hover_plant
    from controllers.pd.linearisation import _axis_ss
    from heli_core.linear import hover_linearisation
    from heli_core.servo import servo_coefficients
    from identification.bench.flight_config import PAPER_PARAMS

    params = PAPER_PARAMS.with_values(gs1=-0.6, k4=0.8, tau_pitch=0.05)
    lin = hover_linearisation(params, 0.3)
    assert lin.states == ("p", "q", "r", "servo_pitch", "roll", "pitch", "yaw")
    assert lin.A[0, 0] == pytest.approx(-2.4208, rel=1e-8) and lin.A[0, 1] == pytest.approx(0.8, rel=1e-8)
    assert lin.Bu[0, 0] == pytest.approx(1.3475 - 0.6 * 0.3, rel=1e-8)  # k2 + gs1·col at this collective
    d1, n1, n2 = servo_coefficients(0.05)
    assert lin.A[3, 3] == pytest.approx(-1.0 / d1, rel=1e-8)  # the pitch servo's Padé pole
    plant = hover_plant(params, 0.01, 0.3)
    np.testing.assert_array_equal(plant.Ac, lin.A)
    np.testing.assert_array_equal(plant.Buc, lin.Bu)
    A, B, C = _axis_ss(params, 1)  # pitch at collective 0: its own block of the same linearisation
    A0, B0, states = hover_linearisation(params, 0.0).axis_block(1)
    np.testing.assert_array_equal(A, A0)
    np.testing.assert_array_equal(B, B0)
    assert states == ["q", "servo_pitch", "pitch"] and A.shape == (3, 3)


def test_a_config_object_or_its_fields_by_keyword():
    """heli_core.config.configured: the default config, a keyword replacing the config's field, the same
    object when nothing replaces it, and a TypeError naming an unknown setting or a config of another class."""
    from dataclasses import dataclass

    from heli_core.config import configured, whole_number

    @dataclass(frozen=True)
    class Settings:
        count: int = 1
        label: str = "a"

        def __post_init__(self):
            object.__setattr__(self, "count", whole_number(self.count, "count", 1))

    base = Settings(count=3)
    assert configured(Settings, None, {}, "test") == Settings()
    assert configured(Settings, base, {}, "test") is base
    assert configured(Settings, base, {"label": "b"}, "test") == Settings(count=3, label="b")
    assert configured(Settings, None, {"count": 2.0}, "test").count == 2
    with pytest.raises(ValueError, match=r"count must be a whole number >= 1, got 0"):
        configured(Settings, base, {"count": 0}, "test")  # a replaced field is checked again
    with pytest.raises(TypeError, match="unknown test settings counts; expected fields of Settings"):
        configured(Settings, None, {"counts": 2}, "test")
    with pytest.raises(TypeError, match="config must be a Settings"):
        configured(Settings, {"count": 2}, {}, "test")
