#!/usr/bin/env bash
# Same binary, other CPUs: runs one release build natively and under qemu-user as an AVX2-only
# CPU (Haswell: AVX2 and FMA, no AVX-512) and a CPU without AVX or FMA (Nehalem), and prints a
# digest of what each computed:
#   physics     a 1000-step Ant rollout of random actions (MuJoCo alone)
#   controller  two Minitaur episodes of the Raibert/QP controller at 1.0 m/s
#   policy      three evaluation episodes of the shipped TD3 Minitaur policy
#   training    a 3000-step TD3 run on InvertedPendulum (weights, optimiser, metrics)
# once with the default kernels (auto: the widest exact path) and once with the gemm crate's
# (LOCOBENCH_KERNELS=library). Same digest in a column = same bits.
#
#   bash benches/cross_cpu.sh [OUT_DIR]     (installs qemu-user if missing; ~10 min on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/cross_cpu}
mkdir -p "$out"
if ! command -v qemu-x86_64 >/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get install -y -q qemu-user >/dev/null
fi
cargo build --release --locked -q
bin=$PWD/target/release/locobench

digest() { sha256sum "$@" | cut -c1-12; }

run_case() { # cpu kernels case
  local cpu=$1 kernels=$2 case=$3 dir="$out/$1-$2-$3"
  local runner=()
  [ "$cpu" != native ] && runner=(qemu-x86_64 -cpu "$cpu")
  rm -rf "$dir"; mkdir -p "$dir"
  export LOCOBENCH_KERNELS=$kernels
  case $case in
    physics)
      "${runner[@]}" "$bin" rollout --env ant --policy random --seed 3 --out "$dir/rollout.csv" >/dev/null
      digest "$dir/rollout.csv" ;;
    controller)
      "${runner[@]}" "$bin" baseline --env minitaur --speed 1.0 --episodes 2 --seed 0 >"$dir/out.txt"
      digest "$dir/out.txt" ;;
    policy)
      "${runner[@]}" "$bin" eval --checkpoint models/policies/minitaur-td3 --episodes 3 --seed 6000 \
        | sed 's/^[^ ]* //' >"$dir/out.txt"
      digest "$dir/out.txt" ;;
    training)
      "${runner[@]}" "$bin" train --env inverted-pendulum --algo td3 --seed 1 --steps 3000 --quiet \
        --set warmup_steps=500,learning_starts=500,eval_every=1000,eval_episodes=2,hidden=[64,64],batch_size=64 \
        --out "$dir/run" >/dev/null
      local ckpt; ckpt=$(ls -d "$dir"/run/checkpoints/step_* | sort -V | tail -1)
      cut -d, -f1-9 "$dir/run/metrics.csv" >"$dir/metrics-no-timing.csv"
      cat "$ckpt/model.safetensors" "$ckpt/optim.safetensors" "$dir/metrics-no-timing.csv" | digest ;;
  esac
}

cpus=(native Haswell Nehalem)
echo "host: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | xargs); commit $(git rev-parse --short HEAD)"
printf '| case | kernels | %s | %s | %s |\n|---|---|---|---|---|\n' "${cpus[@]}"
for case in physics controller policy training; do
  for kernels in auto library; do
    [ "$case" = physics ] && [ "$kernels" = library ] && continue
    [ "$case" = controller ] && [ "$kernels" = library ] && continue
    row="| $case | $kernels |"
    for cpu in "${cpus[@]}"; do row="$row $(run_case "$cpu" "$kernels" "$case" 2>&1 | tail -1) |"; done
    echo "$row"
  done
done
