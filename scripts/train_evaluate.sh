#!/usr/bin/env bash
# Evaluates denoising models against the noisy input on sequences never used in training, with
# clean references: the bundled scenes (samples/scenes) and held-out procedural seeds.
#   scripts/train_evaluate.sh [MODEL.affw ...]      (no model: the built-in default)
# Renders the evaluation set once into ${AFFINITY_DATA:-$HOME/.cache/affinity/data-v1}/eval
# (EVAL_FRAMES=8 frames of EVAL_SIZE=128x96 at EVAL_SPP=4, reference EVAL_REFERENCE_SPP=256,
# procedural seeds EVAL_SEEDS="9100-9103"), then runs `affinity denoise` on every sequence and
# prints mean SMAPE / PSNR per sequence, noisy vs denoised, for each model. Also writes the
# table to $AFFINITY_DATA/eval/results_<model name>.csv.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
data=${AFFINITY_DATA:-$HOME/.cache/affinity/data-v1}
bin=${AFFINITY_BIN:-$root/build/core/affinity}
frames=${EVAL_FRAMES:-8}
size=${EVAL_SIZE:-128x96}
spp=${EVAL_SPP:-4}
ref=${EVAL_REFERENCE_SPP:-256}
seeds=${EVAL_SEEDS:-9100-9103}
eval_dir=$data/eval
[ -x "$bin" ] || { echo "train_evaluate: $bin not built" >&2; exit 1; }
mkdir -p "$eval_dir"

names=()
for scene in "$root"/samples/scenes/*.json; do
  name=$(basename "$scene" .json)
  names+=("$name")
  [ -f "$eval_dir/$name/render_summary.json" ] && continue
  "$bin" render --scene "$scene" --frames "$frames" --spp "$spp" --size "$size" --reference-spp "$ref" --seed 7 \
    --out "$eval_dir/$name" --compression piz --force >/dev/null 2>&1
  echo "rendered $name"
done
for part in ${seeds//,/ }; do
  for seed in $(if [[ $part == *-* ]]; then seq "${part%-*}" "${part#*-}"; else echo "$part"; fi); do
    name=procedural_$seed
    names+=("$name")
    [ -f "$eval_dir/$name/render_summary.json" ] && continue
    "$bin" render --scene "procedural:$seed" --frames "$frames" --spp "$spp" --size "$size" --reference-spp "$ref" \
      --seed "$seed" --out "$eval_dir/$name" --compression piz --force >/dev/null 2>&1
    echo "rendered $name"
  done
done

models=("$@")
[ ${#models[@]} -eq 0 ] && models=(builtin)
for model in "${models[@]}"; do
  label=$(basename "$model" .affw)
  work=$(mktemp -d)
  for name in "${names[@]}"; do
    args=(denoise --in "$eval_dir/$name" --out "$work/$name" --force)
    [ "$model" != builtin ] && args+=(--model "$model")
    "$bin" "${args[@]}" >/dev/null
  done
  python3 - "$work" "$eval_dir/results_$label.csv" "$model" "${names[@]}" <<'EOF'
import json, sys
work, csv_path, model, names = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4:]
rows = []
for name in names:
    frames = json.load(open(f"{work}/{name}/denoise_summary.json"))["per_frame"]
    mean = lambda kind, metric: sum(f[kind][metric] for f in frames) / len(frames)
    rows.append((name, mean("noisy", "smape"), mean("denoised", "smape"), mean("noisy", "psnr"), mean("denoised", "psnr")))
print(f"model {model}")
print(f"{'sequence':<18} {'SMAPE noisy':>11} {'denoised':>9} {'ratio':>6} {'PSNR noisy':>10} {'denoised':>9}")
with open(csv_path, "w") as out:
    out.write("sequence,smape_noisy,smape_denoised,psnr_noisy,psnr_denoised\n")
    for name, sn, sd, pn, pd in rows:
        print(f"{name:<18} {sn:11.4f} {sd:9.4f} {sd / sn:6.2f} {pn:10.2f} {pd:9.2f}")
        out.write(f"{name},{sn:.5f},{sd:.5f},{pn:.3f},{pd:.3f}\n")
    n = len(rows)
    sn, sd = sum(r[1] for r in rows) / n, sum(r[2] for r in rows) / n
    pn, pd = sum(r[3] for r in rows) / n, sum(r[4] for r in rows) / n
    print(f"{'mean':<18} {sn:11.4f} {sd:9.4f} {sd / sn:6.2f} {pn:10.2f} {pd:9.2f}")
    out.write(f"mean,{sn:.5f},{sd:.5f},{pn:.3f},{pd:.3f}\n")
EOF
  rm -rf "$work"
done
