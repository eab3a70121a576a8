#!/usr/bin/env bash
# Same binary, other CPUs: runs the digest bench (benches/digest.rs: an Ant episode of random
# actions, a Minitaur episode of the controller, two episodes of the shipped TD3 policy and a
# 3000-step TD3 run and one of SAC, each hashed bit for bit) natively and under qemu-user as an AVX2-only CPU
# (Haswell: AVX2 and FMA, no AVX-512) and as a CPU without AVX or FMA (Nehalem), once with the
# default kernels and once with the gemm crate's (LOCOBENCH_KERNELS=library). Prints a markdown
# table: the same digest along a row means the same bits on those CPUs.
#
#   bash benches/cross_cpu.sh            (installs qemu-user if missing; ~15 min on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v qemu-x86_64 >/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get install -y -q qemu-user >/dev/null
fi
bin=$(cargo bench --locked --bench digest --no-run --message-format=json 2>/dev/null \
  | sed -n 's/.*"executable":"\([^"]*digest[^"]*\)".*/\1/p' | tail -1)
[ -x "$bin" ] || { echo "cross_cpu: could not build the digest bench" >&2; exit 1; }
commit="$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- src benches Cargo.toml || echo ' (modified)')"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cpus=(native Haswell Nehalem)
for kernels in auto library; do
  for cpu in "${cpus[@]}"; do
    runner=()
    [ "$cpu" != native ] && runner=(qemu-x86_64 -cpu "$cpu")
    LOCOBENCH_KERNELS=$kernels "${runner[@]}" "$bin" --bench >"$out/$kernels-$cpu" &
  done
  wait
done
echo "host: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | xargs); built at commit $commit"
echo
printf '| case | LOCOBENCH_KERNELS |'; printf ' %s |' "${cpus[@]}"; echo
printf '|---|---|'; printf -- '---|%.0s' "${cpus[@]}"; echo
for kernels in auto library; do
  for case in kernels physics controller policy training training-sac; do
    printf '| %s | %s |' "$case" "$kernels"
    for cpu in "${cpus[@]}"; do printf ' %s |' "$(awk -v c="$case" '$1 == c {print $2}' "$out/$kernels-$cpu")"; done
    echo
  done
done
