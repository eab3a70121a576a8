"""Regenerates tests/reference/minitaur-pybullet.csv: how PyBullet's own MinitaurBulletEnv
responds to constant leg-model actions (steps until it falls, capped at 300, and the base pose
then), with dynamics randomisation off. tests/minitaur.rs checks locobench's Minitaur against it.

    python3 -m venv /tmp/pyb && /tmp/pyb/bin/pip install pybullet "gym==0.26.2" "numpy<2"
    # pybullet_envs registers with gym's pre-0.26 registry API; point it at the new one:
    sed -i 's/registry.env_specs/registry/' /tmp/pyb/lib/python3.11/site-packages/pybullet_envs/__init__.py
    /tmp/pyb/bin/python tests/reference/make_pybullet_minitaur_reference.py \
        | sed -n '/^name,/,$p' > tests/reference/minitaur-pybullet.csv

Measured with pybullet 3.2.7 (PyPI wheel).
"""
import numpy as np
import pybullet
from pybullet_envs.bullet.minitaur_gym_env import MinitaurBulletEnv

# action[0..4] swing the legs (FL, BL, FR, BR), action[4..8] extend them.
ACTIONS = [
    ("zero", [0, 0, 0, 0, 0, 0, 0, 0]),
    ("swing all +1", [1, 1, 1, 1, 0, 0, 0, 0]),
    ("swing all -1", [-1, -1, -1, -1, 0, 0, 0, 0]),
    ("extend all +1", [0, 0, 0, 0, 1, 1, 1, 1]),
    ("extend all -1", [0, 0, 0, 0, -1, -1, -1, -1]),
    ("extend front +1", [0, 0, 0, 0, 1, 0, 1, 0]),
    ("extend back +1", [0, 0, 0, 0, 0, 1, 0, 1]),
    ("extend left +1", [0, 0, 0, 0, 1, 1, 0, 0]),
    ("extend right +1", [0, 0, 0, 0, 0, 0, 1, 1]),
    ("left -1 right +1", [0, 0, 0, 0, -1, -1, 1, 1]),
    ("swing front +1 back -1", [1, -1, 1, -1, 0, 0, 0, 0]),
    ("diagonal", [1, 1, -1, -1, 1, -1, -1, 1]),
]

env = MinitaurBulletEnv(render=False, env_randomizer=None)
print("name,action,steps,fell,height,up_z")
for name, action in ACTIONS:
    env.reset()
    steps, done = 0, False
    while not done and steps < 300:
        _, _, done, _ = env.step(np.array(action, dtype=float))
        steps += 1
    height = env.minitaur.GetBasePosition()[2]
    up_z = pybullet.getMatrixFromQuaternion(env.minitaur.GetBaseOrientation())[8]
    print(f"{name},{' '.join(str(a) for a in action)},{steps},{int(done)},{height:.4f},{up_z:.4f}")
