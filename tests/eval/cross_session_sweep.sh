#!/bin/sh
# Learn in one session, track in another, over many random objects: each object is calibrated on
# 3,000 frames of its own scene (seed S) and tracked in sim::anotherSession of it (other motion,
# viewing directions, six or more glints a camera, a passing hand). Prints the pooled rates over
# all objects and over those learnt whole (one model of every marker: what tracking alone is
# answerable for), and fails when the latter miss the found share or show a wrong pose more often
# than MAX_WRONG per found frame.
# Usage: cross_session_sweep.sh EVAL_TRACKING FIRST_SEED LAST_SEED MIN_FOUND MAX_WRONG [LEVEL]
set -eu
eval_tracking=$1 first=$2 last=$3 min_found=$4 max_wrong=$5 level=${6:-points}
summaries=$(mktemp)
trap 'rm -f "$summaries"' EXIT
seed=$first
while [ "$seed" -le "$last" ]; do
    "$eval_tracking" --scene random_object --calibrate-frames 3000 --calibrate-seed "$seed" \
        --other-session --seed 1 --frames 2000 --level "$level" | sed -n 's/^summary: //p' \
        >>"$summaries"
    seed=$((seed + 1))
done
awk -v first="$first" -v last="$last" -v min_found="$min_found" -v max_wrong="$max_wrong" '
{ e += $4; f += $6; w += $8; r += $10; a += $12
  if ($2 == 1) { n1++; e1 += $4; f1 += $6; w1 += $8; r1 += $10; a1 += $12 } }
END {
  printf "random_object seeds %d-%d, another session: all objects found %d of %d eligible frames (%.2f%%), wrong %d, returns found at once %d of %d\n", first, last, f, e, 100 * f / (e ? e : 1), w, a, r
  printf "learnt whole (%d of %d objects): found %d of %d (%.2f%%), wrong %d, returns found at once %d of %d (%.1f%%)\n", n1, NR, f1, e1, 100 * f1 / (e1 ? e1 : 1), w1, a1, r1, 100 * a1 / (r1 ? r1 : 1)
  exit !(e1 > 0 && f1 >= min_found * e1 && w1 <= max_wrong * f1)
}' "$summaries"
