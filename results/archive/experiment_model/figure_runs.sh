#!/bin/sh
# The two runs of the volume-balance figure (issue #47 item 5): the paper and experiment presets, h = 4, to 2 s,
# one after the other on one core, with the code of commit e628f68 (exported to /tmp/h47_code_e628f68).
cd /tmp/h47_code_e628f68
export PYTHONPATH=/tmp/h47_code_e628f68 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1 DCHFRAC_ASSEMBLY_THREADS=1
R=/work/runs/h47
mkdir -p $R
for preset in paper experiment; do
  /usr/bin/time -f "$preset wall %e s" nice -n 5 python -m sweep.cli run --preset $preset --h 4 --t-end 2 --quiet --out $R/balance_${preset}_h4
done
python -m sweep.cli balance $R/balance_paper_h4 $R/balance_experiment_h4 --labels "paper (h = 4)","experiment (h = 4)" --out /work/wt/h47/results/experiment_model/volume_balance_h4.png
