#!/usr/bin/env bash
# Throughput of locobench against Stable-Baselines3 on the same machine, alternating in one run:
# gradient updates/s and training env-steps/s for TD3 (400-300), SAC (256-256) and DDPG (400-300)
# at batch 256 on HalfCheetah. Each library runs on one thread and on two (locobench
# `--threads 2`, PyTorch `torch.set_num_threads(2)`). Prints every measurement and the ratios
# locobench/SB3 (median over rounds): the issue's comparison is SB3 on one torch thread; the
# two-thread columns show what each library gets from the second core.
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
    for threads in 1 2; do
      cargo bench --quiet --bench throughput -- --algo "$algo" --updates "$updates" --steps "$steps" --threads "$threads" | tee -a "$results"
      OMP_NUM_THREADS=$threads MKL_NUM_THREADS=$threads \
        "$venv/bin/python" benches/sb3/sb3_throughput.py "$algo" "$updates" "$steps" "$threads" | tee -a "$results"
    done
  done
done
python3 - "$results" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.startswith("{")]
def med(library, algo, threads, key):
    return statistics.median(
        r[key] for r in rows if r["library"] == library and r["algo"] == algo and r.get("threads", 1) == threads
    )
print("\nmedian over rounds; L = locobench, S = SB3; 1t/2t = threads")
print(f"{'':24} {'L 1t':>7} {'L 2t':>7} {'S 1t':>7} {'S 2t':>7}  {'L1t/S1t':>7} {'L2t/S1t':>7} {'L2t/S2t':>7}")
for algo in ["td3", "sac", "ddpg"]:
    for key, label in [("updates_per_s", "updates/s"), ("train_steps_per_s", "train steps/s")]:
        l1, l2, s1, s2 = (med(lib, algo, t, key) for lib, t in [("locobench", 1), ("locobench", 2), ("sb3", 1), ("sb3", 2)])
        print(f"{algo:<5} {label:<18} {l1:>7.1f} {l2:>7.1f} {s1:>7.1f} {s2:>7.1f}  {l1 / s1:>7.2f} {l2 / s1:>7.2f} {l2 / s2:>7.2f}")
PY
rm -f "$results"
