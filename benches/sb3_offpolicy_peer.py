"""Stable-Baselines3's SAC or TD3 on locobench's Minitaur through Gymnasium, with
rl-baselines3-zoo's settings for PyBullet's Minitaur, evaluated under the protocol with
`locobench.evaluate`: an implementation independent of locobench's on the same env, to tell a
defect of ours from what the env asks of an off-policy learner.

Hyperparameters (DLR-RM/rl-baselines3-zoo, `hyperparams/sac.yml` and `hyperparams/td3.yml`,
entry `MinitaurBulletEnv-v0`):
- SAC: learning rate 3e-4, buffer 100k, batch 256, entropy coefficient 'auto', one gradient
  step per env step, 10k warm-up steps; SB3's defaults otherwise (256-256 networks, gamma 0.99,
  tau 0.005). No observation normalisation (the zoo's line is commented out).
- TD3: gamma 0.99, buffer 1M, Gaussian action noise 0.1, 10k warm-up steps, batch 100, learning
  rate 1e-3, 1000 gradient steps every 1000 env steps, 400-300 networks. The zoo also wraps the
  env in a TimeFeatureWrapper (the remaining time as an extra observation); it is left out here
  so that the policy takes the env's own observations and converts with `import_sb3`.

Writes into OUT: `progress.csv` (each training episode's end step, wall seconds and return, as
SB3's Monitor counts it), `model-<STEPS>.zip` at each budget of BUDGETS it reaches,
`held_out.json` (per budget, `locobench.evaluate` on the protocol's 50 held-out episodes, protocol
seed 0, deterministic actions), `external-<STEPS>/` (those episodes, for `locobench report
--external`) and `run.toml` (settings, versions, machine, wall and CPU time).

    OMP_NUM_THREADS=1 python benches/sb3_offpolicy_peer.py sac 0 300000 benches/results/minitaur/sb3-sac-seed0-300k
"""
import json
import os
import pathlib
import platform
import sys
import time

import numpy as np
import stable_baselines3
import torch
from stable_baselines3 import SAC, TD3
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.noise import NormalActionNoise

import locobench

ENV_ID = "locobench/Minitaur-v0"
# The budgets evaluated (LOCOBENCH_PEER_BUDGETS=N,M,... for a smoke test).
BUDGETS = tuple(int(b) for b in os.environ.get("LOCOBENCH_PEER_BUDGETS", "100000,300000,500000,1000000").split(","))

SETTINGS = {
    "sac": dict(learning_rate=3e-4, buffer_size=100_000, batch_size=256, ent_coef="auto", train_freq=1,
                gradient_steps=1, learning_starts=10_000),
    "td3": dict(gamma=0.99, buffer_size=1_000_000, learning_starts=10_000, batch_size=100, learning_rate=1e-3,
                train_freq=1000, gradient_steps=1000, policy_kwargs=dict(net_arch=[400, 300])),
}


class Progress(BaseCallback):
    """Each training episode's end (step, wall seconds, return), and the held-out evaluation of the
    policy at each budget it passes."""

    def __init__(self, out, seed, algo):
        super().__init__()
        self.out, self.seed, self.algo = out, seed, algo
        self.start = time.time()
        self.rows = []
        self.evaluations = {}

    def _on_step(self):
        for info in self.locals.get("infos", []):
            if "episode" in info:
                self.rows.append((self.num_timesteps, time.time() - self.start, float(info["episode"]["r"])))
        if self.num_timesteps in BUDGETS:
            self._evaluate(self.num_timesteps)
        return True

    def _evaluate(self, steps):
        path = self.out / f"model-{steps}.zip"
        self.model.save(path)
        result = locobench.evaluate(self.model, ENV_ID, episodes=50, seed=0, out=self.out / f"external-{steps}",
                                    label=f"sb3-{self.algo}", training_seed=self.seed, steps=steps,
                                    policy_file=path, library=("stable-baselines3", stable_baselines3.__version__))
        self.evaluations[steps] = {k: result[k] for k in ("return_mean", "falls", "episodes", "speed", "length")}
        self.evaluations[steps]["wall_s"] = time.time() - self.start
        print(f"{self.algo} seed {self.seed} at {steps}: held-out return {result['return_mean']}, "
              f"falls {result['falls']}/{result['episodes']}", flush=True)
        self.flush()

    def flush(self):
        with open(self.out / "progress.csv", "w") as f:
            f.write("step,wall_s,episode_return\n")
            f.writelines(f"{s},{w:.1f},{r:.6f}\n" for s, w, r in self.rows)
        (self.out / "held_out.json").write_text(json.dumps(self.evaluations, indent=1) + "\n")


def main():
    algo, seed, steps, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), pathlib.Path(sys.argv[4])
    if algo not in SETTINGS:
        sys.exit(f"benches/sb3_offpolicy_peer.py: algorithm {algo!r} is not one of {sorted(SETTINGS)}")
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    locobench.register_envs()
    env = make_vec_env(ENV_ID, n_envs=1, seed=seed)
    settings = dict(SETTINGS[algo])
    if algo == "td3":
        settings["action_noise"] = NormalActionNoise(np.zeros(8), 0.1 * np.ones(8))
        model = TD3("MlpPolicy", env, seed=seed, device="cpu", **settings)
    else:
        model = SAC("MlpPolicy", env, seed=seed, device="cpu", **settings)
    progress = Progress(out, seed, algo)
    cpu0 = time.process_time()
    model.learn(steps, callback=progress)
    progress.flush()
    shown = {k: (v if not isinstance(v, NormalActionNoise) else "normal 0.1") for k, v in settings.items()}
    (out / "run.toml").write_text("\n".join([
        f"# benches/sb3_offpolicy_peer.py {algo} {seed} {steps} {out}",
        f'env = "{ENV_ID}"', f"seed = {seed}", f"steps = {steps}", f'algorithm = "{algo}"',
        f'hyperparameters = "rl-baselines3-zoo hyperparams/{algo}.yml, MinitaurBulletEnv-v0 (no TimeFeatureWrapper)"',
        f'settings = "{shown}"', f'stable_baselines3 = "{stable_baselines3.__version__}"',
        f'torch = "{torch.__version__}"', f'python = "{platform.python_version()}"',
        f'cpu = "{platform.processor() or platform.machine()}"', "torch_threads = 1",
        f"wall_time_s = {time.time() - progress.start:.1f}", f"cpu_time_s = {time.process_time() - cpu0:.1f}",
    ]) + "\n")


if __name__ == "__main__":
    main()
