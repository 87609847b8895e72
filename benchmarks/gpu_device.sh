#!/usr/bin/env bash
# On the GPU machine, in a checkout of this repository: unpack a bundle made by gpu_bundle.sh,
# print what sweep3d's probe finds, time benchmarks/bare_loop.py over the bundle's jobs once per
# RUN, and print gpu.py's table (set-up, first render, renders/s after it, pixels against the CPU).
#
#   BUNDLE=DIR_WITH_bundle.tar.xz* RESULTS=DIR bash benchmarks/gpu_device.sh [RUN ...]
#
# RUN is DEVICE-N: cpu-1 cuda-1 optix-1 cuda-2 optix-2 by default, in that order (the first GPU
# run of a process pays any kernel compile: see benchmarks/RESULTS.md, GPU rendering). Each run
# may take CAP seconds (300), all of them LIMIT seconds (520). WORK: where to unpack (/tmp/gpu).
# KERNEL: a Cycles CUDA binary for this GPU (kernel_sm_XY.cubin.zst, from scripts/cycles_kernel.sh) put beside
# Blender's own, so that no render waits for the driver to compile Cycles' PTX.
# INFER: a folder with efficientnet_lite_pytorch, Lite0's .pth and lite0.onnx (bare_infer.py
# --export): after the renders, bare_infer.py classifies cuda-1's (else cpu-1's) frames blurred at
# σ = 0, 1, 2, 3 with torch on CUDA and on the CPU, and with ONNX Runtime on the CPU (infer.jsonl).
set -u
export PYTHONUNBUFFERED=1
started=$(date +%s)
repo=$(cd "$(dirname "$0")/.." && pwd)
work=${WORK:-/tmp/gpu} results=${RESULTS:?RESULTS: a folder for the table and logs}
mkdir -p "$work/frames" "$results"
cat "${BUNDLE:?BUNDLE: the folder holding bundle.tar.xz or its parts}"/bundle.tar.xz* | xz -d -T0 | tar -C "$work" -xf - \
  || exit 1
echo "unpacked in $(( $(date +%s) - started )) s"
if [ -n "${KERNEL:-}" ]; then
  cp "$KERNEL" "$(ls -d "$work"/site/bpy/[0-9]*.[0-9]*)/scripts/addons_core/cycles/lib/" && echo "kernel: $(basename "$KERNEL")"
fi
export LD_LIBRARY_PATH=$work/py/lib:$work/libs PYTHONPATH=$work/site PYTHONNOUSERSITE=1
export CUDA_CACHE_PATH=${CUDA_CACHE_PATH:-$work/nvcache} CUDA_CACHE_MAXSIZE=${CUDA_CACHE_MAXSIZE:-4294967296}
python=$work/py/bin/python3.11
command -v nvidia-smi >/dev/null && nvidia-smi -L
timeout 120 "$python" "$repo/sweep3d/stages/render/cycles/gpus.py" 2>&1 | tail -1 | tee "$results/probe.txt"
[ $# -gt 0 ] || set -- cpu-1 cuda-1 optix-1 cuda-2 optix-2
for run in "$@"; do
  left=$(( ${LIMIT:-520} - ($(date +%s) - started) ))
  [ "$left" -lt 20 ] && { echo "no time left for $run"; break; }
  cap=${CAP:-300}; [ "$left" -lt "$cap" ] && cap=$left
  echo "== $run (at most $cap s)"
  timeout "$cap" "$python" "$repo/benchmarks/bare_loop.py" "$work/jobs/jobs.json" "$work/frames/$run" \
    --device "${run%-*}" > "$work/frames/$run.json" 2> "$results/$run.err"
  echo "exit $?"
  tail -1 "$work/frames/$run.json"
  grep -q '"loop"' "$work/frames/$run.json" || rm -f "$work/frames/$run.json"  # stopped: no timing line
  env -u PYTHONPATH -u LD_LIBRARY_PATH python3 "$repo/benchmarks/gpu.py" report "$work/frames" > "$results/table.md" 2>&1
done
cat "$results/table.md"
if [ -n "${INFER:-}" ]; then
  frames=$work/frames/cuda-1; [ -d "$frames" ] || frames=$work/frames/cpu-1
  weights=$(ls "$INFER"/*.pth)
  for args in "--backend torch --device cuda" "--backend torch --device cuda" "--backend torch --device cpu" \
      "--backend onnx --model $INFER/lite0.onnx" "--backend onnx --model $INFER/lite0.onnx --threads 2"; do
    env -u LD_LIBRARY_PATH PYTHONPATH="$INFER" timeout 120 python3 "$repo/benchmarks/bare_infer.py" "$frames" \
      --weights "$weights" $args 2>>"$results/infer.err" | tee -a "$results/infer.jsonl"
  done
fi
echo "total $(( $(date +%s) - started )) s"
