#!/usr/bin/env bash
# Sets everything up and runs every test: the C++ suite (CTest), the Python suite (pytest), the
# Blender extension's suite on bpy 5.0 (Python 3.11) and 5.3 (Python 3.13), then the C++ unit
# tests again under AddressSanitizer + UndefinedBehaviorSanitizer, then the libFuzzer targets for
# a bounded time (AFFINITY_FUZZ_SECONDS each, default 60).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
jobs=${AFFINITY_JOBS:-2}
"$root/scripts/setup.sh"

echo "== Python lint (ruff, pyproject.toml)"
.venv/bin/ruff check .

echo "== C++ format (.clang-format)"
scripts/check_format.sh

echo "== C++ tests (Release)"
ctest --test-dir build --output-on-failure -j "$jobs"

echo "== Python tests"
# The repository root too: the benchmark (affinity_bench/) is a package of the repository, not of the module.
PYTHONPATH="$root/build/python:$root" AFFINITY_BUILD_DIR="$root/build" .venv/bin/python -m pytest -q tests/python

# AFFINITY_REQUIRE_CORE: fail rather than test the pipeline with the stand-in denoiser.
echo "== Blender extension tests (bpy 5.0, Python 3.11, headless)"
PYTHONPATH="$root/build/python:$root/blender_addon" AFFINITY_REQUIRE_CORE=1 .venv-blender/bin/python \
  -m pytest -q -W error tests/blender

echo "== Blender extension tests (bpy 5.3, Python 3.13, in the Debian 13 root of setup_py313.sh)"
# The development core for Python 3.13 is the cp313 wheel, unpacked (build/python is for 3.11).
scripts/in_py313_root.sh python -m pip install -q --no-deps --no-index --disable-pip-version-check \
  --upgrade --target build-py313/python blender_addon/affinity_denoiser/wheels/affinity_core-*-cp313-*.whl
scripts/in_py313_root.sh env PYTHONPATH="$root/build-py313/python:$root/blender_addon" AFFINITY_REQUIRE_CORE=1 \
  python -m pytest -q -W error tests/blender

echo "== The render engine through Blender's own command line (Debian 13's blender 4.3 program)"
scripts/test_blender_binary.sh

echo "== C++ tests under AddressSanitizer + UndefinedBehaviorSanitizer"
# libtorch is not instrumented and the training code is covered by the Release run above.
cmake -S . -B build-sanitize -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DAFFINITY_SANITIZE=ON \
  -DAFFINITY_BUILD_PYTHON=OFF -DAFFINITY_BUILD_TRAINING=OFF -DAFFINITY_BUILD_BENCH=OFF >/dev/null
cmake --build build-sanitize -j "$jobs"
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
  ctest --test-dir build-sanitize --output-on-failure -j "$jobs"

echo "== Fuzzing the weights, frame and scene-file readers (libFuzzer + ASan + UBSan, clang)"
fuzz_seconds=${AFFINITY_FUZZ_SECONDS:-60}
CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DAFFINITY_FUZZ=ON -DAFFINITY_BUILD_PYTHON=OFF \
  -DAFFINITY_BUILD_TESTS=OFF -DAFFINITY_BUILD_BENCH=OFF >/dev/null
cmake --build build-fuzz -j "$jobs" --target fuzz_weights fuzz_frame_reader fuzz_scene_file make_fuzz_seeds
# Seeds are regenerated every run; what the fuzzers add to the corpus is kept between runs.
build-fuzz/tests/fuzz/make_fuzz_seeds build-fuzz/corpus/weights build-fuzz/corpus/frames
# The scene files' seeds are the bundled scenes (every section and key of the format).
mkdir -p build-fuzz/corpus/scenes build-fuzz/findings
cp samples/scenes/*.json build-fuzz/corpus/scenes/
for fuzzer in weights:fuzz_weights frames:fuzz_frame_reader scenes:fuzz_scene_file; do
  corpus=${fuzzer%%:*} target=${fuzzer#*:}
  log=build-fuzz/$target.log
  dictionary=()
  [ "$target" = fuzz_scene_file ] && dictionary=(-dict=tests/fuzz/scene_file.dict)
  if ! build-fuzz/tests/fuzz/$target -max_total_time="$fuzz_seconds" -timeout=10 -print_final_stats=1 \
      "${dictionary[@]}" -artifact_prefix=build-fuzz/findings/ "build-fuzz/corpus/$corpus" >"$log" 2>&1; then
    tail -n 80 "$log"
    echo "FAIL: $target found a crash, leak, timeout or undefined behaviour; the input is in build-fuzz/findings/" >&2
    exit 1
  fi
  grep -E "^Done|stat::number_of_executed_units" "$log" | head -1
done
