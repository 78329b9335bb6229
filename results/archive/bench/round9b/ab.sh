#!/bin/sh
# Ninth round, second part: OpenBLAS held to one thread during a run.  Before (worktree of the commit before the
# change) and after, one run at a time, every other job paused.  Usage: sh ab.sh BEFORE_TREE AFTER_TREE OUT_DIR
set -e
B=$1; A=$2; OUT=$3
for h in 2 1; do
  for w in before after; do
    T=$B; [ $w = after ] && T=$A
    env -u OPENBLAS_NUM_THREADS PYTHONPATH=$T python -m sweep.cli bench --profile --h $h --out $OUT/fast_h${h}_$w.json -qq
  done
done
for w in before after; do
  T=$B; [ $w = after ] && T=$A
  env -u OPENBLAS_NUM_THREADS PYTHONPATH=$T DCHFRAC_ASSEMBLY_THREADS=2 DCHFRAC_KERNELS=numpy python -m sweep.cli bench \
    --profile --h 2 --t-end 1.0 --option linear_solver=superlu --out $OUT/default_1s_h2_$w.json -qq
  env -u OPENBLAS_NUM_THREADS PYTHONPATH=$T python -m sweep.cli bench --profile --h 2 --t-end 1.0 --out $OUT/fast_1s_h2_$w.json -qq
done
