"""The controller and trained policies, called the way Stable-Baselines3 policies are."""
import os

import gymnasium as gym
import numpy as np

from locobench import _core
from locobench.envs import LocobenchEnv


class Controller:
    """The Raibert/QP controller, commanded to a forward speed (m/s) and yaw rate (rad/s).

    It reads the whole simulation state, not only the observation, so it drives a locobench env:
    pass an env name to get one made in the controller's action mode (``controller.env``), or an
    env made with the options ``Controller.env_options(name)`` lists. ``predict`` follows SB3.
    """

    def __init__(self, env, speed=0.35, yaw_rate=0.0, gait=None):
        if isinstance(env, str):
            env = make_controller_env(env)
        base = env.unwrapped if isinstance(env, gym.Env) else env
        if not isinstance(base, LocobenchEnv):
            raise TypeError("Controller drives a locobench env (or give an env name)")
        for key, value in _core.Controller.env_options(base.name):
            if base._core.option_value(key) != value:
                raise ValueError(
                    f"the controller needs the env made with {key}={value} "
                    f"(Controller.env_options('{base.name}')); this one has {base._core.option_value(key)}"
                )
        self._core = _core.Controller(base.name, float(speed), float(yaw_rate), gait)
        self.env = env
        self._base = base
        self._episode = None

    @staticmethod
    def env_options(name):
        """The options an env needs for the controller to drive it, as a dict of TOML texts."""
        return dict(_core.Controller.env_options(name))

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """(action, state) for the env's current state, as SB3's ``predict``."""
        if self._base.episode != self._episode:
            self._episode = self._base.episode
            self._core.begin_episode(max(self._episode, 0))
        obs = np.asarray(observation, dtype=np.float64).ravel().tolist()
        return np.asarray(self._core.act(self._base._core, obs), dtype=np.float32), state


def make_controller_env(name, **options):
    """A Gymnasium env in the controller's action mode (Minitaur: torque actions)."""
    from locobench.envs import ENV_IDS

    if name not in ENV_IDS:
        raise ValueError(f"unknown env '{name}': one of {sorted(ENV_IDS)}")
    return gym.make(ENV_IDS[name], _option_pairs=list(_core.Controller.env_options(name)), **options)


class TrainedPolicy:
    """A trained actor acting deterministically; ``predict`` follows SB3."""

    def __init__(self, path, budget=None, device="cpu"):
        self._core = _core.TrainedPolicy(os.fspath(path), budget, device)
        self.env_name = self._core.env

    def make_env(self, perturbed=False, **options):
        """A Gymnasium env in the world ``locobench eval`` plays the policy in: the options it was
        trained with, its training perturbations (pushes, terrain, latency, noise, random
        dynamics) switched off, and any options given here on top. ``perturbed=True`` keeps the
        training perturbations on."""
        from locobench.envs import ENV_IDS

        pairs = self._core.env_options if perturbed else self._core.evaluation_options
        return gym.make(ENV_IDS[self.env_name], _option_pairs=list(pairs), **options)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """(action, state): the actor's action for one observation, in the env's bounds."""
        obs = np.asarray(observation, dtype=np.float64)
        if obs.ndim == 2:
            actions = [self._core.act(o.tolist()) for o in obs]
            return np.asarray(actions, dtype=np.float32), state
        return np.asarray(self._core.act(obs.ravel().tolist()), dtype=np.float32), state


def load_policy(path, budget=None, device="cpu"):
    """A trained policy, as ``locobench eval --policy PATH [--budget N] [--device D]`` reads it.

    ``path``: a run directory (its newest checkpoint, or for a committed result run such as
    ``benches/results/minitaur/ppo-8envs-seed0-2m`` its newest budget policy), a checkpoint
    directory, a budget policy file (``RUN/policies/step-N.safetensors``) or an exported policy.
    ``budget``: with a run directory, the actor the run saved at that step.
    ``device``: where the networks run, ``"cpu"`` (the exact path) or ``"cuda"`` / ``"cuda:N"``
    (a build with the ``cuda`` feature; see docs/gpu.md). Anything else is a ``ValueError``.
    """
    return TrainedPolicy(path, budget, device)
