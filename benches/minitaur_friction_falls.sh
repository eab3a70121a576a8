#!/usr/bin/env bash
# Falls against foot friction: each contender plays the same held-out episodes (protocol seed
# $SEED, $EPISODES of them, PyBullet's randomised dynamics) with every foot's friction drawn as
# usual (U(0.8, 1.5), minitaur_env_randomizer.py) and then scaled by each of $SCALES
# (`--option friction_scale=S`). Writes CSV to stdout:
#   contender,budget,friction_scale,episodes,falls,mean_return,mean_speed
# Usage: LOCOBENCH=target/release/locobench bash benches/minitaur_friction_falls.sh > out.csv
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${LOCOBENCH:-target/release/locobench}
SEED=${SEED:-1}
EPISODES=${EPISODES:-100}
SCALES=${SCALES:-"0.7 1.0 1.3"}
CONTENDERS=${CONTENDERS:-"benches/results/minitaur/td3-combined-ln-best20-seed0@500000
benches/results/minitaur/td3-combined-ln-best20-seed1@500000
benches/results/minitaur/td3-combined-ln-best20-seed2@500000
benches/results/minitaur/crossq-combined-seed0@500000
benches/results/minitaur/crossq-combined-seed1@500000
benches/results/minitaur/crossq-combined-seed2@500000
controller@1.5"}
echo "contender,budget,friction_scale,episodes,falls,mean_return,mean_speed"
for c in $CONTENDERS; do
  path=${c%@*}; at=${c#*@}
  for s in $SCALES; do
    if [ "$path" = controller ]; then
      out=$("$bin" baseline --env minitaur --speed "$at" --episodes "$EPISODES" --seed "$SEED" --option "friction_scale=$s" 2>&1)
      # The sweep table's one row: speed, return ± std, achieved speed, ..., falls as k/n.
      row=$(printf '%s\n' "$out" | tail -1)
      ret=$(echo "$row" | awk '{print $2}')
      speed=$(echo "$row" | awk '{print $5}')
      falls=$(echo "$row" | awk '{for (i = 1; i <= NF; i++) if ($i ~ /^[0-9]+\/[0-9]+$/) {split($i, f, "/"); print f[1]}}')
    else
      out=$("$bin" eval --policy "$path" --budget "$at" --episodes "$EPISODES" --seed "$SEED" --option "friction_scale=$s" 2>&1)
      falls=$(printf '%s\n' "$out" | sed -n 's/^ *falls *\([0-9]*\)\/.*/\1/p' | head -1)
      ret=$(printf '%s\n' "$out" | sed -n 's/^ *return *mean *\([-0-9.]*\).*/\1/p' | head -1)
      speed=$(printf '%s\n' "$out" | sed -n 's/^ *speed *\([-0-9.]*\) m\/s.*/\1/p' | head -1)
    fi
    [ -n "$falls" ] && [ -n "$ret" ] || { echo "could not read the output for $c at friction_scale=$s:" >&2; printf '%s\n' "$out" >&2; exit 1; }
    echo "$path,$at,$s,$EPISODES,$falls,$ret,$speed"
  done
done
