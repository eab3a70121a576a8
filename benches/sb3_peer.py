"""A Stable-Baselines3 PPO peer run on a locobench env through Gymnasium, evaluated under the
protocol with `locobench.evaluate`.

Hyperparameters are rl-baselines3-zoo's (DLR-RM/rl-baselines3-zoo, hyperparams/ppo.yml):
`MinitaurBulletEnv-v0` for Minitaur and the tuned `HalfCheetah-v3` entry for HalfCheetah, each
with `normalize: true` (SB3's VecNormalize on observations and rewards). Writes into OUT:

- `model.zip` and `vecnormalize.pkl` (SB3's own files);
- `progress.csv`: per rollout, the environment steps, wall seconds and the mean return of the
  episodes that ended in it (SB3's Monitor, raw rewards);
- `held_out.json`: `locobench.evaluate` on the protocol's held-out episodes (50, protocol seed 0,
  deterministic actions through the VecNormalize observation statistics), with the controller at
  the policy's speed where the env has one;
- `external/`: those episodes with their provenance, for `locobench report --external`;
- `run.toml`: the hyperparameters, the library versions, the machine, the wall and CPU time of
  training.

`half-cheetah-cleanrl` trains SB3 with locobench's own PPO settings instead (CleanRL's), for
`benches/ppo_vs_sb3.py`'s like-for-like comparison.

Run with `OMP_NUM_THREADS=1` (one core per run), from a venv with stable-baselines3 and locobench
(`bash python/check_sb3.sh` makes target/sb3-check-venv):

    python benches/sb3_peer.py minitaur 0 1000000 benches/results/minitaur/sb3-ppo-seed0-1m

Where OUT already holds `model.zip` and `vecnormalize.pkl`, it only evaluates them again.
"""
import json
import os
import pathlib
import platform
import sys
import time

import gymnasium as gym
import numpy as np
import stable_baselines3
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

import locobench

ZOO = {
    "minitaur": dict(
        id="locobench/Minitaur-v0",
        n_envs=8,
        ppo=dict(n_steps=2048, batch_size=64, gae_lambda=0.95, gamma=0.99, n_epochs=10, ent_coef=0.0,
                 learning_rate=2.5e-4, clip_range=0.2),
        policy_kwargs={},
    ),
    "half-cheetah": dict(
        id="locobench/HalfCheetah-v5",
        n_envs=1,
        ppo=dict(batch_size=64, n_steps=512, gamma=0.98, learning_rate=2.0633e-05, ent_coef=0.000401762,
                 clip_range=0.1, n_epochs=20, gae_lambda=0.92, max_grad_norm=0.8, vf_coef=0.58096),
        policy_kwargs=dict(log_std_init=-2, ortho_init=False, activation_fn=torch.nn.ReLU,
                           net_arch=dict(pi=[256, 256], vf=[256, 256])),
    ),
    # The settings of locobench's own PPO runs (benches/results/half-cheetah/ppo-seed*-1m: CleanRL's
    # ppo_continuous_action.py), so that the two implementations meet with the same hyperparameters
    # and the same networks: 64-64 tanh, orthogonal init, 2048-step rollouts, 32 minibatches of 64,
    # 10 epochs, Adam 3e-4 (epsilon 1e-5) annealed linearly to 0, value clipping at 0.2,
    # gradient-norm limit 0.5, observations and rewards normalised and clipped at 10.
    "half-cheetah-cleanrl": dict(
        id="locobench/HalfCheetah-v5",
        n_envs=1,
        ppo=dict(n_steps=2048, batch_size=64, gae_lambda=0.95, gamma=0.99, n_epochs=10, ent_coef=0.0,
                 learning_rate="linear 3e-4", clip_range=0.2, clip_range_vf=0.2, vf_coef=0.5, max_grad_norm=0.5),
        policy_kwargs=dict(net_arch=dict(pi=[64, 64], vf=[64, 64]), optimizer_kwargs=dict(eps=1e-5)),
        source="locobench's PPO settings (CleanRL ppo_continuous_action.py)",
        label="sb3-ppo-cleanrl",
    ),
}


def ppo_kwargs(zoo):
    """SB3's PPO arguments; "linear X" is a learning rate annealed linearly from X to 0."""
    kwargs = dict(zoo["ppo"])
    lr = kwargs["learning_rate"]
    if isinstance(lr, str):
        start = float(lr.split()[1])
        kwargs["learning_rate"] = lambda remaining: start * remaining
    return kwargs


