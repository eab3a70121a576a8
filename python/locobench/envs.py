"""Every locobench environment as a Gymnasium environment."""
import importlib
import importlib.util
import json
import numbers
import sys

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from locobench import _core

# Gymnasium ids: the Gymnasium-v5 tasks keep their version; Minitaur is this project's first.
ENV_IDS = {
    "minitaur": "locobench/Minitaur-v0",
    "half-cheetah": "locobench/HalfCheetah-v5",
    "ant": "locobench/Ant-v5",
    "humanoid": "locobench/Humanoid-v5",
    "inverted-pendulum": "locobench/InvertedPendulum-v5",
    "walker2d": "locobench/Walker2d-v5",
    "hopper": "locobench/Hopper-v5",
    "minitaur-command": "locobench/MinitaurCommand-v0",
    "ant-command": "locobench/AntCommand-v0",
    "walker2d-notch": "locobench/Walker2dNotch-v0",
}

_RENDER_MODES = ["rgb_array", "rgb_array_list"]


def _toml_value(key, value):
    """An option value as the TOML text the Rust side parses."""
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        value = float(value)
        if not np.isfinite(value):
            raise ValueError(f"option {key}: {value} is not finite")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(key, v) for v in value) + "]"
    raise TypeError(f"option {key}: {value!r} is not a bool, number, string or list")


def _load_triton_first():
    """PyTorch's triton (which PyTorch imports when it first builds an optimizer) crashes the
    process with a segmentation fault when it is loaded after Mesa's OpenGL (OSMesa), which
    rendering loads: both bring their own LLVM. Loaded first, both work; so where triton is
    installed, it is imported before the first renderer."""
    if "triton" not in sys.modules and importlib.util.find_spec("triton") is not None:
        importlib.import_module("triton")


def _core_arguments(options, reward):
    """Env options as (key, TOML text) pairs and reward weights as (term, weight) pairs, as the
    Rust side takes them."""
    pairs = [(k, _toml_value(k, v)) for k, v in options.items()]
    weights = [(str(t), float(w)) for t, w in (reward or {}).items()]
    return pairs, weights


def _float64_actions(actions, shape, what, hint=""):
    """``actions`` as float64 after checking they are numeric (TypeError) and of ``shape``
    (ValueError), the messages naming ``what``."""
    a = np.asarray(actions)
    if a.dtype.kind not in "fiu":
        raise TypeError(f"{what} dtype {a.dtype} is not numeric")
    if a.shape != shape:
        raise ValueError(f"{what} shape {a.shape}, expected {shape}{hint}")
    return a.astype(np.float64, copy=False)


class LocobenchEnv(gym.Env):
    """A locobench environment (Rust and MuJoCo underneath) with Gymnasium's API.

    ``name`` is the env's locobench name (``locobench.env_names()``); every other keyword is an
    env option (``locobench envs`` and docs/environments.md list them), and ``reward`` maps
    reward-term names to weights. ``info["reward_terms"]`` holds each term's signed contribution;
    they sum to the reward. The episode limit is the env's own ``max_episode_steps`` option
    (truncation), so no TimeLimit wrapper is needed.
    """

    metadata = {"render_modes": _RENDER_MODES}

    def __init__(
        self, name, render_mode=None, reward=None, width=640, height=480, camera="follow", _option_pairs=None, **options
    ):
        if render_mode is not None and render_mode not in _RENDER_MODES:
            raise ValueError(f"render_mode={render_mode!r}: one of {_RENDER_MODES} (or None)")
        self.render_mode = render_mode
        pairs, weights = _core_arguments(options, reward)
        self._core = _core.Env(name, list(_option_pairs or []) + pairs, weights)
        self.name = self._core.name
        low, high = self._core.observation_bounds
        self.observation_space = spaces.Box(np.array(low), np.array(high), dtype=np.float64)
        low, high = self._core.action_bounds
        self.action_space = spaces.Box(
            np.array(low, dtype=np.float32), np.array(high, dtype=np.float32), dtype=np.float32
        )
        self.metadata = {"render_modes": _RENDER_MODES, "render_fps": 1.0 / self._core.dt}
        self.episode = -1
        # Made here, so that a missing OpenGL library or a bad camera is an error at once.
        if render_mode is not None:
            _load_triton_first()
        self._renderer = None if render_mode is None else _core.Renderer(self._core, width, height, camera)
        self._frames = []

    def reset(self, *, seed=None, options=None):
        """Starts an episode. ``seed`` reseeds the env's own stream; without one it continues."""
        super().reset(seed=seed)
        if options:
            raise ValueError("reset(options=...) is not supported: give env options to gymnasium.make")
        if seed is not None and (not isinstance(seed, numbers.Integral) or seed < 0):
            raise ValueError(f"seed must be a non-negative integer, not {seed!r}")
        obs, info = self._core.reset(None if seed is None else int(seed))
        self.episode += 1
        if self.render_mode == "rgb_array_list":
            self._frames = [self._frame()]
        return np.asarray(obs, dtype=np.float64), info

    def step(self, action):
        a = _float64_actions(action, self.action_space.shape, "action")
        obs, reward, terminated, truncated, info = self._core.step(a.ravel().tolist())
        if self.render_mode == "rgb_array_list":
            self._frames.append(self._frame())
        return np.asarray(obs, dtype=np.float64), float(reward), bool(terminated), bool(truncated), info

    def _frame(self):
        width, height, rgb = self._renderer.render(self._core)
        return np.frombuffer(rgb, dtype=np.uint8).reshape(height, width, 3)

    def set_state(self, qpos, qvel):
        """Overwrites the simulation's positions and velocities (Gymnasium MujocoEnv's set_state)."""
        self._core.set_state(np.asarray(qpos, dtype=np.float64).tolist(), np.asarray(qvel, dtype=np.float64).tolist())

    @property
    def command(self):
        """On a command task (``locobench/MinitaurCommand-v0``, ``locobench/AntCommand-v0``): the
        velocity command in force, (forward speed m/s, yaw rate rad/s); None on other envs."""
        return self._core.command

    def set_command(self, speed, yaw_rate=0.0):
        """On a command task: holds this command (forward speed m/s, yaw rate rad/s, positive
        turning left) from the next step until the next reset, as a joystick would. The random
        redraws and any schedule stop until then. Other envs raise ValueError."""
        self._core.set_command(float(speed), float(yaw_rate))

    @property
    def state(self):
        """(qpos, qvel) of the simulation now."""
        qpos, qvel = self._core.state
        return np.asarray(qpos), np.asarray(qvel)

    def render(self):
        """The frame of the current state, (height, width, 3) uint8, with ``render_mode="rgb_array"``;
        the frames since the last call (or reset), with ``"rgb_array_list"``; None without a
        render mode. Offscreen, with no display: OSMesa, or EGL with ``MUJOCO_GL=egl``."""
        if self.render_mode == "rgb_array":
            return self._frame()
        if self.render_mode == "rgb_array_list":
            frames, self._frames = self._frames, []
            return frames
        if self.render_mode is None:
            gym.logger.warn("render() without a render_mode: make the env with render_mode='rgb_array'")
        return None


def register_envs():
    """Registers every locobench env with Gymnasium (done on import)."""
    for name, env_id in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(
                id=env_id,
                entry_point="locobench.envs:LocobenchEnv",
                vector_entry_point="locobench.vector:LocobenchVectorEnv",
                kwargs={"name": name},
            )
