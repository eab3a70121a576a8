"""The optional Stable-Baselines3 check: SB3's own env checker on every locobench env, a short
SAC and PPO training on Minitaur and a look at the trained policy, then SB3's VecVideoRecorder on
a vector env from SB3's make_vec_env (which asks every env for render_mode="rgb_array"). Run by
python/check_sb3.sh."""
import pathlib
import sys
import tempfile
import time

import gymnasium as gym
import numpy as np
import stable_baselines3
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.env_checker import check_env

import locobench

steps = int(sys.argv[1]) if len(sys.argv) > 1 else 3000
print(f"stable-baselines3 {stable_baselines3.__version__}, gymnasium {gym.__version__}")
for env_id in sorted(locobench.ENV_IDS.values()):
    check_env(gym.make(env_id).unwrapped, warn=True)
    print(f"check_env {env_id}: passed")
for algo in (SAC, PPO):
    env = gym.make("locobench/Minitaur-v0")
    model = algo("MlpPolicy", env, seed=0, verbose=0, **({"learning_starts": 1000} if algo is SAC else {"n_steps": 1024}))
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    elapsed = time.perf_counter() - start
    obs, _ = env.reset(seed=1)
    total, length = 0.0, 0
    while True:
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, _ = env.step(action)
        total, length = total + reward, length + 1
        if terminated or truncated:
            break
    print(f"{algo.__name__} on locobench/Minitaur-v0: {steps} steps in {elapsed:.0f} s; one episode after: return {total:.3f}, {length} steps")

from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecVideoRecorder

with tempfile.TemporaryDirectory() as out:
    venv = make_vec_env("locobench/Minitaur-v0", n_envs=4, seed=0)
    recorder = VecVideoRecorder(venv, out, record_video_trigger=lambda step: step == 0, video_length=100,
                                name_prefix="minitaur")
    recorder.reset()
    for _ in range(120):
        recorder.step(np.stack([venv.action_space.sample() for _ in range(venv.num_envs)]))
    recorder.close()
    videos = sorted(pathlib.Path(out).glob("*.mp4"))
    assert videos and videos[0].stat().st_size > 10_000, videos
    print(f"VecVideoRecorder on make_vec_env('locobench/Minitaur-v0', n_envs=4): wrote {videos[0].name}, "
          f"{videos[0].stat().st_size} bytes")
