#!/bin/sh
# Ninth round: before (worktree of the commit before the change) against after (main), one run at a time,
# every other job paused.  Usage: sh ab.sh BEFORE_TREE AFTER_TREE OUT_DIR
set -e
B=$1; A=$2; OUT=$3
for i in 1 2; do
  for w in before after; do
    T=$B; [ $w = after ] && T=$A
    PYTHONPATH=$T python -m sweep.cli bench --profile --h 2 --out $OUT/fast_h2_${w}_$i.json -qq
  done
done
for w in before after; do
  T=$B; [ $w = after ] && T=$A
  PYTHONPATH=$T python -m sweep.cli bench --profile --h 1 --out $OUT/fast_h1_${w}.json -qq
done
