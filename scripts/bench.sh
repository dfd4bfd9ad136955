#!/usr/bin/env bash
# The full evaluation benchmark (docs/BENCHMARK.md): our denoiser, its ablations, the noisy
# input, OpenImageDenoise and SVGF on the bundled failure-case scenes and held-out procedural
# seeds at 2, 4 and 8 spp, and the equal-time comparison. Speed at 1080p is
# scripts/bench_denoiser.sh's.
#   scripts/bench.sh [more python -m affinity_bench options]     (run from anywhere; paths are
#                                                                  relative to the repository)
# Sets up and builds (scripts/setup.sh), then writes results/bench/ (results.md, CSVs, charts).
# The sequences are rendered once into ${AFFINITY_BENCH_DATA:-~/.cache/affinity/bench-v1} and
# reused. BENCH_OUT overrides the output folder.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
"$root/scripts/setup.sh"
build=${AFFINITY_BUILD_DIR:-build}
PYTHONPATH="$build/python:$root" .venv/bin/python -m affinity_bench --config full --out "${BENCH_OUT:-results/bench}" "$@"
