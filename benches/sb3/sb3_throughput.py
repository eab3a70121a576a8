"""Stable-Baselines3 side of the throughput comparison: one JSON line with gradient updates/s
(batch 256, one update after another) and environment steps/s while training (one update per
step, after 1000 warm-up steps) on HalfCheetah-v5, PyTorch on THREADS threads (default 1).

Same settings as locobench's side (benches/throughput.rs): TD3 and DDPG 400-300 with lr 1e-3
and Gaussian exploration noise 0.1, SAC 256-256 with lr 3e-4 and automatic temperature.
Usage: python sb3_throughput.py td3|sac|ddpg UPDATES STEPS [THREADS]
"""
import json
import sys
import time

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import DDPG, SAC, TD3
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.noise import NormalActionNoise

THREADS = int(sys.argv[4]) if len(sys.argv) > 4 else 1
torch.set_num_threads(THREADS)
WARMUP = 1000


def make(algo):
    env = gym.make("HalfCheetah-v5")
    n = env.action_space.shape[0]
    common = dict(batch_size=256, learning_starts=WARMUP, train_freq=1, gradient_steps=1, device="cpu", seed=0, verbose=0)
    noise = NormalActionNoise(np.zeros(n), 0.1 * np.ones(n))
    if algo == "td3":
        return TD3("MlpPolicy", env, policy_kwargs=dict(net_arch=[400, 300]), learning_rate=1e-3, action_noise=noise, **common)
    if algo == "ddpg":
        return DDPG("MlpPolicy", env, policy_kwargs=dict(net_arch=[400, 300]), learning_rate=1e-3, action_noise=noise, **common)
    if algo == "sac":
        return SAC("MlpPolicy", env, policy_kwargs=dict(net_arch=[256, 256]), learning_rate=3e-4, **common)
    raise SystemExit(f"unknown algorithm {algo}")


class WarmupClock(BaseCallback):
    """Notes the time when warm-up ends and when training ends."""

    def __init__(self):
        super().__init__()
        self.start = None

    def _on_step(self):
        if self.num_timesteps == WARMUP:
            self.start = time.perf_counter()
        return True


def main():
    algo, updates, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    model = make(algo)
    model.learn(total_timesteps=WARMUP)  # fills the buffer; no update before learning_starts
    model.train(gradient_steps=10, batch_size=256)
    started = time.perf_counter()
    model.train(gradient_steps=updates, batch_size=256)
    ups = updates / (time.perf_counter() - started)

    model = make(algo)
    clock = WarmupClock()
    model.learn(total_timesteps=WARMUP + steps, callback=clock)
    sps = steps / (time.perf_counter() - clock.start)
    print(json.dumps({"library": "sb3", "algo": algo, "threads": THREADS, "updates_per_s": round(ups, 2), "train_steps_per_s": round(sps, 2)}))


if __name__ == "__main__":
    main()
