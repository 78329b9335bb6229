set -x
cd /tmp
for w in r8before main; do
  env PYTHONPATH=WORKTREE_OF_$w DCHFRAC_ASSEMBLY_THREADS=2 DCHFRAC_KERNELS=numpy python -m sweep.cli bench --profile --h 2 --t-end 0.3 --option linear_solver=superlu --out results/archive/bench/round8/default2_h2_$w.json -q
done
for w in r8before main; do
  env PYTHONPATH=WORKTREE_OF_$w DCHFRAC_ASSEMBLY_THREADS=2 DCHFRAC_KERNELS=numpy python -m sweep.cli bench --profile --h 2 --t-end 1.0 --option linear_solver=superlu --out results/archive/bench/round8/default_1s_h2_$w.json -q
done
env PYTHONPATH=/work/main DCHFRAC_ASSEMBLY_THREADS=2 python -m sweep.cli bench --profile --h 2 --t-end 0.3 --out results/archive/bench/round8/fast_h2_0.3_main.json -q
env PYTHONPATH=/work/main DCHFRAC_ASSEMBLY_THREADS=2 python -m sweep.cli bench --profile --h 2 --t-end 1.0 --out results/archive/bench/round8/fast_1s_h2_main.json -q
