#!/usr/bin/env bash
# The test suite as CI runs it, in two sessions that together run every test once (the soak apart):
#   1. the fast lane, under its guard: a test without a blender/torch/browser/slow marker that imports
#      torch or bpy or starts a render worker fails, so `pytest -m fast` never breaks unseen;
#      Hypothesis at full strength (the lane alone defaults to its lighter profile);
#   2. every other test.
# Extra arguments go to both sessions (say -x, or -n 0 for one process).
set -euo pipefail
cd "$(dirname "$0")/.."
.venv/bin/python -m pytest -m "fast and not soak" --hypothesis-profile full "$@"
.venv/bin/python -m pytest -m "not fast and not soak" "$@"
