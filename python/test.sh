#!/usr/bin/env bash
# The Python side of the test suite: builds the package (dev profile, sharing cargo test's
# compiled dependencies) into target/py-venv with Gymnasium, its MuJoCo envs (the reference the
# tests compare with), pytest, and Stable-Baselines3 with sb3-contrib (and the PyTorch they need,
# a download of a few GB): the SB3 conversion checks and refusals run, never skipped
# (LOCOBENCH_REQUIRE_SB3=1). Then runs python/tests.
set -euo pipefail
cd "$(dirname "$0")/.."
LOCOBENCH_PY_PROFILE=dev \
  LOCOBENCH_PY_EXTRA="gymnasium[mujoco]==1.4.0 pytest moviepy tensorboard stable-baselines3==2.9.2 sb3-contrib==2.9.0" \
  bash python/install.sh target/py-venv
# One thread for PyTorch: the tests' networks are small, and a second thread only contends.
LOCOBENCH_REQUIRE_SB3=1 OMP_NUM_THREADS=1 target/py-venv/bin/python -m pytest -q -p no:cacheprovider python/tests
