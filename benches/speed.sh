#!/usr/bin/env bash
# Runs the speed benchmarks (env steps, controller, agent updates) and the memory bench, and keeps
# their results as data beside a note on the machine: benches/results/<date>-<machine>/speed.csv
# and memory-bench.md. `locobench docs` quotes the newest speed.csv in docs/benchmarks.md.
#
#   bash benches/speed.sh [OUT_DIR]        (~10 min on 2 cores; best on an otherwise idle machine)
#   LOCOBENCH_BENCH_NOTE="..." adds a note on the conditions (e.g. what else ran) to the files.
set -euo pipefail
cd "$(dirname "$0")/.."
cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | xargs)
simd=$(grep -qw avx512f /proc/cpuinfo && echo avx512 || (grep -qw avx2 /proc/cpuinfo && echo avx2 || echo sse))
slug=$(echo "$cpu" | tr 'A-Z' 'a-z' | sed 's/([^)]*)//g; s/processor//; s/[^a-z0-9]\+/-/g; s/^-//; s/-$//')
out=${1:-benches/results/$(date +%F)-$slug-$simd}
mkdir -p "$out"
commit=$(git rev-parse --short=10 HEAD)$(git diff --quiet HEAD -- src benches Cargo.toml || echo "+dirty")
command="cargo bench --bench env_step --bench controller --bench agents"
rm -rf target/criterion
$command 2>/dev/null | grep -E "^[a-z_]+/|time:" || true
tmp=$(mktemp)
{
  echo "# machine: $cpu ($simd), $(nproc) cores; commit $commit; command: $command${LOCOBENCH_BENCH_NOTE:+; $LOCOBENCH_BENCH_NOTE}"
  echo "group,benchmark,mean_ns,low_ns,high_ns"
  for est in target/criterion/*/*/new/estimates.json; do
    dir=$(dirname "$(dirname "$est")")
    jq -r --slurpfile b "$dir/new/benchmark.json" \
      '[$b[0].group_id, $b[0].function_id, .mean.point_estimate, .mean.confidence_interval.lower_bound, .mean.confidence_interval.upper_bound] | @csv' "$est"
  done
} > "$tmp"
mv "$tmp" "$out/speed.csv"
{
  echo "\`cargo bench --bench memory\`, $cpu ($simd), commit $commit${LOCOBENCH_BENCH_NOTE:+ ($LOCOBENCH_BENCH_NOTE)}:"
  echo
  cargo bench --bench memory 2>/dev/null
} > "$out/memory-bench.md.tmp" && mv "$out/memory-bench.md.tmp" "$out/memory-bench.md"
echo "wrote $out/speed.csv and $out/memory-bench.md"
