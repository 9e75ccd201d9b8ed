#!/bin/sh
# Calibration quality over many seeds of one or more scenes: the share of learnable runs learnt
# right (every object one complete model, no false marker, marker RMS within 0.1 mm).
# Usage: calibration_sweep.sh EVAL_CALIBRATION SCENE[,SCENE...] FIRST_SEED LAST_SEED MIN_SHARE
set -eu
eval_calibration=$1 scenes=$2 first=$3 last=$4 min_share=$5
right=0 wrong=0 unlearnable=0
for scene in $(echo "$scenes" | tr ',' ' '); do
    seed=$first
    while [ "$seed" -le "$last" ]; do
        verdict=$("$eval_calibration" --scene "$scene" --level points --seed "$seed" \
            --frames 3000 | sed -n 's/^result: //p')
        case $verdict in
        right) right=$((right + 1)) ;;
        "not learnable") unlearnable=$((unlearnable + 1)) ;;
        *) wrong=$((wrong + 1)) && echo "$scene seed $seed: $verdict" ;;
        esac
        seed=$((seed + 1))
    done
done
learnable=$((right + wrong))
echo "$scenes seeds $first-$last: $right of $learnable learnable right ($unlearnable not learnable)"
# Integer arithmetic: right / learnable >= min_share, with the share in thousandths.
share_milli=$(awk "BEGIN { printf \"%d\", $min_share * 1000 }")
[ "$learnable" -gt 0 ] && [ $((right * 1000)) -ge $((share_milli * learnable)) ]
