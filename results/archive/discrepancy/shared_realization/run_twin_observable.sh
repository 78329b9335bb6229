#!/bin/bash
# issue #53 item 3: the ten-minute twin re-evaluated with [noise] realization_blocks = "observable" from a copy of its cache
cd /work/wt/xcov
export PYTHONPATH=/work/wt/xcov
echo "START $(date -u +%T) load $(cut -d' ' -f1-3 /proc/loadavg) commit $(git rev-parse --short HEAD) cache files $(find /work/runs/xcov/cache_copy -type f | wc -l)"
nice -n 5 python -m sweep.discrepancy.twins campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml \
    --results /work/runs/xcov/out --cache /work/runs/xcov/cache_copy \
    --only compliant_boundary_crn_kbar_cement --jobs 1 \
    --set spec.noise.disc_refresh=0 --set spec.profile.correction_anchors=2 \
    --set 'spec.noise.realization_blocks="observable"' > /work/runs/xcov/summary_stdout.json
echo "RC $? END $(date -u +%T) cache files $(find /work/runs/xcov/cache_copy -type f | wc -l)"
