"""Checks locobench's MJCF models against Gymnasium's own under one MuJoCo version: same body
masses and inertias, and the same trajectory under the reference actions (max |qpos, qvel|
difference printed per model). Run with the venv of make_gymnasium_reference.py:

    /tmp/gymref/bin/python tests/reference/compare_models.py

Measured with mujoco 4.0.0, gymnasium 1.4.0: hopper 7e-15, walker2d 2e-13, half_cheetah 0 over 100 control
steps (4 physics steps each), with contacts.
"""
import math
import os

import gymnasium
import mujoco
import numpy as np

ASSETS = os.path.join(os.path.dirname(gymnasium.__file__), "envs", "mujoco", "assets")
HERE = os.path.dirname(os.path.abspath(__file__))
MODELS = {
    # locobench model: (Gymnasium's model file, physics steps per control step)
    "hopper.xml": ("hopper.xml", 4),
    "walker2d.xml": ("walker2d_v5.xml", 4),
    "half_cheetah.xml": ("half_cheetah.xml", 5),
}


def main():
    for ours, (theirs, frame_skip) in MODELS.items():
        models = [
            mujoco.MjModel.from_xml_path(os.path.join(ASSETS, theirs)),
            mujoco.MjModel.from_xml_path(os.path.join(HERE, "..", "..", "models", ours)),
        ]
        data = [mujoco.MjData(m) for m in models]
        assert np.allclose(models[0].body_mass, models[1].body_mass), ours
        assert np.allclose(models[0].body_inertia, models[1].body_inertia), ours
        worst = 0.0
        for t in range(100):
            action = [0.5 * math.sin((t * 7 + i * 3) * 0.37) for i in range(models[0].nu)]
            for m, d in zip(models, data):
                d.ctrl[:] = action
                for _ in range(frame_skip):
                    mujoco.mj_step(m, d)
            worst = max(worst, np.abs(data[0].qpos - data[1].qpos).max(), np.abs(data[0].qvel - data[1].qvel).max())
        print(f"{ours}: max difference {worst:.1e} over 100 steps (mujoco {mujoco.__version__})")


if __name__ == "__main__":
    main()
