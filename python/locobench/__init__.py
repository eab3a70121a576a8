"""locobench from Python: Gymnasium environments, the Raibert/QP controller and trained policies.

Importing the package registers every environment with Gymnasium::

    import gymnasium as gym
    import locobench

    env = gym.make("locobench/Minitaur-v0", randomize_dynamics=False, reward={"drift": 0.5})
"""
from locobench._core import env_names_ as _env_names
from locobench.envs import ENV_IDS, LocobenchEnv, register_envs
from locobench.policies import Controller, TrainedPolicy, load_policy

__all__ = ["ENV_IDS", "LocobenchEnv", "Controller", "TrainedPolicy", "load_policy", "env_names", "register_envs"]


def env_names():
    """The names of the registered environments, as the command line knows them."""
    return list(_env_names())


register_envs()
