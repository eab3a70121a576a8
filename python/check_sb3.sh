#!/usr/bin/env bash
# Optional check, not part of the test suite: Stable-Baselines3 with PyTorch (a download of a few
# GB) in target/sb3-check-venv, SB3's check_env on every env and a short SAC and PPO training on
# Minitaur.
#
#   bash python/check_sb3.sh [STEPS]     (default 3000 steps per algorithm)
set -euo pipefail
cd "$(dirname "$0")/.."
LOCOBENCH_PY_EXTRA="stable-baselines3==2.9.2" bash python/install.sh target/sb3-check-venv
OMP_NUM_THREADS=1 target/sb3-check-venv/bin/python python/check_sb3.py "${1:-3000}"
