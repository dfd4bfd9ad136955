#!/usr/bin/env bash
# A training-data folder made of some of another one's sequences, as symbolic links (nothing is
# copied or re-rendered), so that affinity_train's --data can train on a chosen mix: the sparks
# fine-tunes (docs/TRAINING.md, "Sparks in the training data") trained on the 300 base sequences
# plus 40 of the 100 sparks ones, and validated on the base sequences only:
#   scripts/link_data_subset.sh ~/.cache/affinity/data-ref256 ~/.cache/affinity/data-mix \
#       'seed_*' 'sparks_013[0-3]?'
# Usage: link_data_subset.sh FROM TO TRAIN_PATTERN... ; FROM/train sequences whose folder name
# matches a pattern are linked into TO/train, FROM/val sequences matching VAL_PATTERN (environment,
# default 'seed_*') into TO/val. TO may already hold links from an earlier call (they are
# replaced); anything else in it is left alone and makes the script stop.
set -euo pipefail
if [ $# -lt 3 ]; then
    echo "usage: $0 FROM TO TRAIN_PATTERN...   (VAL_PATTERN=... for the validation sequences)" >&2
    exit 2
fi
from=$(cd "$1" && pwd)
to=$2
shift 2
val_pattern=${VAL_PATTERN:-seed_*}

link_matching() {  # link_matching SPLIT PATTERN...: links FROM/SPLIT/<match> into TO/SPLIT
    local split=$1 count=0 pattern sequence name
    shift
    mkdir -p "$to/$split"
    for pattern in "$@"; do
        for sequence in "$from/$split"/$pattern; do
            [ -d "$sequence" ] || continue
            name=$(basename "$sequence")
            if [ -e "$to/$split/$name" ] && [ ! -L "$to/$split/$name" ]; then
                echo "$0: $to/$split/$name exists and is not a link; not touching it" >&2
                exit 1
            fi
            ln -sfn "$sequence" "$to/$split/$name"
            count=$((count + 1))
        done
    done
    if [ "$count" -eq 0 ]; then
        echo "$0: no sequence in $from/$split matches: $*" >&2
        exit 1
    fi
    echo "$to/$split: $count sequences linked"
}

link_matching train "$@"
link_matching val "$val_pattern"
