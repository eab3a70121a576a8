#!/usr/bin/env bash
# The Python side of the test suite: builds the package (dev profile, sharing cargo test's
# compiled dependencies) into target/py-venv with Gymnasium, its MuJoCo envs (the reference the
# tests compare with) and pytest, then runs python/tests.
set -euo pipefail
cd "$(dirname "$0")/.."
LOCOBENCH_PY_PROFILE=dev LOCOBENCH_PY_EXTRA="gymnasium[mujoco]==1.4.0 pytest moviepy tensorboard" bash python/install.sh target/py-venv
target/py-venv/bin/python -m pytest -q -p no:cacheprovider python/tests
