#!/usr/bin/env bash
# Builds locobench with the `cuda` feature on a machine without a GPU or a system CUDA: the
# CUDA 13.0 compiler and libraries come from NVIDIA's PyPI wheels, installed under target/.
# Usage: scripts/build-cuda.sh [cargo build arguments...]   (default: --release --bin locobench)
# Output: target/cuda/release/locobench. Run it on a GPU machine as docs/gpu.md says.
#
# Pinned to 13.0.x: a newer nvcc writes PTX that driver 580 may refuse.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD/target/cuda-toolkit
compute_cap=${CUDA_COMPUTE_CAP:-90}

if [ ! -x "$root/venv/bin/python" ]; then
    python3 -m venv "$root/venv"
fi
if [ ! -f "$root/.installed" ]; then
    "$root/venv/bin/pip" install -q \
        nvidia-cuda-nvcc==13.0.88 nvidia-cuda-crt==13.0.88 nvidia-nvvm==13.0.88 \
        nvidia-cuda-cccl==13.0.85 nvidia-cuda-runtime==13.0.96 nvidia-cublas==13.0.2.14 \
        nvidia-curand==10.4.0.35 nvidia-cuda-nvrtc==13.0.88
    touch "$root/.installed"
fi

# A CUDA root as the build scripts expect one: bin/, include/, nvvm/ and lib64/ with
# unversioned links.
cu13=$(echo "$root"/venv/lib/python3*/site-packages/nvidia/cu13)
cuda=$root/root
rm -rf "$cuda"
mkdir -p "$cuda/lib64"
for d in bin include nvvm; do ln -s "$cu13/$d" "$cuda/$d"; done
for lib in "$cu13"/lib/lib*.so.*; do
    base=$(basename "$lib")
    ln -sf "$lib" "$cuda/lib64/$base"
    ln -sf "$lib" "$cuda/lib64/${base%%.so.*}.so"
done

# cudarc's dynamic linking passes -lcuda, and no wheel ships the driver's library: a link-time
# stub that defines every driver function cudarc declares, with the driver's soname, so the
# binary loads the real libcuda.so.1 at run time.
cudarc_sys=$(ls -d "${CARGO_HOME:-$HOME/.cargo}"/registry/src/*/cudarc-*/src/driver/sys 2>/dev/null | sort -V | tail -1)
if [ -z "$cudarc_sys" ]; then
    cargo fetch >/dev/null
    cudarc_sys=$(ls -d "${CARGO_HOME:-$HOME/.cargo}"/registry/src/*/cudarc-*/src/driver/sys | sort -V | tail -1)
fi
grep -rhoE 'pub (unsafe )?fn cu[A-Za-z0-9_]+' "$cudarc_sys" | sed -E 's/pub (unsafe )?fn //' | sort -u \
    | sed 's/.*/void &(void) {}/' >"$root/libcuda_stub.c"
cc -shared -fPIC -Wl,-soname,libcuda.so.1 -o "$cuda/lib64/libcuda.so" "$root/libcuda_stub.c"

export CUDA_ROOT=$cuda CUDA_PATH=$cuda CUDA_HOME=$cuda
export PATH=$cuda/bin:$PATH
export CUDA_COMPUTE_CAP=$compute_cap CUDARC_CUDA_VERSION=13000
export LIBRARY_PATH=$cuda/lib64${LIBRARY_PATH:+:$LIBRARY_PATH}
export LD_LIBRARY_PATH=$cuda/lib64${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
export CARGO_TARGET_DIR=$PWD/target/cuda
if [ $# -eq 0 ]; then set -- --release --bin locobench; fi
cargo build --features cuda "$@"
