#!/usr/bin/env bash
# Installs what the tests need, then runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# No incremental caches: a one-off run does not reuse them, and they cost disk (CI ran out once).
export CARGO_INCREMENTAL=0
cargo test --locked --all-targets --no-fail-fast
