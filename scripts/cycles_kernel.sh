#!/usr/bin/env bash
# Compile Cycles' CUDA kernel for a GPU whose binary Blender does not ship (A100: 80, H100 and
# H200: 90), once and ahead of time, on any x86-64 Linux machine (no GPU needed), with ptxas from
# NVIDIA's PyPI wheel nvidia-cuda-nvcc-cu12. Without it the NVIDIA driver compiles Blender's PTX
# at the first GPU render, on one core: more than 8 minutes on an H200 (benchmarks/RESULTS.md, GPU
# rendering). With it Cycles loads the binary as it loads the ones it ships: the first render on
# an H200 took 0.5 s.
#
#   bash scripts/cycles_kernel.sh SM            # e.g. 90: installs kernel_sm_90.cubin.zst into .venv's bpy
#   bash scripts/cycles_kernel.sh SM OUT_DIR    # writes it to OUT_DIR instead (copy it into bpy's
#                                               # <version>/scripts/addons_core/cycles/lib/ there)
#
# ptxas 12.9 (its binaries load on NVIDIA driver 575 or newer); 501 s on one core of the H200
# machine (ptxas 13.0 there). Needs zstd (Debian's zstd package).
set -euo pipefail
sm=${1:?usage: cycles_kernel.sh SM [OUT_DIR]}
repo=$(cd "$(dirname "$0")/.." && pwd)
python=$repo/.venv/bin/python
lib=$("$python" -c 'import importlib.util as u, glob, os
root = os.path.dirname(u.find_spec("bpy").origin)
print(glob.glob(os.path.join(root, "[0-9]*.[0-9]*", "scripts", "addons_core", "cycles", "lib"))[0])')
out=${2:-$lib}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$python" -m pip download -q --no-deps "nvidia-cuda-nvcc-cu12==12.9.86" -d "$work"
(cd "$work" && "$python" -m zipfile -e ./*.whl wheel)
ptxas=$work/wheel/nvidia/cuda_nvcc/bin/ptxas
chmod +x "$ptxas"
zstd -d -q "$lib/kernel_compute_75.ptx.zst" -o "$work/kernel.ptx"
mkdir -p "$out"
started=$(date +%s)
"$ptxas" -arch="sm_$sm" -O3 "$work/kernel.ptx" -o "$work/kernel_sm_$sm.cubin"
zstd -q -3 -f "$work/kernel_sm_$sm.cubin" -o "$out/kernel_sm_$sm.cubin.zst"
echo "$out/kernel_sm_$sm.cubin.zst: ptxas took $(( $(date +%s) - started )) s"
