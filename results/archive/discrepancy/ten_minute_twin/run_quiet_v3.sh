#!/bin/bash
# The ten-minute twin, cold, with the starting SPEC's covariance and threshold (issue #53 item 4): run_quiet_v2.sh's
# run (disc_refresh = 0, correction_anchors = 2, prefetch_jacobian; fresh cache, 2 jobs, a quiet machine) with three
# fine realizations instead of six (half the fine runs), which the starting SPEC's choices make sound on the toy
# (realization_blocks = "observable", threshold = "f_realizations", lag1 = "mean_ratio": 0.970 coverage at k = 3,
# results/discrepancy/shared_realization/README.md).  Run from a worktree at main (WT, default /work/wt/ten3).
export WT=${WT:-/work/wt/ten3} OUT=${OUT:-/work/runs/ten3/cold}
export EXTRA='spec.discretization.mesh_seeds=[1, 2, 3]
spec.noise.realization_blocks="observable"
spec.noise.lag1="mean_ratio"
spec.profile.threshold="f_realizations"'
exec "$(dirname "$0")/run_quiet_v2.sh"
