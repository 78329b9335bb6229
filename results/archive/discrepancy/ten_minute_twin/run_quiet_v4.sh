#!/bin/bash
# The ten-minute twin, cold (issue #53 item 4): run_quiet_v3.sh's settings (the starting SPEC's covariance, threshold
# and lag-1 estimator at three fine realizations) plus [fit] chi2_tol = 0.1, a real least-squares start stopping
# once a step gains less than 0.1 in chi2 (every interval's threshold here is above 3.84).  Run from a worktree at
# main (WT, default /work/wt/fittol) on a quiet machine.
export WT=${WT:-/work/wt/fittol} OUT=${OUT:-/work/runs/ten4/cold}
export EXTRA='spec.discretization.mesh_seeds=[1, 2, 3]
spec.noise.realization_blocks="observable"
spec.noise.lag1="mean_ratio"
spec.profile.threshold="f_realizations"
spec.fit.chi2_tol=0.1'
exec "$(dirname "$0")/run_quiet_v2.sh"
