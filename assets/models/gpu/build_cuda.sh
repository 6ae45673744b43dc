#!/usr/bin/env bash
# Builds `tnd --features cuda` on a machine without a GPU or a CUDA install, from NVIDIA's PyPI wheels, to carry to a
# GPU machine (which has the driver and CUDA PyTorch but no Rust toolchain).
#
# Usage (repository root):  bash assets/models/gpu/build_cuda.sh [DEST]     DEST defaults to .dev
# Writes DEST/tnd-cuda.xz (stripped, xz-compressed: 67 MB -> 18 MB, under the device's 64 MiB carry) and
# DEST/cuda-lib/libcudart.so.13; the toolkit (~350 MB) stays in the target directory (cuda-toolkit/).
#
# What the build needs, and from where (all CUDA 13.4, pinned below):
#   nvidia-cuda-nvcc   nvcc, cudafe++, ptxas, fatbinary, nvlink       nvidia-nvvm       cicc, libdevice
#   nvidia-cuda-crt    crt/ headers                                    nvidia-cuda-cccl  libcu++/CUB/Thrust headers
#   nvidia-cuda-runtime  cuda_runtime.h, cuda_fp16.h, ..., libcudart.so.13 (candle-kernels links it)
# cuBLAS, cuRAND and NVRTC are not linked: candle's cudarc loads them and the driver (libcuda.so.1) when a CUDA device
# is opened (`dynamic-loading`, vendor/candle-core/PATCHED.md), so the GPU machine must provide CUDA 13 builds of
# them on LD_LIBRARY_PATH (e.g. PyTorch's cu13 wheels: site-packages/nvidia/cu13/lib) and a driver that runs CUDA 13.4
# PTX (R580 or newer). CUDA 13.4 is the newest cudarc 0.19 knows (`cuda-version-from-build-system` reads nvcc).
# Kernels: PTX for compute capability $CUDA_COMPUTE_CAP (default 90: H100/H200), JIT-compiled by the driver.
set -euo pipefail
cd "$(dirname "$0")/../../.."
dest="${1:-.dev}"
cuda_version=13.4.92
cccl_version=13.3.5.0.6
python="${PYTHON:-python3}"

target_dir="$(cargo metadata --format-version 1 --no-deps | "$python" -c "import json, sys; print(json.load(sys.stdin)['target_directory'])")"
toolkit="$target_dir/cuda-toolkit"
root="$toolkit/nvidia/cu13"
if [ ! -x "$root/bin/nvcc" ] || [ ! -x "$root/nvvm/bin/cicc" ]; then
    wheels="$target_dir/cuda-wheels"
    mkdir -p "$wheels"
    "$python" -m pip download --quiet --disable-pip-version-check --no-deps -d "$wheels" \
        "nvidia-cuda-nvcc==$cuda_version" "nvidia-nvvm==$cuda_version" "nvidia-cuda-crt==$cuda_version" \
        "nvidia-cuda-runtime==$cuda_version" "nvidia-cuda-cccl==$cccl_version"
    rm -rf "$toolkit.partial"
    mkdir -p "$toolkit.partial"
    for wheel in "$wheels"/*.whl; do
        "$python" -m zipfile -e "$wheel" "$toolkit.partial/"
    done
    # Wheels are zip files: the executables lose their mode bits.
    chmod +x "$toolkit.partial/nvidia/cu13/bin/"* "$toolkit.partial/nvidia/cu13/nvvm/bin/"*
    ln -sf libcudart.so.13 "$toolkit.partial/nvidia/cu13/lib/libcudart.so"
    rm -rf "$toolkit"
    mv "$toolkit.partial" "$toolkit"
fi
root="$(cd "$root" && pwd)"
echo "build_cuda: $("$root/bin/nvcc" --version | tail -n 2 | head -n 1)"

export CUDA_HOME="$root" CUDA_PATH="$root" CUDA_ROOT="$root" PATH="$root/bin:$PATH" LIBRARY_PATH="$root/lib"
export CUDA_COMPUTE_CAP="${CUDA_COMPUTE_CAP:-90}"
cargo build --release --bin tnd --features cuda
mkdir -p "$dest/cuda-lib"
cp "$target_dir/release/tnd" "$target_dir/tnd-cuda"
strip "$target_dir/tnd-cuda"
xz -T0 -6 -c "$target_dir/tnd-cuda" > "$dest/tnd-cuda.xz.partial"
mv "$dest/tnd-cuda.xz.partial" "$dest/tnd-cuda.xz"
cp "$root/lib/libcudart.so.13" "$dest/cuda-lib/"
echo "build_cuda: wrote $dest/tnd-cuda.xz ($(du -h "$dest/tnd-cuda.xz" | cut -f1)) and $dest/cuda-lib/libcudart.so.13"
echo "build_cuda: on the GPU machine: assets/models/gpu/cuda_check.sh TND_CPU $dest/tnd-cuda.xz OUT"
