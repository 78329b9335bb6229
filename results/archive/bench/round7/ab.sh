set -x
cd /tmp
for w in pcwt main; do
  env PYTHONPATH=/work/$w DCHFRAC_ASSEMBLY_THREADS=2 python -m sweep.cli bench --profile --h 2 --out /work/runs/r7/fast_h2_$w.json -q
done
for w in pcwt main; do
  env PYTHONPATH=/work/$w DCHFRAC_ASSEMBLY_THREADS=2 DCHFRAC_KERNELS=numpy python -m sweep.cli bench --profile --h 2 --t-end 0.3 --option linear_solver=superlu --out /work/runs/r7/default_h2_$w.json -q
done
