#!/usr/bin/env bash
# Set up sweep3d on a fresh Debian 12 machine: system libraries, meshes, a virtualenv.
#   bash scripts/setup.sh          # what `sweep3d run` needs
#   bash scripts/setup.sh --test   # plus the test and docs extras and Chromium for the report's browser tests
# Safe to rerun: it installs only what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

with_test=0
[ "${1:-}" = "--test" ] && with_test=1

# Libraries bpy needs to import headless, Sweet Home 3D's furniture (the quickstart's meshes), and LLVM 19 for
# the mitsuba engine's llvm_ad_rgb variant (without it Mitsuba renders with scalar_rgb, about 2.5x slower).
packages="libx11-6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libsm6 libice6 libxext6 libgl1 libegl1 sweethome3d-furniture libllvm19"
[ "$with_test" = 1 ] && packages="$packages chromium"
if ! dpkg -s $packages >/dev/null 2>&1; then
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  $sudo apt-get update -q
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q $packages
fi

python=python3.11
command -v "$python" >/dev/null 2>&1 || python=python3
"$python" -c 'import sys; assert sys.version_info[:2] == (3, 11), "bpy 4.5 needs Python 3.11"'
[ -x .venv/bin/python ] || "$python" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
# The CPU build of torch first (an unpinned torch would pull a multi-GB CUDA build).
.venv/bin/python -m pip install -q "torch==2.13.0"
if [ "$with_test" = 1 ]; then
  .venv/bin/python -m pip install -q -e ".[test,docs]"  # docs: tests/docs/test_docs_site.py builds the site
else
  .venv/bin/python -m pip install -q -e .
fi
# The report starts faster with plotly.js's smaller "cartesian" bundle (npm registry, MIT); it
# must match the plotly.js version that the plotly package writes figures for. Optional.
plotly_js=$(.venv/bin/python -c 'from plotly.offline import get_plotlyjs_version as v; print(v())')
target=.venv/share/sweep3d/plotly-cartesian.min.js
if command -v npm >/dev/null 2>&1 && ! grep -qs "v$plotly_js" "$target"; then
  tmp=$(mktemp -d)
  if (cd "$tmp" && npm pack -q "plotly.js-cartesian-dist-min@$plotly_js" >/dev/null 2>&1 && tar -xzf ./*.tgz); then
    mkdir -p "$(dirname "$target")" && cp "$tmp/package/plotly-cartesian.min.js" "$target"
  else
    echo "note: plotly.js-cartesian-dist-min@$plotly_js not fetched; reports use plotly's full bundle"
  fi
  rm -rf "$tmp"
fi
echo "sweep3d is installed: .venv/bin/sweep3d --help"
