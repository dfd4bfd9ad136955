#!/usr/bin/env bash
# Sets everything up and runs every test: the C++ suite (CTest), the Python suite (pytest),
# then the C++ unit tests again under AddressSanitizer + UndefinedBehaviorSanitizer.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
jobs=${AFFINITY_JOBS:-2}
"$root/scripts/setup.sh"

echo "== C++ tests (Release)"
ctest --test-dir build --output-on-failure -j "$jobs"

echo "== Python tests"
PYTHONPATH="$root/build/python" AFFINITY_BUILD_DIR="$root/build" .venv/bin/python -m pytest -q tests/python

echo "== Blender extension tests (bpy, headless)"
PYTHONPATH="$root/build/python:$root/blender_addon" .venv-blender/bin/python -m pytest -q -W error \
  tests/blender

echo "== C++ tests under AddressSanitizer + UndefinedBehaviorSanitizer"
cmake -S . -B build-sanitize -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DAFFINITY_SANITIZE=ON \
  -DAFFINITY_BUILD_PYTHON=OFF >/dev/null
cmake --build build-sanitize -j "$jobs"
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
  ctest --test-dir build-sanitize --output-on-failure -j "$jobs"
