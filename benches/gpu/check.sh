#!/usr/bin/env bash
# The GPU check (docs/gpu.md), one command of at most 8 minutes on a machine with an NVIDIA GPU:
#   1. the device-generic path on CUDA against the fused CPU path (locobench device check);
#   2. update speed, locobench on the GPU beside Stable-Baselines3 on the same GPU in the same run
#      (TD3 400-300, SAC 256-256, CrossQ critics 256 / 1024 / 2048, a PPO epoch for SB3), and the
#      launch floor (CrossQ at width 8, batch 8);
#   3. same seed, same metrics on the GPU, and an exact resume;
#   4. CrossQ with 2048-wide critics on HalfCheetah for TRAIN_SECONDS (default 170).
# Usage, from the repository root:  bash benches/gpu/check.sh OUT_DIR
# Needs: a CUDA build (scripts/build-cuda.sh) at $LOCOBENCH (default target/cuda/release/locobench);
# CUDA 13's libcublas, libcurand and libnvrtc (found in PyTorch's wheels when not on the library
# path); MuJoCo's library (add its folder to LD_LIBRARY_PATH); for SB3, stable-baselines3 and
# sb3-contrib importable by python3.
set -uo pipefail
out=${1:?usage: check.sh OUT_DIR}
bin=${LOCOBENCH:-target/cuda/release/locobench}
train_seconds=${TRAIN_SECONDS:-170}
speed_seconds=${SPEED_SECONDS:-6}
# the device and CrossQ's critic width, other than cuda and 2048 only to try the script on a CPU
device=${DEVICE:-cuda}
width=${CRITIC_WIDTH:-2048}
mkdir -p "$out"
log() { echo "[$(date -u +%T)] $*"; }
if ! ldconfig -p | grep -q 'libcublas.so.13 '; then
    cu13=$(python3 -c 'import nvidia, os; print(os.path.join(list(nvidia.__path__)[0], "cu13", "lib"))' 2>/dev/null)
    export LD_LIBRARY_PATH=${cu13}${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
fi
export PYTHONUNBUFFERED=1

log "gpu"
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$out/gpu.csv"
"$bin" --version 2>/dev/null || true

log "1. generic path on cuda against the fused cpu path"
"$bin" device check --device "$device" | tee "$out/generic-check.csv" || { log "generic check failed"; exit 1; }

log "2. update speed"
speed() { "$bin" device speed --device "$device" --seconds "$speed_seconds" "$@"; }
{
    speed --algo td3 --hidden 400,300 --header
    speed --algo sac --hidden 256,256
    for w in 256 1024 2048; do speed --algo crossq --hidden 256,256 --critic-hidden $w,$w; done
    speed --algo crossq --hidden 8,8 --critic-hidden 8,8 --batch 8
} | tee "$out/locobench-updates.csv"
timeout 150 python3 benches/sb3/sb3_updates.py "${device%%:*}" "$speed_seconds" | tee "$out/sb3-updates.csv"

log "3. same seed, same metrics; exact resume"
det="--env half-cheetah --algo crossq --seed 0 --device $device --quiet --set critic_hidden=[$width,$width],learning_starts=2000,warmup_steps=2000,eval_every=1000,eval_episodes=2,checkpoint_every=1000"
"$bin" train $det --steps 4000 --out "$out/tmp-a" >/dev/null &&
    "$bin" train $det --steps 4000 --out "$out/tmp-b" >/dev/null &&
    "$bin" train $det --steps 3000 --out "$out/tmp-c" >/dev/null &&
    "$bin" train --resume "$out/tmp-c" --steps 4000 --device "$device" --quiet >/dev/null
# everything but the wall-clock columns
strip() { cut -d, -f1-9,12- "$1/metrics.csv"; }
{
    echo "what,identical_metrics_rows"
    cmp -s <(strip "$out/tmp-a") <(strip "$out/tmp-b") && echo "same seed twice,yes" || echo "same seed twice,no"
    cmp -s <(strip "$out/tmp-a") <(strip "$out/tmp-c") && echo "stopped at 3000 and resumed,yes" || echo "stopped at 3000 and resumed,no"
} | tee "$out/determinism.csv"
diff <(strip "$out/tmp-a") <(strip "$out/tmp-b") | head -5

log "4. crossq, critics $width-$width, half-cheetah, ${train_seconds} s"
run="$out/tmp-crossq$width"
timeout -s INT "$train_seconds" "$bin" train --env half-cheetah --algo crossq --seed 0 --device "$device" --quiet \
    --set "critic_hidden=[$width,$width]" --steps 1000000 --out "$run" >/dev/null
for f in metrics.csv config.toml provenance.csv; do cp "$run/$f" "$out/crossq$width-$f"; done
grep '^eval' "$out/crossq$width-metrics.csv" | cut -d, -f2,5,6,10,11
rm -rf "$out"/tmp-*
log "done"