class Progress(BaseCallback):
    """Per rollout: steps, wall seconds, mean return of the episodes that ended in it."""

    def __init__(self, path, started):
        super().__init__()
        self.file = open(path, "w")
        self.file.write("step,wall_s,episodes,mean_return\n")
        self.started = started
        self.returns = []

    def _on_step(self):
        for info in self.locals["infos"]:
            if "episode" in info:
                self.returns.append(info["episode"]["r"])
        return True

    def _on_rollout_end(self):
        mean = float(np.mean(self.returns)) if self.returns else float("nan")
        self.file.write(f"{self.num_timesteps},{time.perf_counter() - self.started:.1f},{len(self.returns)},{mean:.4f}\n")
        self.file.flush()
        self.returns = []


def main():
    env_name, seed, steps, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), pathlib.Path(sys.argv[4])
    zoo = ZOO[env_name]
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    # No rendering while training (SB3 asks every env for render_mode="rgb_array" by default).
    venv = make_vec_env(zoo["id"], n_envs=zoo["n_envs"], seed=seed, env_kwargs={"render_mode": None})
    trained = (out / "model.zip").exists() and (out / "vecnormalize.pkl").exists()
    if trained:
        venv = VecNormalize.load(str(out / "vecnormalize.pkl"), venv)
        model = PPO.load(out / "model.zip", env=venv, device="cpu")
        wall = None
    else:
        # rl-baselines3-zoo's `normalize: true` gives VecNormalize the algorithm's discount factor
        # (rl_zoo3/exp_manager.py, "Use the same discount factor as for the algorithm").
        venv = VecNormalize(venv, gamma=zoo["ppo"]["gamma"])
        model = PPO("MlpPolicy", venv, seed=seed, verbose=0, device="cpu", policy_kwargs=zoo["policy_kwargs"],
                    **ppo_kwargs(zoo))
        started, cpu_started = time.perf_counter(), time.process_time()
        model.learn(total_timesteps=steps, callback=Progress(out / "progress.csv", started))
        wall, cpu_time = time.perf_counter() - started, time.process_time() - cpu_started
        model.save(out / "model.zip")
        venv.save(out / "vecnormalize.pkl")

    rms, clip, eps = venv.obs_rms, venv.clip_obs, venv.epsilon

    def act(obs):
        normalised = np.clip((obs - rms.mean) / np.sqrt(rms.var + eps), -clip, clip).astype(np.float32)
        action, _ = model.predict(normalised, deterministic=True)
        return action

    controller = zoo["id"] in ("locobench/Minitaur-v0", "locobench/Ant-v5")
    held_out = locobench.evaluate(act, zoo["id"], episodes=50, seed=0, controller=controller, out=out / "external",
                                  label=zoo.get("label", "sb3-ppo"), training_seed=seed, steps=steps, policy_file=out / "model.zip",
                                  library=("stable-baselines3", stable_baselines3.__version__))
    (out / "held_out.json").write_text(json.dumps(held_out, indent=1, default=float))
    if trained:
        print(f"{env_name} seed {seed}: evaluated the saved model again")
        return
    kwargs = {k: (v.__name__ if isinstance(v, type) else v) for k, v in zoo["policy_kwargs"].items()}
    lines = [
        "# A Stable-Baselines3 PPO peer run (benches/sb3_peer.py)",
        f'env = "{zoo["id"]}"',
        f"seed = {seed}",
        f"steps = {steps}",
        f"n_envs = {zoo['n_envs']}",
        'hyperparameters = "' + zoo.get("source", "rl-baselines3-zoo hyperparams/ppo.yml, " + ("MinitaurBulletEnv-v0" if env_name == "minitaur" else "HalfCheetah-v3")) + '; VecNormalize"',
        "ppo = {" + ", ".join(f"{k} = {json.dumps(v)}" for k, v in zoo["ppo"].items()) + "}",
        f'policy_kwargs = "{kwargs}"',
        f'stable_baselines3 = "{stable_baselines3.__version__}"',
        f'torch = "{torch.__version__}"',
        f'gymnasium = "{gym.__version__}"',
        f'python = "{platform.python_version()}"',
        f'cpu = "{cpu()}"',
        f"torch_threads = {torch.get_num_threads()}",
        f"wall_time_s = {wall:.1f}",
        f"cpu_time_s = {cpu_time:.1f}",
    ]
    (out / "run.toml").write_text("\n".join(lines) + "\n")
    print(f"{env_name} seed {seed}: {steps} steps in {wall:.0f} s; held-out return "
          f"{held_out['return_mean'][0]:.3f} [{held_out['return_mean'][1]:.3f}, {held_out['return_mean'][2]:.3f}], "
          f"falls {held_out['falls']}/{held_out['episodes']}, {held_out['speed']:.2f} m/s")


def cpu():
    for line in open("/proc/cpuinfo"):
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor()


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
