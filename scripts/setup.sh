#!/usr/bin/env bash
# Installs the Debian packages locobench needs to build and run. Safe to run again.
set -euo pipefail
# Rendering (src/render/): Mesa's OSMesa and EGL for an OpenGL context without a display, and
# ffmpeg to encode MP4 and WebM videos.
packages=(libmujoco-dev libclang-dev pkg-config libosmesa6 libegl1 libegl-mesa0 ffmpeg)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q "${missing[@]}"
fi
command -v cargo >/dev/null || { echo "setup: cargo not found; install Rust (rustup) first" >&2; exit 1; }
