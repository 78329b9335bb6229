#!/bin/bash
# The ten-minute twin, cold, with the levers of the ten-minute branch (issue #53 item 4): fresh cache, 2 jobs,
# run from the worktree /work/wt/ten (branch ten-minute) on a quiet machine (background jobs paused by the lead).
# The lever beside run_quiet.sh's (disc_refresh = 0, correction_anchors = 2), the one judged sound
# (results/discrepancy/README.md, "Ten minutes"):
#   spec.fit.prefetch_jacobian=true   a real fit's Jacobian points run in the batch of its residuals (the same
#                                     runs and fit; the baseline's 46 runs in 24 rounds of 2 instead of 31)
# Not used (they move this twin's interval off the truth): spec.profile.correction_realizations=3.
# WT (worktree), OUT (a fresh folder) and EXTRA (more --set settings, one per line) may be given in the
# environment: run_quiet_v3.sh does.
set -e
WT=${WT:-/work/wt/ten}
OUT=${OUT:-/work/runs/ten/cold}
cd "$WT"
export PYTHONPATH="$WT"
export OUT EXTRA
if [ -e "$OUT" ]; then echo "$OUT exists: move it away first (the measurement is cold)"; exit 1; fi
mkdir -p "$OUT"
echo "START $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg) commit $(git rev-parse --short HEAD) $(python -m sweep.cli --version | head -1)"
python - <<'PY'
import os, resource, subprocess, sys, time
t0 = time.time()
out = os.environ["OUT"]
extra = [a for line in os.environ.get("EXTRA", "").splitlines() if line.strip() for a in ("--set", line.strip())]
rc = subprocess.call([sys.executable, "-m", "sweep.discrepancy.twins",
    "campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml",
    "--results", f"{out}/out", "--cache", f"{out}/cache",
    "--only", "compliant_boundary_crn_kbar_cement", "--jobs", "2",
    "--set", "spec.noise.disc_refresh=0", "--set", "spec.profile.correction_anchors=2",
    "--set", "spec.fit.prefetch_jacobian=true", *extra],
    stdout=open(f"{out}/summary_stdout.json", "w"))
ru = resource.getrusage(resource.RUSAGE_CHILDREN)
print(f"RC {rc} WALL {time.time() - t0:.2f} s, CPU {ru.ru_utime:.2f}+{ru.ru_stime:.2f}", flush=True)
PY
echo "END $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
