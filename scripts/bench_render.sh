#!/usr/bin/env bash
# Renderer throughput: a 256x256, 8-frame, 4-spp sequence with 1024-spp references for three
# bundled scenes; prints seconds and rays per second per scene (from render_summary.json).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${AFFINITY_BENCH_OUT:-$root/out/bench_render}
frames=${FRAMES:-8}
echo "| scene | frames | seconds | seconds per frame | Mrays/s | load average before |"
echo "|---|---|---|---|---|---|"
for scene in ${SCENES:-glossy refraction disocclusion}; do
  load=$(cut -d' ' -f1 /proc/loadavg)
  "$root/build/core/affinity" render --scene "$scene" --frames "$frames" --spp 4 --size 256x256 \
    --reference-spp 1024 --seed 1 --out "$out/$scene" --force >/dev/null 2>&1
  "$root/.venv/bin/python" - "$out/$scene/render_summary.json" "$load" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
print(f"| {s['scene']} | {s['frames']} | {s['seconds']:.1f} | {s['seconds'] / s['frames']:.1f} | "
      f"{s['rays_per_second'] / 1e6:.2f} | {sys.argv[2]} |")
PY
done
