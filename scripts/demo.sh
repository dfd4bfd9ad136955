#!/usr/bin/env bash
# The main job: set everything up, render the bundled sample sequence at low spp with its
# references, denoise it, and write the frames, images and metrics summaries to out/demo/.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/setup.sh"
out=${AFFINITY_DEMO_OUT:-$root/out/demo}
"$root/build/core/affinity" render --scene glossy --frames 8 --spp 4 --size 192x144 \
  --reference-spp 256 --seed 1 --out "$out/frames" --previews --force
"$root/build/core/affinity" denoise --in "$out/frames" --out "$out/denoised" --force
"$root/.venv/bin/python" "$root/scripts/summarize_demo.py" "$out"
