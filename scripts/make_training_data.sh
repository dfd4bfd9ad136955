#!/usr/bin/env bash
# Renders the training and validation sequences of the procedural scene generator into a
# cache outside the repository (docs/TRAINING.md):
#   ${AFFINITY_DATA:-$HOME/.cache/affinity/data-v1}/train/seed_NNNNN   training sequences
#   ${AFFINITY_DATA:-$HOME/.cache/affinity/data-v1}/val/seed_NNNNN     held-out validation sequences
#   .../train/sparks_NNNNN, .../val/sparks_NNNNN   the same seeds' scenes with tiny, very bright
#                                                  moving lamps ("procedural-sparks:SEED")
# Training sequences use a moderate reference (TRAIN_REFERENCE_SPP, default 64: a Noise2Noise-style
# target that is far less noisy than the 2-8 spp input); validation sequences always get a
# clean reference (VAL_REFERENCE_SPP, default 256). Finished sequences (render_summary.json
# present) are skipped, so the command can be interrupted and re-run to continue.
#
# Settings (environment): TRAIN_SEEDS (default "1000-1099"), VAL_SEEDS ("9000-9003"),
# SPARK_TRAIN_SEEDS and SPARK_VAL_SEEDS (default none),
# FRAMES (6), SIZE (96x96), SPP (8), TRAIN_REFERENCE_SPP (64), VAL_REFERENCE_SPP (256),
# JOBS (parallel renders, default 1), COMPRESSION (piz; none reads faster and takes 1.3x the
# space), AFFINITY_BIN (default build/core/affinity).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
data=${AFFINITY_DATA:-$HOME/.cache/affinity/data-v1}
bin=${AFFINITY_BIN:-$root/build/core/affinity}
train_seeds=${TRAIN_SEEDS:-1000-1099}
val_seeds=${VAL_SEEDS:-9000-9003}
spark_train_seeds=${SPARK_TRAIN_SEEDS:-}
spark_val_seeds=${SPARK_VAL_SEEDS:-}
frames=${FRAMES:-6}
size=${SIZE:-96x96}
spp=${SPP:-8}
train_ref=${TRAIN_REFERENCE_SPP:-64}
val_ref=${VAL_REFERENCE_SPP:-256}
jobs=${JOBS:-1}
compression=${COMPRESSION:-piz}
[ -x "$bin" ] || { echo "make_training_data: $bin not built (cmake --build build --target affinity)" >&2; exit 1; }

expand() {  # "a-b" or "a,b,c" -> one seed per line
  local part
  for part in ${1//,/ }; do
    if [[ $part == *-* ]]; then seq "${part%-*}" "${part#*-}"; else echo "$part"; fi
  done
}

render_one() {  # split variant seed reference_spp
  local split=$1 variant=$2 seed=$3 ref=$4
  local dir scene
  if [ "$variant" = sparks ]; then
    dir=$(printf '%s/%s/sparks_%05d' "$data" "$split" "$seed") scene="procedural-sparks:$seed"
  else
    dir=$(printf '%s/%s/seed_%05d' "$data" "$split" "$seed") scene="procedural:$seed"
  fi
  [ -f "$dir/render_summary.json" ] && return 0
  # Different animation phases across seeds: the camera path spans frames 0..16.
  local first=$(( seed % 11 ))
  "$bin" render --scene "$scene" --frames "$frames" --first-frame "$first" --spp "$spp" \
    --size "$size" --reference-spp "$ref" --seed "$seed" --out "$dir" --compression "$compression" --force >/dev/null
  echo "$split $scene done ($(date +%H:%M:%S))"
}
export -f render_one
export data bin frames size spp compression

mkdir -p "$data/train" "$data/val"
start=$(date +%s)
{
  for seed in $(expand "$val_seeds"); do echo "val base $seed $val_ref"; done
  for seed in $(expand "$spark_val_seeds"); do echo "val sparks $seed $val_ref"; done
  for seed in $(expand "$train_seeds"); do echo "train base $seed $train_ref"; done
  for seed in $(expand "$spark_train_seeds"); do echo "train sparks $seed $train_ref"; done
} | xargs -P "$jobs" -n 4 bash -c 'render_one "$@"' _
echo "make_training_data: $(ls "$data/train" | wc -l) training and $(ls "$data/val" | wc -l) validation sequences in $data ($(( $(date +%s) - start )) s)"
