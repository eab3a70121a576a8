"""Stable-Baselines3's gradient updates per second on a device (the GPU mode of the SB3
comparison, benches/gpu/check.sh): one CSV row per algorithm and width, on a dummy env of
HalfCheetah's sizes (17 observations, 6 actions), so that only the update is timed.

TD3 400-300 (lr 1e-3), SAC 256-256, sb3-contrib's CrossQ (critic width 256 / 1024 / 2048,
batch renormalisation, as sb3-contrib ships it), batch 256, one update after another; PPO: one
epoch (minibatches of 64) over a 2048-step rollout, 64-64 networks.
Usage: python sb3_updates.py DEVICE SECONDS [ALGO...]   (DEVICE cpu or cuda)
"""
import sys
import time

import gymnasium as gym
import numpy as np
import stable_baselines3
import torch
from stable_baselines3 import PPO, SAC, TD3

WARMUP = 1000


class Dummy(gym.Env):
    """Random observations, reward 0: the networks' sizes without a simulator."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (17,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (6,), np.float32)

    def __init__(self):
        self.rng = np.random.default_rng(0)
        self.t = 0

    def reset(self, seed=None, options=None):
        self.t = 0
        return self.rng.uniform(-1, 1, 17).astype(np.float32), {}

    def step(self, action):
        self.t += 1
        obs = self.rng.uniform(-1, 1, 17).astype(np.float32)
        return obs, float(self.rng.normal()), False, self.t >= 1000, {}


def off_policy(algo, width, device):
    common = dict(batch_size=256, learning_starts=WARMUP, train_freq=1, gradient_steps=1, device=device, seed=0, verbose=0)
    env = Dummy()
    if algo == "td3":
        return TD3("MlpPolicy", env, policy_kwargs=dict(net_arch=[400, 300]), learning_rate=1e-3, **common)
    if algo == "sac":
        return SAC("MlpPolicy", env, policy_kwargs=dict(net_arch=[256, 256]), **common)
    if algo == "crossq":
        from sb3_contrib import CrossQ

        return CrossQ("MlpPolicy", env, policy_kwargs=dict(net_arch=dict(pi=[256, 256], qf=[width, width])), **common)
    raise SystemExit(f"unknown algorithm {algo}")


def time_updates(model, seconds):
    model.learn(total_timesteps=WARMUP)  # fills the buffer; no update before learning_starts
    model.train(gradient_steps=20, batch_size=256)
    if model.device.type == "cuda":
        torch.cuda.synchronize()
    n, started = 0, time.perf_counter()
    while time.perf_counter() - started < seconds:
        model.train(gradient_steps=10, batch_size=256)
        n += 10
    if model.device.type == "cuda":
        torch.cuda.synchronize()
    return n, n / (time.perf_counter() - started)


def ppo_epoch(device, seconds):
    model = PPO("MlpPolicy", Dummy(), n_steps=2048, batch_size=64, n_epochs=1, device=device, seed=0, verbose=0)
    model.learn(total_timesteps=2048)  # one rollout and one epoch (warm-up)
    n, started = 0, time.perf_counter()
    while time.perf_counter() - started < seconds:
        model.train()
        n += 1
    return n, n / (time.perf_counter() - started)


def main():
    device, seconds = sys.argv[1], float(sys.argv[2])
    algos = sys.argv[3:] or ["td3", "sac", "crossq256", "crossq1024", "crossq2048", "ppo"]
    torch.set_num_threads(1)
    name = torch.cuda.get_device_name(0) if device == "cuda" else "cpu"
    print(f"# stable-baselines3 {stable_baselines3.__version__}, torch {torch.__version__}", flush=True)
    print("library,algo,device,gpu,hidden,critic_hidden,count,rate,unit", flush=True)
    for a in algos:
        if a == "ppo":
            n, rate = ppo_epoch(device, seconds)
            print(f"sb3,ppo,{device},{name},64-64,,{n},{rate:.2f},epochs_per_s", flush=True)
            continue
        width = int(a[len("crossq"):]) if a.startswith("crossq") else 0
        algo = "crossq" if width else a
        n, rate = time_updates(off_policy(algo, width, device), seconds)
        hidden = {"td3": "400-300", "sac": "256-256", "crossq": "256-256"}[algo]
        critic = f"{width}-{width}" if width else ""
        print(f"sb3,{algo},{device},{name},{hidden},{critic},{n},{rate:.2f},updates_per_s", flush=True)


if __name__ == "__main__":
    main()
