#!/usr/bin/env bash
# One command for a full training (docs/TRAINING.md): renders the data cache if needed, trains,
# plots the loss curves, exports the best weights and evaluates them with the benchmark's renderer
# suite (docs/BENCHMARK.md) beside the built-in model, OpenImageDenoise and the noisy input.
#   scripts/train.sh [extra affinity_train options for both stages, e.g. --crop 96]
# The defaults are the shipped default model's recipe from scratch on the CPU (docs/TRAINING.md,
# "One command in two stages"): preset small; 220 procedural and 40 "sparks" sequences rendered
# at 16 spp with 256-spp targets and 8 validation sequences (18-22 minutes on 2 cores); crops
# of 4 x 64x64 x 6 frames at 2-8 spp per step. Two stages, in the order of the shipped chain:
#   1. from scratch, SMAPE + 0.5 warped temporal SMAPE + coarse SMAPE (lr 1e-3, half-life 3000);
#   2. the last FINAL_MINUTES (20) from stage 1's best weights, adding the warped absolute
#      temporal term at 0.1 (lr 1e-4, half-life 1200). That term cuts flicker but spreads the
#      light of tiny bright lamps onto their neighbours (a halo); added last, the halo is about
#      half as bright as with the term from the first step (docs/TRAINING.md, "One command in
#      two stages").
# The whole command keeps to BUDGET minutes (170): the training gets what the data step left,
# less 10 minutes for the evaluation (the benchmark: 4-9 minutes on 2 cores; the first time it
# also renders its sequences into its cache, about 6 minutes more), so a slow host trains for
# less rather than running past 3 hours (rendering the data took 18 minutes on the Intel host of
# 2026-12-04, 46 on an AMD EPYC Zen 1 host). The machine must do nothing else meanwhile: a
# build, a benchmark or a second trainer beside it slows each step several times over, even at
# the lowest scheduling class.
# Environment: AFFINITY_DATA (data cache, default $HOME/.cache/affinity/data-v2), RUN (output
# folder, default $AFFINITY_DATA/../runs/<preset>; stages in RUN/stage1 and RUN/stage2; a stage
# whose weights RUN/stageN.affw exist is not run again, an interrupted one resumes), PRESET
# (small), MINUTES (training minutes of both stages; default: what BUDGET leaves; 0 is not
# allowed), FINAL_MINUTES (20), BATCH (4), LR_HALF_LIFE (3000, stage 1), THREADS (2), SEED (1),
# DEVICE (cpu; cuda with a CUDA build of libtorch), EXPORT (weights file to write, default
# $RUN/exported.affw; core/models/default.affw replaces the built-in model at the next build);
# the evaluation goes to $RUN/bench (results.md, results.csv, charts).
# OpenMP's default wait policy (workers spin briefly before sleeping): with OMP_WAIT_POLICY=passive a
# step takes about twice as long (docs/TRAINING.md, "Threads that sleep between ops").
# Data settings: see scripts/make_training_data.sh (TRAIN_SEEDS, SPP, JOBS, ...; defaults below).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
export AFFINITY_DATA=${AFFINITY_DATA:-$HOME/.cache/affinity/data-v2}
export TRAIN_SEEDS=${TRAIN_SEEDS:-1000-1219} SPARK_TRAIN_SEEDS=${SPARK_TRAIN_SEEDS:-1300-1339}
export VAL_SEEDS=${VAL_SEEDS:-9000-9007} SPP=${SPP:-16} TRAIN_REFERENCE_SPP=${TRAIN_REFERENCE_SPP:-256}
export JOBS=${JOBS:-2} COMPRESSION=${COMPRESSION:-none}
preset=${PRESET:-small}
run=${RUN:-$(dirname "$AFFINITY_DATA")/runs/$preset}
export_path=${EXPORT:-$run/exported.affw}
trainer=$root/build/training/affinity_train
[ -x "$trainer" ] || { echo "train.sh: build it first: cmake --build build -j2 --target affinity_train affinity" >&2; exit 1; }

"$root/scripts/make_training_data.sh"
budget=${BUDGET:-170}
minutes=${MINUTES:-$(( budget - SECONDS / 60 - 10 ))}
if [ "$minutes" -lt 10 ] && [ -z "${MINUTES:-}" ]; then
  echo "train.sh: the data step used $((SECONDS / 60)) of the $budget minutes; $minutes left for training (set MINUTES or BUDGET)" >&2
  exit 1
fi
final_minutes=${FINAL_MINUTES:-20}
first_minutes=$(( minutes - final_minutes ))
if [ "$first_minutes" -lt 10 ]; then
  echo "train.sh: $minutes training minutes leave $first_minutes for stage 1 after FINAL_MINUTES=$final_minutes" >&2
  exit 1
fi
echo "train.sh: data ready after $((SECONDS / 60)) min; training for $minutes min ($first_minutes + $final_minutes)"
common=(--data "$AFFINITY_DATA" --preset "$preset" --steps 100000 --batch "${BATCH:-4}" --crop 64 --frames 6
  --val-every 200 --checkpoint-every 200 --coarse-weight 1 --temporal-weight 0.5 --warped-temporal
  --threads "${THREADS:-2}" --device "${DEVICE:-cpu}")
if [ ! -f "$run/stage1.affw" ]; then
  "$trainer" "${common[@]}" --out "$run/stage1" --minutes "$first_minutes" --lr 1e-3 \
    --lr-half-life "${LR_HALF_LIFE:-3000}" --seed "${SEED:-1}" --export "$run/stage1.affw" "$@"
fi
if [ ! -f "$run/stage2.affw" ]; then
  "$trainer" "${common[@]}" --out "$run/stage2" --minutes "$final_minutes" --init "$run/stage1.affw" \
    --lr 1e-4 --lr-half-life 1200 --absolute-temporal-weight 0.1 --seed "$(( ${SEED:-1} + 1 ))" \
    --export "$run/stage2.affw" "$@"
fi
cp "$run/stage2.affw" "$export_path.tmp" && mv "$export_path.tmp" "$export_path"
python=$root/.venv/bin/python
[ -x "$python" ] || python=python3
"$python" "$root/training/plot_loss.py" "$run/stage1/loss.csv" "$run/stage2/loss.csv" --out "$run/loss.png" \
  --title "affinity_train $preset, two stages"
# The evaluation is the benchmark's (docs/BENCHMARK.md), on the trained and the built-in model.
PYTHONPATH=$root/build/python:$root "$python" -m affinity_bench --config full --model "trained=$export_path" \
  --model small=builtin --methods noisy,oidn,ours-trained,ours-small --no-reference-noise --out "$run/bench"
