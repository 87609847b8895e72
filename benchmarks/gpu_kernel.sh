#!/usr/bin/env bash
# Compile Cycles' CUDA kernel for a GPU whose binary Blender does not ship (A100: 80, H100 and
# H200: 90), ahead of time and on any x86-64 machine, with ptxas from NVIDIA's PyPI wheel
# nvidia-cuda-nvcc-cu12. Without it the driver compiles Blender's PTX at the first render, on one
# core, for more than 5 minutes (benchmarks/RESULTS.md, GPU rendering); with it Cycles loads the
# binary as it loads the ones it ships. Put the output beside them, in bpy's
# <version>/scripts/addons_core/cycles/lib/ (gpu_device.sh does, given KERNEL=...).
#
#   bash benchmarks/gpu_kernel.sh SM OUT_DIR      # e.g. 90 /tmp/kernel -> kernel_sm_90.cubin.zst
#
# ptxas 12.9 (driver 575 or newer loads its binaries); about NN minutes on one core here.
set -euo pipefail
sm=${1:?usage: gpu_kernel.sh SM OUT_DIR} out=${2:?usage: gpu_kernel.sh SM OUT_DIR}
repo=$(cd "$(dirname "$0")/.." && pwd)
python=$repo/.venv/bin/python
lib=$("$python" -c 'import importlib.util as u, glob, os
root = os.path.dirname(u.find_spec("bpy").origin)
print(glob.glob(os.path.join(root, "[0-9]*.[0-9]*", "scripts", "addons_core", "cycles", "lib"))[0])')
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$python" -m pip download -q --no-deps "nvidia-cuda-nvcc-cu12==12.9.86" -d "$work"
(cd "$work" && unzip -q ./*.whl 'nvidia/cuda_nvcc/bin/ptxas')
chmod +x "$work/nvidia/cuda_nvcc/bin/ptxas"
zstd -d -q "$lib/kernel_compute_75.ptx.zst" -o "$work/kernel.ptx"
mkdir -p "$out"
started=$(date +%s)
"$work/nvidia/cuda_nvcc/bin/ptxas" -arch="sm_$sm" -O3 "$work/kernel.ptx" -o "$work/kernel_sm_$sm.cubin"
zstd -q -19 -f "$work/kernel_sm_$sm.cubin" -o "$out/kernel_sm_$sm.cubin.zst"
echo "$out/kernel_sm_$sm.cubin.zst: ptxas took $(( $(date +%s) - started )) s"
