"""Reports ask an agent what it is (``describe()``) instead of testing its class."""

from controllers.agent_description import describe_agent
from controllers.pd.controller import PDController, PDGains


def test_an_agent_is_asked_and_one_without_describe_is_named_by_its_class():
    class Custom:
        def describe(self):
            return "mpc", "MPC (horizon 20)"

        def predict(self, observation, state=None, episode_start=None, deterministic=False):
            return observation[..., :3] * 0, state

    class PPO:  # an SB3 model says nothing of itself
        pass

    pd = PDController(PDGains([20.0, 30.0, 4.0], [3.0, 5.0, 0.5]), [1, -1, 1])
    assert describe_agent(Custom()) == ("mpc", "MPC (horizon 20)")
    assert describe_agent(PPO()) == ("ppo", "PPO")
    assert describe_agent(pd) == ("pd", "PD kp=(20, 30, 4) kd=(3, 5, 0.5)") == pd.describe()


def test_a_residual_describes_its_policy_and_its_base():
    from controllers.rl.residual_agent import ResidualAgent

    class PPO:
        pass

    pd = PDController(PDGains([20.0, 30.0, 4.0], [3.0, 5.0, 0.5]), [1, -1, 1])
    agent = ResidualAgent.__new__(ResidualAgent)  # the parts describe() reads, without a trained policy
    agent.policy, agent.base, agent.scale = PPO(), pd, 0.05
    assert describe_agent(agent) == ("ppo-residual", "PPO ±0.05 stick on PD kp=(20, 30, 4) kd=(3, 5, 0.5)")
