#!/bin/sh
# Background runs of issue #47 (one core): the code is the export of commit c5a1c23 in /tmp/h47_code_c5a1c23 (so that
# edits of the worktree do not reach running workers); results in this worktree's results/.
# Resume: rerun this script (the campaigns skip done runs); if /tmp/h47_code_c5a1c23 is gone, re-export it with
#   mkdir -p /tmp/h47_code_c5a1c23 && git archive c5a1c23 | tar -x -C /tmp/h47_code_c5a1c23
cd /tmp/h47_code_c5a1c23
export PYTHONPATH=/tmp/h47_code_c5a1c23 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1 DCHFRAC_ASSEMBLY_THREADS=1
R=/work/wt/h47/results
nice -n 5 python -m sweep.cli campaign run campaigns/experiment_mesh_convergence.toml --results $R --jobs 1
nice -n 5 python -m sweep.cli campaign run campaigns/experiment_kbar_h2.toml --results $R --jobs 1
