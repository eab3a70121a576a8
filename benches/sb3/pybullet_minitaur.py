"""Stable-Baselines3's TD3 or SAC on PyBullet's own MinitaurBulletEnv (the env locobench's
Minitaur reimplements), with the settings locobench uses by default, evaluated like locobench
(10 deterministic episodes every 5k steps). It answers whether a learning behaviour seen here
(e.g. TD3 settling on an immediate fall) belongs to the task or to this project.

    python3 -m venv /tmp/pyb && /tmp/pyb/bin/pip install pybullet "gym==0.26.2" "numpy<2" \
        stable-baselines3==2.3.2 gymnasium "setuptools<70"
    sed -i 's/registry.env_specs/registry/' /tmp/pyb/lib/python3.11/site-packages/pybullet_envs/__init__.py
    /tmp/pyb/bin/python benches/sb3/pybullet_minitaur.py td3 0 100000 td3-seed0.csv

Prints and writes `step,eval_mean,eval_std,eval_length` rows.
"""
import sys

import gymnasium
import numpy as np
import torch
from pybullet_envs.bullet.minitaur_gym_env import MinitaurBulletEnv
from stable_baselines3 import SAC, TD3
from stable_baselines3.common.noise import NormalActionNoise


class Minitaur(gymnasium.Env):
    """The old-gym PyBullet env with gymnasium's API and the 1000-step limit it is run with."""

    def __init__(self):
        self.env = MinitaurBulletEnv(render=False)
        low = self.env.observation_space.low.astype(np.float32)
        self.observation_space = gymnasium.spaces.Box(low, -low, dtype=np.float32)
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, (8,), dtype=np.float32)
        self.t = 0

    def reset(self, seed=None, options=None):
        self.t = 0
        return self.env.reset().astype(np.float32), {}

    def step(self, action):
        obs, reward, done, _ = self.env.step(np.asarray(action, dtype=float))
        self.t += 1
        return obs.astype(np.float32), float(reward), bool(done), self.t >= 1000 and not done, {}


def evaluate(model, env, episodes=10):
    returns, lengths = [], []
    for _ in range(episodes):
        obs, _ = env.reset()
        total, n, done = 0.0, 0, False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, r, term, trunc, _ = env.step(action)
            total, n, done = total + r, n + 1, term or trunc
        returns.append(total)
        lengths.append(n)
    return float(np.mean(returns)), float(np.std(returns)), float(np.mean(lengths))


def main():
    algo, seed, steps, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    torch.set_num_threads(1)
    np.random.seed(seed)  # PyBullet's dynamics randomiser draws from numpy's global stream
    env, eval_env = Minitaur(), Minitaur()
    if algo == "td3":
        model = TD3("MlpPolicy", env, learning_rate=1e-3, batch_size=100, learning_starts=10_000, tau=0.005,
                    action_noise=NormalActionNoise(np.zeros(8), 0.1 * np.ones(8)), policy_delay=2,
                    target_policy_noise=0.2, target_noise_clip=0.5, policy_kwargs={"net_arch": [400, 300]},
                    seed=seed, verbose=0)
    elif algo == "sac":
        model = SAC("MlpPolicy", env, learning_rate=3e-4, batch_size=256, learning_starts=10_000, tau=0.005,
                    ent_coef="auto", policy_kwargs={"net_arch": [256, 256]}, seed=seed, verbose=0)
    else:
        raise SystemExit(f"unknown algorithm {algo}")
    with open(out, "w") as f:
        f.write("step,eval_mean,eval_std,eval_length\n")
        for step in range(5000, steps + 1, 5000):
            model.learn(5000, reset_num_timesteps=False)
            m, s, n = evaluate(model, eval_env)
            line = f"{step},{m:.4f},{s:.4f},{n:.1f}"
            print(line, flush=True)
            f.write(line + "\n")
            f.flush()


if __name__ == "__main__":
    main()
