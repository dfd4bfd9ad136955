#!/usr/bin/env bash
# One command for a full training (docs/TRAINING.md): renders the data cache if needed, trains,
# plots the loss curves, exports the best weights and evaluates them against the noisy input.
#   scripts/train.sh [extra affinity_train options, e.g. --albedo-demodulation]
# The defaults are a full CPU training of the small preset: crops of 4 x 64x64 x 6 frames per
# step, 160 minutes of training after the data (400 sequences, about 17 minutes to render on 2
# cores), so that the whole command ends within 3 hours on a 2-core machine (docs/TRAINING.md,
# "A full CPU training"; the shipped default itself was trained on a GPU).
# Environment: AFFINITY_DATA (data cache, default $HOME/.cache/affinity/data-v1), RUN (output
# folder, default $AFFINITY_DATA/../runs/<preset>), PRESET (small), STEPS (100000: the time limit
# ends the run), MINUTES (160; 0: no limit), BATCH (4), LR_HALF_LIFE (1200), THREADS (2), SEED (1),
# DEVICE (cpu; cuda with a CUDA build of libtorch), EXPORT (weights file to write, default
# $RUN/exported.affw; core/models/default.affw replaces the built-in model at the next build).
# OpenMP's default wait policy (workers spin briefly before sleeping): with OMP_WAIT_POLICY=passive a
# step takes about twice as long (docs/TRAINING.md, "Threads that sleep between ops").
# Data settings: see scripts/make_training_data.sh (TRAIN_SEEDS, default here 1000-1399, JOBS, ...).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
export AFFINITY_DATA=${AFFINITY_DATA:-$HOME/.cache/affinity/data-v1}
export TRAIN_SEEDS=${TRAIN_SEEDS:-1000-1399}
export JOBS=${JOBS:-2} COMPRESSION=${COMPRESSION:-none}
preset=${PRESET:-small}
run=${RUN:-$(dirname "$AFFINITY_DATA")/runs/$preset}
export_path=${EXPORT:-$run/exported.affw}
trainer=$root/build/training/affinity_train
[ -x "$trainer" ] || { echo "train.sh: build it first: cmake --build build -j2 --target affinity_train affinity" >&2; exit 1; }

"$root/scripts/make_training_data.sh"
"$trainer" --data "$AFFINITY_DATA" --out "$run" --preset "$preset" \
  --steps "${STEPS:-100000}" --minutes "${MINUTES:-160}" --batch "${BATCH:-4}" --crop 64 --frames 6 \
  --lr 1e-3 --lr-half-life "${LR_HALF_LIFE:-1200}" --val-every 100 --checkpoint-every 100 \
  --threads "${THREADS:-2}" --device "${DEVICE:-cpu}" --seed "${SEED:-1}" --export "$export_path" "$@"
python=$root/.venv/bin/python
[ -x "$python" ] || python=python3
"$python" "$root/training/plot_loss.py" "$run/loss.csv" --out "$run/loss.png" --title "affinity_train $preset"
"$root/scripts/train_evaluate.sh" "$export_path"
