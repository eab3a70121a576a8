"""Stable-Baselines3's SAC learning curve on Gymnasium's HalfCheetah-v5, for comparison with
locobench's SAC at equal steps: SAC v2 with SB3's defaults (256-256, Adam 3e-4, batch 256, tau
0.005, automatic temperature towards -dim(A), tanh correction log(1 - a^2 + 1e-6)), 10k uniformly
random steps first, then one update per step; every 5k steps 10 deterministic evaluation
episodes on a separate env. One torch thread.

Usage: python sac_halfcheetah_curve.py SEED [STEPS] > curve.csv   (prints step,eval_mean,eval_std)
"""
import sys

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback

SEED = int(sys.argv[1])
STEPS = int(sys.argv[2]) if len(sys.argv) > 2 else 100_000
EVERY, EPISODES = 5_000, 10
torch.set_num_threads(1)


class Evaluate(BaseCallback):
    def __init__(self):
        super().__init__()
        self.env = gym.make("HalfCheetah-v5")
        self.episode_seed = 10_000 + SEED

    def _on_step(self):
        if self.num_timesteps % EVERY == 0:
            returns = []
            for i in range(EPISODES):
                obs, _ = self.env.reset(seed=self.episode_seed + i)
                done, total = False, 0.0
                while not done:
                    action, _ = self.model.predict(obs, deterministic=True)
                    obs, reward, terminated, truncated, _ = self.env.step(action)
                    total += reward
                    done = terminated or truncated
                returns.append(total)
            print(f"{self.num_timesteps},{np.mean(returns)},{np.std(returns)}", flush=True)
        return True


env = gym.make("HalfCheetah-v5")
model = SAC(
    "MlpPolicy",
    env,
    policy_kwargs=dict(net_arch=[256, 256]),
    learning_rate=3e-4,
    batch_size=256,
    buffer_size=1_000_000,
    learning_starts=10_000,
    tau=0.005,
    gamma=0.99,
    train_freq=1,
    gradient_steps=1,
    device="cpu",
    seed=SEED,
    verbose=0,
)
print("step,eval_mean,eval_std", flush=True)
model.learn(total_timesteps=STEPS, callback=Evaluate())
