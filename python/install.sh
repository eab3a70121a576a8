#!/usr/bin/env bash
# Builds the locobench Python package (release) and installs it into a virtual environment,
# creating it if needed, with Gymnasium and NumPy. On a fresh Debian 12 machine, as root or with
# sudo; needs a Rust toolchain.
#
#   bash python/install.sh [VENV]        (default .venv; then: source VENV/bin/activate)
#
# VENV may be absolute or relative to the directory the script is called from; the default is
# .venv in the checkout.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
venv=${1:-$root/.venv}
case "$venv" in
  /*) ;;
  *) venv="$PWD/$venv" ;;
esac
cd "$root"
profile=${LOCOBENCH_PY_PROFILE:-release}
bash scripts/setup.sh
if ! python3 -m venv --help >/dev/null 2>&1 || ! python3 -c "import ensurepip" >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get install -y -q python3-venv
fi
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/pip" install -q --upgrade "maturin>=1.5,<2" "gymnasium>=1.0" numpy ${LOCOBENCH_PY_EXTRA:-}
# dev builds share their compiled dependencies with `cargo test` (same target directory and
# settings), which keeps the test command's clock short.
if [ "$profile" = release ]; then flag=--release; else flag=; fi
VIRTUAL_ENV="$venv" PATH="$venv/bin:$PATH" CARGO_INCREMENTAL=0 \
  "$venv/bin/maturin" develop -q $flag -m python/Cargo.toml
"$venv/bin/python" -c "import locobench; print('locobench', 'installed into $venv:', ', '.join(locobench.ENV_IDS.values()))"
