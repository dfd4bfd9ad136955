#!/usr/bin/env bash
# Fine-tunes a model on Cycles sequences mixed with the renderer's, validated on Cycles, then
# runs the Cycles benchmark suite on it beside the built-in model (docs/CYCLES_DATA.md).
#   scripts/train_cycles.sh [extra affinity_train options]
# Data: CYCLES_DATA (default ~/.cache/affinity/cycles-v1, made by training/cycles/make_data.py;
# its val/ sequences validate), RENDERER_DATA (~/.cache/affinity/data-v1, made by
# scripts/make_training_data.sh; its train/ sequences join the training set unless it is
# empty: RENDERER_DATA= trains on Cycles only). Both are linked into MIX (symbolic links).
# Training: from INIT (core/models/default.affw) for MINUTES (40), lr LR (3e-4) halved every
# 1500 steps, the shipped model's last-stage loss (SMAPE + 0.5 warped temporal SMAPE + coarse
# SMAPE + 0.1 absolute temporal); RUN (~/.cache/affinity/runs/cycles) holds the checkpoints, so
# an interrupted run resumes; the best weights go to RUN/exported.affw.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cycles_data=${CYCLES_DATA:-$HOME/.cache/affinity/cycles-v1}
renderer_data=${RENDERER_DATA-$HOME/.cache/affinity/data-v1}
mix=${MIX:-$HOME/.cache/affinity/mix-cycles}
run=${RUN:-$HOME/.cache/affinity/runs/cycles}
trainer=$root/build/training/affinity_train
[ -x "$trainer" ] || { echo "train_cycles.sh: build it first: cmake --build build -j2 --target affinity_train" >&2; exit 1; }

link() {  # link SPLIT FOLDER...: finished sequences (render_summary.json) into MIX/SPLIT
  local split=$1 sequence
  shift
  mkdir -p "$mix/$split"
  for sequence in "$@"; do
    [ -f "$sequence/render_summary.json" ] && ln -sfn "$sequence" "$mix/$split/$(basename "$sequence")"
  done
  return 0
}
link train "$cycles_data"/train/cycles_[0-9][0-9][0-9][0-9][0-9]
link val "$cycles_data"/val/cycles_[0-9][0-9][0-9][0-9][0-9]
[ -n "$renderer_data" ] && link train "$renderer_data"/train/*
echo "train_cycles.sh: $(ls "$mix/train" | grep -c '^cycles_') Cycles and $(ls "$mix/train" | grep -vc '^cycles_') renderer training sequences, $(ls "$mix/val" | wc -l) Cycles validation sequences"

"$trainer" --data "$mix" --init "${INIT:-$root/core/models/default.affw}" --out "$run" --steps 100000 \
  --minutes "${MINUTES:-40}" --batch 4 --crop 64 --frames 6 --val-every 200 --checkpoint-every 200 \
  --coarse-weight 1 --temporal-weight 0.5 --warped-temporal --absolute-temporal-weight 0.1 \
  --lr "${LR:-3e-4}" --lr-half-life 1500 --threads "${THREADS:-2}" --export "$run/exported.affw" "$@"
"$root/.venv/bin/python" "$root/training/plot_loss.py" "$run/loss.csv" --out "$run/loss.png" \
  --title "affinity_train fine-tune on Cycles"
PYTHONPATH=$root/build/python:$root "$root/.venv/bin/python" -m affinity_bench --config cycles --data "$cycles_data" \
  --model "cycles=$run/exported.affw" --model small=builtin --out "$run/bench_cycles"
