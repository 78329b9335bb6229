#!/bin/bash
# The ten-minute twin, cold (issue #53 item 4): fresh cache, 2 jobs, on main, background jobs paused.
cd /work/main
export PYTHONPATH=/work/main
echo "START $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg) commit $(git rev-parse --short HEAD)"
python - <<'PY'
import resource, subprocess, sys, time
t0 = time.time()
rc = subprocess.call([sys.executable, "-m", "sweep.discrepancy.twins",
    "campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml",
    "--results", "/work/runs/twin10b/out", "--cache", "/work/runs/twin10b/cache",
    "--only", "compliant_boundary_crn_kbar_cement", "--jobs", "2",
    "--set", "spec.noise.disc_refresh=0", "--set", "spec.profile.correction_anchors=2"],
    stdout=open("/work/runs/twin10b/summary_stdout.json", "w"))
ru = resource.getrusage(resource.RUSAGE_CHILDREN)
print(f"RC {rc} WALL {time.time() - t0:.2f} s, CPU {ru.ru_utime:.2f}+{ru.ru_stime:.2f}", flush=True)
PY
echo "END $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg)"
