#!/usr/bin/env bash
# Builds mvpcc with the CUDA and wgpu backends (cargo features `cuda`, `wgpu`) on a machine
# without the CUDA toolkit and without internet beyond the package registries, and packs the
# stripped binary for carrying to a GPU machine.
#
#   scripts/build-cuda.sh [OUT_DIR]    build; OUT_DIR (default target/cuda-dist) gets the
#                                      stripped mvpcc packed as mvpcc.xz
#   scripts/build-cuda.sh --check      only `cargo check` every target with the features (CI)
#
# Why each step (docs/gpu.md):
# - cudarc loads the CUDA driver at run time, so no toolkit is needed to build. It must be told
#   which driver API to bind: CUDARC_CUDA_VERSION=13000 matches a CUDA 13.0 driver (580.x); with
#   newer bindings, calls the older driver lacks fail at run time with "Missing symbol".
# - cubecl-cuda compiles kernels through LLVM's NVPTX backend and links LLVM statically. The
#   crate that supplies it (tracel-llvm-bundler) downloads LLVM at build time unless it finds an
#   installed copy; the same LLVM 23 comes as the PyPI package mlc-llvm-static, which this script
#   installs into a venv under target/ and presents where the bundler looks
#   ($XDG_DATA_HOME/tracel/...), with the marker file the bundler writes after its own install.
# - The binary needs glibc >= 2.35 and GLIBCXX_3.4.30 where it runs (as built on Debian 12).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD/target/cuda-llvm
llvm_version=23.1.0-4
export CUDARC_CUDA_VERSION=${CUDARC_CUDA_VERSION:-13000}
export XDG_DATA_HOME=$root/share

installed=$XDG_DATA_HOME/tracel/tracel-llvm-$llvm_version/.tracel-llvm-installed
if [ ! -e "$installed" ]; then
    python3 -m venv "$root/venv"
    "$root/venv/bin/pip" install --quiet 'mlc-llvm-static[all]==23.1.1.post0'
    static=$(echo "$root"/venv/lib/python3*/site-packages/mlc_llvm_static/static)
    [ -d "$static/lib" ] || { echo "error: no LLVM static libraries in $static" >&2; exit 1; }
    mkdir -p "$XDG_DATA_HOME/tracel"
    ln -sfn "$static" "$XDG_DATA_HOME/tracel/tracel-llvm-$llvm_version"
    touch "$installed"
fi

if [ "${1:-}" = --check ]; then
    exec cargo check --locked --features cuda,wgpu --all-targets --target-dir target/cuda
fi
out=${1:-target/cuda-dist}
cargo build --release --locked --features cuda,wgpu --target-dir target/cuda
mkdir -p "$out"
stripped=target/cuda/mvpcc-stripped
strip -o "$stripped" target/cuda/release/mvpcc
xz -T0 -6 -c "$stripped" >"$out/mvpcc.xz"
ls -l "$stripped" "$out/mvpcc.xz"
