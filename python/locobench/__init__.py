"""locobench from Python: Gymnasium environments, the Raibert/QP controller and trained policies.

Importing the package registers every environment with Gymnasium::

    import gymnasium as gym
    import locobench

    env = gym.make("locobench/Minitaur-v0", randomize_dynamics=False, reward={"drift": 0.5})
    envs = gym.make_vec("locobench/Minitaur-v0", num_envs=8)   # stepped in Rust, on every core
"""
from locobench._core import env_names_ as _env_names
from locobench._core import episode_seed
from locobench.envs import ENV_IDS, LocobenchEnv, register_envs
from locobench.evaluation import evaluate
from locobench.sb3 import import_sb3
from locobench.policies import Controller, TrainedPolicy, load_policy
from locobench.vector import LocobenchVectorEnv

__all__ = [
    "ENV_IDS",
    "LocobenchEnv",
    "LocobenchVectorEnv",
    "episode_seed",
    "Controller",
    "TrainedPolicy",
    "load_policy",
    "env_names",
    "evaluate",
    "import_sb3",
    "register_envs",
]


def env_names():
    """The names of the registered environments, as the command line knows them."""
    return list(_env_names())


register_envs()
