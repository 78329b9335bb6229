"""The ten-minute levers judged on a copy of the quiet run's cache (issue #53 item 4; read-only: a run the cache
lacks raises).  Two questions, at the correction stage's point (initial baseline) and the profile's two anchors:
(1) how well m of the six realizations carry the six's mean correction from one point to another (common random
numbers), against the change itself and the realizations' spread, in noise units (2 kPa, 0.2 mm);
(2) how a realization's deviation is shared across the four conditions (its mean deviation per condition and the
correlation across conditions), and the offset an m-mean leaves in each.
Run: PYTHONPATH=/work/wt/ten python levers_cache.py > results/discrepancy/ten_minute_twin/levers/cache_levers.txt"""
from pathlib import Path

import numpy as np

import sweep.discrepancy.forward as fwm
from solver import RunOptions
from sweep.discrepancy.data import load_measured
from sweep.discrepancy.forward import SolverForward, fine_forwards
from sweep.discrepancy.heldout import heldout_data
from sweep.discrepancy.noise import coarse_and_fines
from sweep.discrepancy.problem import Problem
from sweep.discrepancy.spec import spec_from_dict
from sweep.discrepancy.twins import load_twin_campaign


def _no(self, todo, code):
    raise RuntimeError(f"not cached: {list(todo)[:2]}")


fwm.SolverForward._run_batch = _no
CACHE = Path("/work/runs/ten/cache_m2")           # a copy of /work/runs/twin10b/cache (the quiet run)
camp = load_twin_campaign("/work/wt/ten/campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml")
spec = spec_from_dict(camp["spec"])
data = heldout_data(load_measured("/work/runs/twin10b/out/compliant_boundary_crn_kbar_cement/data"), spec)
fwd = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), CACHE / "workflow", n_jobs=1)
fine = fine_forwards(spec, CACHE / "workflow", 1)
pb = Problem(data, spec, fwd)
P = {"init": {"kbar": 0.0015, "effect:compliant_boundary": 0.0},
     "a1": {"kbar": 0.003821120498103685, "effect:compliant_boundary": 0.017642603850349752},
     "a2": {"kbar": 0.004038501580553543, "effect:compliant_boundary": 0.02022002713907446}}
res = {k: coarse_and_fines(pb, fine, v) for k, v in P.items()}
sig, obs, OBS = pb.noise.sig_measured, pb.obs, ("p_inj", "front_radius_mean")


def rms(a, o):
    return np.sqrt(np.nanmean(a[obs == o] ** 2))


print("(1) carrying the mean correction by m realizations")
for o in OBS:
    s = res["a1"][1].std(axis=0, ddof=1) / sig
    print(f"{o}: realization spread at a1 RMS {rms(s, o):.3f} noise sd, its six-mean's sd {rms(s, o) / np.sqrt(6):.3f}")
for i, j in (("init", "a1"), ("init", "a2"), ("a1", "a2")):
    (c1, f1), (c2, f2) = res[i], res[j]
    d = (f2 - f1) / sig
    dcorr, sd = d.mean(axis=0) - (c2 - c1) / sig, d.std(axis=0, ddof=1)
    print(f"{i}->{j}: change of the correction RMS p {rms(dcorr, 'p_inj'):.3f} front {rms(dcorr, OBS[1]):.3f}; "
          f"per-realization change sd RMS p {rms(sd, 'p_inj'):.3f} front {rms(sd, OBS[1]):.3f}")
    for m in (1, 2, 3):
        e = d[:m].mean(axis=0) - d.mean(axis=0)
        print(f"   m={m}: carried vs all six RMS p {rms(e, 'p_inj'):.3f} front {rms(e, OBS[1]):.3f}")
print("(2) a realization's deviation across the conditions", list(data.ids))
for name, (_, f) in res.items():
    dev = (f - f.mean(axis=0)) / sig
    for o in OBS[::-1]:
        M = np.array([[np.nanmean(dev[k, (pb.cond == c) & (pb.obs == o)]) for c in data.ids] for k in range(len(f))])
        C = np.corrcoef(M.T)
        print(f"{name} {o}: mean deviation per realization (rows) and condition (noise sd)\n{np.round(M, 2)}")
        print(f"   mean correlation across conditions {C[~np.eye(len(data.ids), dtype=bool)].mean():.2f}; "
              f"offset of the m-mean by condition m=3 {np.round(M[:3].mean(axis=0), 2)} m=2 {np.round(M[:2].mean(axis=0), 2)}")
