#!/usr/bin/env bash
# Pack what benchmarks/bare_loop.py needs on a GPU machine that has neither Python 3.11 nor
# Blender: this checkout's Python 3.11 (interpreter and standard library), bpy and numpy from
# .venv, the shared libraries bpy links against beyond the C and C++ runtimes, and a jobs folder
# written by `gpu.py prepare`. Left out: Cycles' kernels for AMD and Intel GPUs, OIDN's HIP and
# SYCL devices, bpy's USD/MaterialX/OIIO Python modules, tests and caches. One xz tarball,
# split into PART_MB parts where uploads to the machine are limited in size (0: one file).
# benchmarks/gpu_device.sh unpacks it there and runs the benchmark.
#
#   bash benchmarks/gpu_bundle.sh OUT_DIR JOBS_DIR [PART_MB]
#
# CUBINS: the NVIDIA capabilities whose Cycles binaries to keep ("all", or e.g. "86 89"; "" keeps
# none: Hopper has none anyway); XZ_OPT: xz's options (default -9 -T0).
set -euo pipefail
out=${1:?usage: gpu_bundle.sh OUT_DIR JOBS_DIR [PART_MB]} jobs=${2:?JOBS_DIR from gpu.py prepare} part=${3:-0}
repo=$(cd "$(dirname "$0")/.." && pwd)
python=$repo/.venv/bin/python
prefix=$("$python" -c 'import sys; print(sys.base_prefix)')
site=$("$python" -c 'import importlib.util as u, os; print(os.path.dirname(os.path.dirname(u.find_spec("bpy").origin)))')
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/py/bin" "$stage/py/lib" "$stage/site" "$stage/libs" "$out"

cp "$prefix/bin/python3.11" "$stage/py/bin/"
cp "$prefix"/lib/libpython3.11.so* "$stage/py/lib/" 2>/dev/null || true  # a static build has none
cp -a "$prefix/lib/python3.11" "$stage/py/lib/"
(cd "$stage/py/lib/python3.11" && rm -rf test site-packages idlelib tkinter ensurepip lib2to3 pydoc_data \
  turtledemo config-3.11*)
cp -a "$site/bpy" "$site/numpy" "$site/numpy.libs" "$stage/site/"
cp -a "$jobs" "$stage/jobs"

bpy=$stage/site/bpy
version=$(basename "$(ls -d "$bpy"/[0-9]*.[0-9]*)")
kernels=$bpy/$version/scripts/addons_core/cycles/lib
rm -f "$kernels"/kernel_*gfx* "$bpy"/lib/libOpenImageDenoise_device_hip* "$bpy"/lib/libOpenImageDenoise_device_sycl*
if [ "${CUBINS-all}" != all ]; then
  for cubin in "$kernels"/kernel_sm_*.cubin*; do
    cc=${cubin##*/kernel_sm_}; cc=${cc%%.*}
    case " ${CUBINS-} " in *" $cc "*) ;; *) rm -f "$cubin" ;; esac
  done
fi
rm -rf "$bpy/$version/python/lib/python3.11/site-packages"/{pxr,MaterialX,OpenImageIO,openvdb*} \
  "$bpy/$version/datafiles/assets"
find "$stage" -name __pycache__ -prune -exec rm -rf {} + -o -path '*/numpy/*/tests' -prune -exec rm -rf {} +
if command -v strip >/dev/null; then
  find "$stage" -name '*.so*' -type f -exec strip --strip-unneeded {} + 2>/dev/null || true
fi

# The shared libraries bpy, numpy and Python load from the system, but for the C and C++ runtimes
# (any Linux has them, and a newer one than this machine's is compatible).
LD_LIBRARY_PATH=$bpy/lib ldd "$bpy/__init__.so" "$bpy"/lib/*.so* "$stage/py/bin/python3.11" 2>/dev/null \
  | awk '$2 == "=>" && $3 ~ /^\// {print $3}' | sort -u | while read -r lib; do
  case "$lib" in
    "$stage"/*|*/libc.so*|*/libm.so*|*/libdl.so*|*/libpthread.so*|*/librt.so*|*/libutil.so*|*/ld-linux*|\
    */libstdc++.so*|*/libgcc_s.so*|*/libpython3.11.so*) ;;
    *) cp -L "$lib" "$stage/libs/" ;;
  esac
done

tar -C "$stage" -cf - py site libs jobs | xz ${XZ_OPT:--9 -T0} > "$stage/bundle.tar.xz"
if [ "$part" -gt 0 ]; then
  split -b "${part}M" -d -a 2 "$stage/bundle.tar.xz" "$out/bundle.tar.xz."
else
  mv "$stage/bundle.tar.xz" "$out/"
fi
ls -l "$out"
