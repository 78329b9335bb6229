#!/bin/bash
# The ten-minute twin, cold, with the starting SPEC's covariance and threshold (issue #53 item 4): fresh cache, 2 jobs,
# run from a worktree at main (WT, default /work/wt/ten3) on a quiet machine (background jobs paused by the lead).
# Beside v2's levers (disc_refresh = 0, correction_anchors = 2, prefetch_jacobian): three fine realizations instead
# of six (half the fine runs), which the starting SPEC's choices make sound on the toy (realization_blocks =
# "observable", threshold = "f_realizations", lag1 = "mean_ratio": 0.970 coverage at k = 3,
# results/discrepancy/shared_realization/README.md).
set -e
WT=${WT:-/work/wt/ten3}
cd "$WT"
export PYTHONPATH="$WT"
OUT=/work/runs/ten3/cold
if [ -e "$OUT" ]; then echo "$OUT exists: move it away first (the measurement is cold)"; exit 1; fi
mkdir -p "$OUT"
echo "START $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg) commit $(git rev-parse --short HEAD) $(python -m sweep.cli --version | head -1)"
python - <<'PY'
import resource, subprocess, sys, time
t0 = time.time()
rc = subprocess.call([sys.executable, "-m", "sweep.discrepancy.twins",
    "campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml",
    "--results", "/work/runs/ten3/cold/out", "--cache", "/work/runs/ten3/cold/cache",
    "--only", "compliant_boundary_crn_kbar_cement", "--jobs", "2",
    "--set", "spec.noise.disc_refresh=0", "--set", "spec.profile.correction_anchors=2",
    "--set", "spec.fit.prefetch_jacobian=true", "--set", "spec.discretization.mesh_seeds=[1, 2, 3]",
    "--set", 'spec.noise.realization_blocks="observable"', "--set", 'spec.noise.lag1="mean_ratio"',
    "--set", 'spec.profile.threshold="f_realizations"'],
    stdout=open("/work/runs/ten3/cold/summary_stdout.json", "w"))
ru = resource.getrusage(resource.RUSAGE_CHILDREN)
print(f"RC {rc} WALL {time.time() - t0:.2f} s, CPU {ru.ru_utime:.2f}+{ru.ru_stime:.2f}", flush=True)
PY
echo "END $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
