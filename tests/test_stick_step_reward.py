"""The stick-step weight from ``heli train`` to the reward the agent is trained on."""

import pytest

pytest.importorskip("stable_baselines3")


def test_heli_train_passes_the_stick_step_weight_into_the_training_task():
    """``--stick-step-weight 0.5`` reaches TrainConfig and the named task the copies fly; 0 leaves the task a name
    (the reward of before); a negative or non-numeric weight is refused by name."""
    import argparse

    from controllers.errors import AgentError
    from controllers.rl.config import TrainConfig
    from controllers.rl.train import _residual_setup
    from heli_cli.train import add_learning_options, learning_settings

    p = argparse.ArgumentParser()
    add_learning_options(p)
    settings = learning_settings(p.parse_args(["--stick-step-weight", "0.5"]))
    assert settings["stick_step_weight"] == 0.5
    config = TrainConfig(algo="ppo", timesteps=64, stick_step_weight=0.5)
    _, task = _residual_setup(config, None, None)
    assert task.task == "hold" and task.stick_step_weight == 0.5 and task.weights == (1.0, 0.1, 0.01)
    assert _residual_setup(TrainConfig(algo="ppo", timesteps=64), None, None)[1] == "hold"
    for bad in (-1.0, float("nan"), "x", True):
        with pytest.raises(AgentError, match="stick_step_weight must be a number >= 0"):
            TrainConfig(algo="ppo", timesteps=64, stick_step_weight=bad)
    with pytest.raises(SystemExit):
        p.parse_args(["--stick-step-weight", "-1"])
