#!/usr/bin/env bash
# What exactness costs, measured in one run: GFLOP/s of every kernel path on the TD3 update's
# products, ns per element of the policy head's exp, ln and tanh, then TD3 / SAC / DDPG gradient
# updates per second (HalfCheetah sizes, batch 256) on one and two threads, on the default exact
# kernels (auto) and on the gemm crate's (library).
# Prints markdown with the machine and commit.
#
#   bash benches/kernels.sh [UPDATES]     (default 300 updates per figure; ~5 min on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
updates=${1:-300}
cargo bench --locked --bench throughput --no-run --quiet 2>/dev/null
echo "host: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | xargs), $(nproc) cores; commit $(git rev-parse --short HEAD)"
echo
echo "\`cargo bench --bench throughput -- --matmul\` (GFLOP/s, one thread):"
echo
cargo bench --locked --bench throughput --quiet -- --matmul 2>/dev/null
echo
echo "\`cargo bench --bench throughput -- --libm\` (ns per element, one thread; the same bits in every column):"
echo
cargo bench --locked --bench throughput --quiet -- --libm 2>/dev/null
echo
echo "\`LOCOBENCH_KERNELS=K cargo bench --bench throughput -- --bench --algo A --threads T --updates $updates --steps 0\` (updates/s):"
echo
echo "| algo | threads | auto | library | auto / library |"
echo "|---|---|---|---|---|"
for algo in td3 sac ddpg; do
  for threads in 1 2; do
    rate() {
      LOCOBENCH_KERNELS=$1 cargo bench --locked --bench throughput --quiet -- --bench --algo "$algo" \
        --threads "$threads" --updates "$updates" --steps 0 2>/dev/null \
        | sed -n 's/.*"kernels": "\([a-z0-9]*\)", "updates_per_s": \([0-9.]*\).*/\1 \2/p'
    }
    read -r path exact <<<"$(rate auto)"
    read -r _ library <<<"$(rate library)"
    echo "| $algo | $threads | $exact ($path) | $library | $(awk -v a="$exact" -v b="$library" 'BEGIN {printf "%.2f", a / b}') |"
  done
done
