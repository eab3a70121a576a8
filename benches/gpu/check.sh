#!/usr/bin/env bash
# The GPU check (docs/gpu.md), one command of at most 8 minutes on a machine with an NVIDIA GPU:
#   1. the device-generic path on CUDA against the fused CPU path, all six algorithms
#      (locobench device check);
#   2. update speed, locobench on the GPU beside Stable-Baselines3 on the same GPU in the same run
#      (TD3 400-300, SAC 256-256, CrossQ critics 256 / 1024 / 2048, a PPO epoch), and the launch
#      floor (CrossQ at width 8, batch 8); with BASELINE_LOCOBENCH set, the CrossQ rows again
#      from that (earlier) build, so that a change to the path is timed against what it replaced;
#   3. same seed, same metrics on the GPU, and an exact resume (CrossQ and PPO);
#   4. a shipped policy evaluated with its networks on the GPU and on the CPU;
#   5. CrossQ with 2048-wide critics on HalfCheetah until DEADLINE (seconds since the epoch; by
#      default 8 minutes after the start) less a margin.
# Usage, from the repository root:  bash benches/gpu/check.sh OUT_DIR
# Needs: a CUDA build (scripts/build-cuda.sh) at $LOCOBENCH (default target/cuda/release/locobench);
# CUDA 13's libcublas, libcurand and libnvrtc (found in PyTorch's wheels when not on the library
# path); MuJoCo's library (add its folder to LD_LIBRARY_PATH); for SB3, stable-baselines3 and
# sb3-contrib importable by python3.
set -uo pipefail
out=${1:?usage: check.sh OUT_DIR}
bin=${LOCOBENCH:-target/cuda/release/locobench}
deadline=${DEADLINE:-$(($(date +%s) + 480))}
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
if ! ldconfig -p | grep -q 'libcuda.so.1 '; then
    driver=$(find /usr/local/nvidia /usr/lib /usr/lib64 -name 'libcuda.so.1' 2>/dev/null | head -1)
    [ -n "$driver" ] && export LD_LIBRARY_PATH=$(dirname "$driver")${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
fi
export PYTHONUNBUFFERED=1

log "gpu"
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv
"$bin" --version || { log "the binary does not start"; exit 1; }

log "1. generic path on $device against the fused cpu path"
"$bin" device check --device "$device" | tee "$out/generic-check.csv" || log "generic check: a gap over its tolerance, or an error"

log "2. update speed"
speed() { "$bin" device speed --device "$device" --seconds "$speed_seconds" "$@"; }
{
    speed --algo td3 --hidden 400,300 --header
    speed --algo sac --hidden 256,256
    for w in 256 1024 2048; do speed --algo crossq --hidden 256,256 --critic-hidden $w,$w; done
    speed --algo crossq --hidden 8,8 --critic-hidden 8,8 --batch 8
    speed --algo ppo --hidden 64,64 --batch 64
} | tee "$out/locobench-updates.csv"
if [ -n "${BASELINE_LOCOBENCH:-}" ]; then
    log "2b. the same CrossQ rows from the baseline build $BASELINE_LOCOBENCH"
    {
        echo "# the baseline build: $("$BASELINE_LOCOBENCH" --version 2>&1 | head -1)"
        first=--header
        for w in 256 2048; do
            "$BASELINE_LOCOBENCH" device speed --device "$device" --seconds "$speed_seconds" --algo crossq --hidden 256,256 \
                --critic-hidden $w,$w $first
            first=
        done
        "$BASELINE_LOCOBENCH" device speed --device "$device" --seconds "$speed_seconds" --algo crossq --hidden 8,8 \
            --critic-hidden 8,8 --batch 8
    } | tee "$out/baseline-updates.csv"
fi
timeout 150 python3 benches/sb3/sb3_updates.py "${device%%:*}" "$speed_seconds" | tee "$out/sb3-updates.csv"

log "3. same seed, same metrics; exact resume"
# 250-step episodes, so that checkpoints (every 250 steps) end episodes and a resume is exact
det="--env half-cheetah --algo crossq --seed 0 --device $device --quiet --option max_episode_steps=250
     --set critic_hidden=[$width,$width],learning_starts=1000,warmup_steps=1000,eval_every=250,eval_episodes=2,checkpoint_every=250"
"$bin" train $det --steps 1500 --out "$out/tmp-a" >/dev/null &&
    "$bin" train $det --steps 1500 --out "$out/tmp-b" >/dev/null &&
    "$bin" train $det --steps 1250 --out "$out/tmp-c" >/dev/null &&
    "$bin" train --resume "$out/tmp-c" --steps 1500 --device "$device" --quiet >/dev/null
# everything but the wall-clock columns
strip() { cut -d, -f1-9,12- "$1/metrics.csv"; }
{
    echo "what,identical_metrics_rows"
    cmp -s <(strip "$out/tmp-a") <(strip "$out/tmp-b") && echo "same seed twice,yes" || echo "same seed twice,no"
    cmp -s <(strip "$out/tmp-a") <(strip "$out/tmp-c") && echo "stopped at 1250 and resumed,yes" || echo "stopped at 1250 and resumed,no"
} | tee "$out/determinism.csv"
diff <(strip "$out/tmp-a") <(strip "$out/tmp-b") | head -5
# PPO: Hopper, three copies, rollouts of 300 steps, checkpoints every 600 (rollout boundaries);
# no learning-rate annealing, so that the shorter first stretch anneals as the whole run does
ppo="--env hopper --algo ppo --seed 0 --device $device --quiet
     --set num_envs=3,num_steps=100,num_minibatches=4,update_epochs=2,anneal_lr=false,eval_every=600,eval_episodes=2,checkpoint_every=600"
"$bin" train $ppo --steps 2400 --out "$out/tmp-pa" >/dev/null &&
    "$bin" train $ppo --steps 2400 --out "$out/tmp-pb" >/dev/null &&
    "$bin" train $ppo --steps 1200 --out "$out/tmp-pc" >/dev/null &&
    "$bin" train --resume "$out/tmp-pc" --steps 2400 --device "$device" --quiet >/dev/null
{
    cmp -s <(strip "$out/tmp-pa") <(strip "$out/tmp-pb") && echo "ppo: same seed twice,yes" || echo "ppo: same seed twice,no"
    cmp -s <(strip "$out/tmp-pa") <(strip "$out/tmp-pc") && echo "ppo: stopped at 1200 and resumed,yes" || echo "ppo: stopped at 1200 and resumed,no"
} | tee -a "$out/determinism.csv"

log "4. shipped policies, their networks on $device and on the cpu"
for p in minitaur-ppo minitaur-td3; do
    for d in cpu "$device"; do
        "$bin" eval --policy models/policies/$p --episodes 10 --device "$d" 2>&1 | sed "s/^/$d: /"
    done
done | tee "$out/eval-devices.txt"

train_seconds=$((deadline - $(date +%s) - 30))
[ "$train_seconds" -lt 30 ] && train_seconds=30
log "5. crossq, critics $width-$width, half-cheetah, ${train_seconds} s"
run="$out/tmp-crossq$width"
timeout -k 40 -s INT "$train_seconds" "$bin" train --env half-cheetah --algo crossq --seed 0 --device "$device" --quiet \
    --set "critic_hidden=[$width,$width]" --steps 1000000 --out "$run" >/dev/null
for f in metrics.csv config.toml provenance.csv; do cp "$run/$f" "$out/crossq$width-$f"; done
grep '^eval' "$out/crossq$width-metrics.csv" | cut -d, -f2,5,6,10,11
rm -rf "$out"/tmp-*
log "done"
