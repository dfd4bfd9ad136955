#!/usr/bin/env bash
# Scores the Blender extension's model (with its pre-roll), OpenImageDenoise on the same passes
# and Blender's own denoiser on several draws of the Cycles suite's noise: the same scenes and
# references, the inputs captured again from other seeds (training/cycles/make_data.py
# --input-draw N --references-from DATA0 --out DATAN). One draw of 8 frames scores a method by
# the luck of its samples as well as by its skill; the spread over draws says which per-scene
# differences the suite can tell apart (docs/CYCLES_DATA.md, "Draws").
#   scripts/cycles_draws.sh OUT DATA0 [DATA1 ...]
# MODEL (default the extension's models/cycles.affw) is the model scored (Blender's denoiser
# comes with every Cycles run of the benchmark). Per draw k: the
# benchmark's CSVs in OUT/draw<k>/ and ColorVideoVDP's in OUT/draw<k>/cvvdp.csv (the frames
# in a scratch folder, removed); then the table over draws, OUT/draws.md
# (scripts/cycles_draws_table.py). Needs the benchmark's .venv and the .venv-cvvdp of
# scripts/setup_cvvdp.sh. About 5 minutes a draw on 2 cores.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
if [ $# -lt 2 ]; then
  echo "usage: scripts/cycles_draws.sh OUT DATA0 [DATA1 ...]" >&2
  exit 2
fi
out=$1
shift
model=${MODEL:-$root/blender_addon/affinity_denoiser/models/cycles.affw}
for tool in "$root/.venv/bin/python" "$root/.venv-cvvdp/bin/python"; do
  if [ ! -x "$tool" ]; then
    echo "cycles_draws: $tool is missing (scripts/setup.sh, scripts/setup_cvvdp.sh)" >&2
    exit 2
  fi
done
mkdir -p "$out"
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT INT TERM
export PYTHONPATH="$root/build/python:$root"
quietly() {  # quietly LOG COMMAND...: its output into LOG, shown only if it fails
  local log=$1
  shift
  "$@" > "$log" 2>&1 || { cat "$log" >&2; echo "cycles_draws: failed: $*" >&2; exit 1; }
}
k=0
for data in "$@"; do
  draw="$out/draw$k"
  rm -rf "$draw"
  echo "cycles_draws: draw $k, $data" >&2
  quietly "$scratch/bench$k.log" "$root/.venv/bin/python" -m affinity_bench --config cycles --data "$data" \
    --model "extension=$model" --methods ours-extension+preroll,oidn --no-reference-noise --out "$draw" \
    --save-outputs "$scratch/draw$k"
  quietly "$scratch/cvvdp$k.log" "$root/.venv-cvvdp/bin/python" "$root/scripts/cvvdp_score.py" "$scratch/draw$k" \
    --out "$draw/cvvdp.csv"
  rm -rf "$scratch/draw$k"
  # The CSVs carry every figure; the charts and pages of each draw are the suite's own kind
  # (results/bench_cycles holds draw 0's).
  find "$draw" -maxdepth 1 -type f ! -name '*.csv' -delete
  k=$((k + 1))
done
"$root/.venv/bin/python" "$root/scripts/cycles_draws_table.py" "$out" --command "scripts/cycles_draws.sh $out $*"
