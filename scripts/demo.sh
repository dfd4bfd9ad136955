#!/usr/bin/env bash
# The main job: set everything up, render the bundled sample sequence at low spp with its
# references, and write the frames, preview images and a metrics summary to out/demo/.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/setup.sh"
out=${AFFINITY_DEMO_OUT:-$root/out/demo}
"$root/build/core/affinity" render --scene glossy --frames 8 --spp 4 --size 192x144 \
  --reference-spp 256 --seed 1 --out "$out" --previews --force
echo "demo: frames, noisy_*.png, reference_*.png and render_summary.json are in $out"
