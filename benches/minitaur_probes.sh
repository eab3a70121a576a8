#!/usr/bin/env bash
# The probes of the issue "every learner walks", item 1: SAC on Minitaur, seed 0, one change at a
# time from the preset, 100k steps each, one thread, then 50 held-out episodes (protocol seed 0).
# Usage: bash benches/minitaur_probes.sh OUT_DIR [STEPS]   (release binary at target/release)
set -euo pipefail
out=${1:?output directory}
steps=${2:-100000}
bin=${LOCOBENCH_BIN:-target/release/locobench}
mkdir -p "$out"
probe() {
    local name=$1; shift
    local dir=$out/$name
    if [ -f "$dir/held_out.txt" ]; then return; fi
    local start=$SECONDS
    if [ -f "$dir/config.toml" ]; then
        "$bin" train --resume "$dir" --steps "$steps" --quiet --threads 1
    else
        "$bin" train --env minitaur --algo sac --seed 0 --steps "$steps" --quiet --threads 1 \
            --out "$dir" "$@"
    fi
    echo "$((SECONDS - start))" > "$dir/wall_s.txt"
    "$bin" eval --policy "$dir" --episodes 50 --seed 0 > "$dir/held_out.tmp"
    mv "$dir/held_out.tmp" "$dir/held_out.txt"
}
probe base
probe norm --set normalize_observations=true
probe rs100 --set reward_scale=100
probe norm-rs100 --set normalize_observations=true,reward_scale=100
probe warmup1k --set warmup_steps=1000,learning_starts=1000
probe hidden512 --set "hidden=[512,512]"
probe utd2 --set updates_per_step=2
# The control frequency: 50 Hz instead of 100 (ten 2 ms physics steps per action, not five), the
# episode still 10 s. Reda et al. 2020 ("Learning to Locomote: Understanding How Environment
# Design Matters for Deep Reinforcement Learning") found it among the choices that decide
# whether a locomotion policy learns.
probe ctrl50hz --option action_repeat=10,max_episode_steps=500
