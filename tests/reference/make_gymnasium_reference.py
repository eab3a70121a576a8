"""Writes reference trajectories from Gymnasium's own v5 environments (tests/reference/*.csv).

The Rust test `gymnasium_reference` replays the same actions from the same initial state
(reset noise 0) in locobench and compares observations and rewards. Regenerate with:

    python3 -m venv /tmp/gymref && /tmp/gymref/bin/pip install "gymnasium[mujoco]"
    /tmp/gymref/bin/python tests/reference/make_gymnasium_reference.py [NAME ...]

With names (e.g. `walker2d hopper`), only those files are rewritten.
"""
import csv
import math
import os
import sys

import gymnasium as gym
import mujoco

ENVS = {
    # locobench name: (Gymnasium id, steps, action scale)
    "half-cheetah": ("HalfCheetah-v5", 200, 0.5),
    "ant": ("Ant-v5", 50, 0.5),
    "humanoid": ("Humanoid-v5", 50, 0.3),
    "inverted-pendulum": ("InvertedPendulum-v5", 200, 0.5),
    "walker2d": ("Walker2d-v5", 100, 0.5),
    "hopper": ("Hopper-v5", 100, 0.5),
}


def action(t, n, scale):
    return [scale * math.sin((t * 7 + i * 3) * 0.37) for i in range(n)]


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    names = sys.argv[1:] or list(ENVS)
    for name in names:
        env_id, steps, scale = ENVS[name]
        env = gym.make(env_id, reset_noise_scale=0.0)
        obs, _ = env.reset(seed=0)
        n = env.action_space.shape[0]
        path = os.path.join(here, f"{name}.csv")
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["step", "reward", "terminated", "observation..."])
            w.writerow([0, 0.0, 0] + [repr(float(v)) for v in obs])
            for t in range(steps):
                obs, reward, terminated, truncated, _ = env.step(action(t, n, scale))
                w.writerow([t + 1, repr(float(reward)), int(terminated)] + [repr(float(v)) for v in obs])
                if terminated or truncated:
                    break
        print(f"{path}: {env_id}, mujoco {mujoco.__version__}, gymnasium {gym.__version__}")


if __name__ == "__main__":
    main()
