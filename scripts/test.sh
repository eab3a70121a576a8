#!/usr/bin/env bash
# Installs what the tests need, then runs the whole test suite: formatting, cargo's tests, clippy
# with warnings as errors, the Python package's tests (python/test.sh: Gymnasium's env checker on
# every env, in a virtual environment under target/), the browser test (tests/browser/report.sh:
# the committed report in headless Chromium, its videos played to the end; as root it installs
# chromium), then the Slurm test (tests/slurm/cluster.sh: a real one-node Slurm on localhost)
# where it can be started, i.e. as root (it installs slurm-wlm and munge) or with Slurm's daemons
# already installed.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# No incremental caches: a one-off run does not reuse them, and they cost disk (CI ran out once).
export CARGO_INCREMENTAL=0
status=0
cargo fmt --all --check || status=$?
cargo test --locked --all-targets --no-fail-fast || status=$?
cargo clippy --locked --all-targets -- -D warnings || status=$?
cargo clippy --locked -p locobench-python -- -D warnings || status=$?
bash python/test.sh || status=$?
bash tests/browser/report.sh || status=1
if [ "$(id -u)" -eq 0 ] || { command -v slurmctld && command -v munged; } >/dev/null 2>&1; then
  bash tests/slurm/cluster.sh || status=1
else
  echo "slurm test: skipped (needs root to install and start slurm-wlm and munge)"
fi
exit "$status"
