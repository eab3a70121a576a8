#!/usr/bin/env bash
# The main job: build locobench, list the environments and roll out each one.
# Writes its outputs under demo/ and says where they are.
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
echo
echo "Rollouts (one CSV row per step) are in $(pwd)/$out/"
