#!/usr/bin/env bash
# Throughput of locobench against Stable-Baselines3 on the same machine, alternating in one run:
# gradient updates/s and training env-steps/s for TD3 (400-300), SAC (256-256) and DDPG (400-300)
# at batch 256 on HalfCheetah, each library on one thread. Prints every measurement and the
# ratios locobench/SB3 (median over rounds).
#
#   bash benches/sb3/compare.sh [ROUNDS] [UPDATES] [STEPS]     (defaults 3 300 1000)
#
# Installs Stable-Baselines3 2.9.2 + Gymnasium (MuJoCo) into target/sb3-venv when missing.
# PyTorch from PyPI brings its CUDA libraries (a few GB download) though only the CPU is used.
set -euo pipefail
cd "$(dirname "$0")/../.."
rounds=${1:-3}
updates=${2:-300}
steps=${3:-1000}
venv=target/sb3-venv
if [ ! -x "$venv/bin/python" ] || ! "$venv/bin/python" -c "import stable_baselines3, gymnasium, mujoco" 2>/dev/null; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q "stable-baselines3==2.9.2" "gymnasium[mujoco]"
fi
bash scripts/setup.sh
cargo bench --bench throughput --no-run --quiet 2>/dev/null
export RAYON_NUM_THREADS=1 CANDLE_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
results=$(mktemp)
echo "machine: $(nproc --all) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs); $(date -u +%Y-%m-%d)"
"$venv/bin/python" -c "import torch, stable_baselines3, mujoco; print(f'torch {torch.__version__}, sb3 {stable_baselines3.__version__}, mujoco (python) {mujoco.__version__}')"
for round in $(seq "$rounds"); do
  for algo in td3 sac ddpg; do
    cargo bench --quiet --bench throughput -- --algo "$algo" --updates "$updates" --steps "$steps" | tee -a "$results"
    "$venv/bin/python" benches/sb3/sb3_throughput.py "$algo" "$updates" "$steps" | tee -a "$results"
  done
done
python3 - "$results" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.startswith("{")]
print("\nmedian over rounds       locobench      SB3   ratio")
for algo in ["td3", "sac", "ddpg"]:
    for key, label in [("updates_per_s", "updates/s"), ("train_steps_per_s", "train steps/s")]:
        ours = statistics.median(r[key] for r in rows if r["library"] == "locobench" and r["algo"] == algo)
        theirs = statistics.median(r[key] for r in rows if r["library"] == "sb3" and r["algo"] == algo)
        print(f"{algo:<5} {label:<18} {ours:>9.1f} {theirs:>8.1f} {ours / theirs:>7.2f}")
PY
rm -f "$results"
