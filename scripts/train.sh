#!/usr/bin/env bash
# One command for a full training (docs/TRAINING.md): renders the data cache if needed, trains,
# plots the loss curves, exports the best weights and evaluates them against the noisy input.
#   scripts/train.sh [extra affinity_train options]
# Environment: AFFINITY_DATA (data cache, default $HOME/.cache/affinity/data-v1), RUN (output
# folder, default $AFFINITY_DATA/../runs/<preset>), PRESET (small), STEPS (3000), MINUTES
# (0: no limit), BATCH (16), DEVICE (cpu; cuda with a CUDA build of libtorch), EXPORT (weights
# file to write, default $RUN/exported.affw; core/models/default.affw replaces the built-in model
# at the next build). Data settings: see scripts/make_training_data.sh (TRAIN_SEEDS, JOBS, ...).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
export AFFINITY_DATA=${AFFINITY_DATA:-$HOME/.cache/affinity/data-v1}
preset=${PRESET:-small}
run=${RUN:-$(dirname "$AFFINITY_DATA")/runs/$preset}
export_path=${EXPORT:-$run/exported.affw}
trainer=$root/build/training/affinity_train
[ -x "$trainer" ] || { echo "train.sh: build it first: cmake --build build -j2 --target affinity_train affinity" >&2; exit 1; }

"$root/scripts/make_training_data.sh"
OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive} "$trainer" --data "$AFFINITY_DATA" --out "$run" --preset "$preset" \
  --steps "${STEPS:-3000}" --minutes "${MINUTES:-0}" --batch "${BATCH:-16}" --crop 64 --frames 6 \
  --lr 1e-3 --lr-half-life 3000 --val-every 100 --checkpoint-every 100 --device "${DEVICE:-cpu}" --seed 1 \
  --export "$export_path" "$@"
python=$root/.venv/bin/python
[ -x "$python" ] || python=python3
"$python" "$root/training/plot_loss.py" "$run/loss.csv" --out "$run/loss.png" --title "affinity_train $preset"
"$root/scripts/train_evaluate.sh" "$export_path"
