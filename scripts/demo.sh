#!/usr/bin/env bash
# The main job: build locobench, list the environments, roll out each one, then train SAC on
# InvertedPendulum until it balances (about a minute on 2 cores), evaluate it, and run the
# Raibert/QP baseline on Minitaur.
# Everything it writes goes under demo/; it says where at the end.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo build --release --quiet
bin=target/release/locobench
out=demo
mkdir -p "$out"
"$bin" envs
for env in half-cheetah ant humanoid inverted-pendulum minitaur; do
  "$bin" rollout --env "$env" --policy random --episodes 2 --seed 0 --out "$out/rollout-$env.csv"
done
"$bin" rollout --env minitaur --policy zero --episodes 1 --seed 0 --out "$out/minitaur-standing.csv"
"$bin" train --env inverted-pendulum --algo sac --seed 0 --out "$out/run-inverted-pendulum-sac" --force
"$bin" eval --checkpoint "$out/run-inverted-pendulum-sac" --episodes 10
"$bin" baseline --env minitaur --speed 0.35,1.0 --episodes 3 --seed 0
echo
echo "Rollouts (one CSV row per step): $(pwd)/$out/rollout-*.csv"
echo "Training run (config.toml, metrics.csv, checkpoints/): $(pwd)/$out/run-inverted-pendulum-sac"
