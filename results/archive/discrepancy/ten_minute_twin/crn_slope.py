"""How well m of the six realizations carry the correction between two profile anchors (twin10's cached
anchors, issue #53 item 4): the change fine_k(x3) − fine_k(x1) per realization, its mean over all six against
the mean over the first m, in noise units (2 kPa, 0.2 mm), beside the change of the mean itself."""
import numpy as np
import sweep.campaign.store as st
st.current_code_hash = lambda: "ef28364bdd8eb658"
import sweep.discrepancy.forward as fw
_fin = fw.finished
fw.finished = lambda rd, code_hash=None: _fin(rd, "ef28364bdd8eb658") or _fin(rd, "436edfd5d504aaef")
from pathlib import Path
from solver import RunOptions
from sweep.discrepancy.twins import load_twin_campaign
from sweep.discrepancy.spec import spec_from_dict
from sweep.discrepancy.data import load_measured
from sweep.discrepancy.heldout import heldout_data
from sweep.discrepancy.forward import SolverForward, fine_forwards
from sweep.discrepancy.problem import Problem
from sweep.discrepancy.noise import coarse_and_fines
CACHE = Path("/work/runs/twin10/cache")
camp = load_twin_campaign("/work/wt/t53/campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml")
spec = spec_from_dict(camp["spec"])
data = heldout_data(load_measured("/work/runs/twin10/out/compliant_boundary_crn_kbar_cement/data"), spec)
fwd = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), CACHE / "workflow", n_jobs=1)
fine = fine_forwards(spec, CACHE / "workflow", 1)
pb = Problem(data, spec, fwd)
A = [(0.004999999983521299, 0.01634683732502954), (0.004931156982214002, 0.018099285108451765),
     (0.004903891644373145, 0.019851732891873988)]
runs0 = fwd.n_runs
res = [coarse_and_fines(pb, fine, {"kbar": k, "effect:compliant_boundary": c}) for k, c in A]
assert fwd.n_runs == runs0 and all(f.n_runs == 0 for f in fine), "not all cached"
sig = pb.noise.sig_measured
obs = pb.obs
for (i, j) in ((0, 2), (0, 1)):
    (c1, f1), (c2, f2) = res[i], res[j]
    d = (f2 - f1) / sig                      # per realization change, noise units
    dmean = d.mean(axis=0) - (c2 - c1) / sig   # change of the correction, all six
    print(f"anchors {i}->{j}: change of the correction RMS (noise units) p_inj {np.sqrt(np.mean(dmean[obs=='p_inj']**2)):.3f}"
          f" front {np.sqrt(np.mean(dmean[obs=='front_radius_mean']**2)):.3f}")
    for m in (1, 2, 3):
        e = d[:m].mean(axis=0) - d.mean(axis=0)
        print(f"   m={m}: error of the carried change vs all six, RMS p_inj {np.sqrt(np.mean(e[obs=='p_inj']**2)):.3f}"
              f" front {np.sqrt(np.mean(e[obs=='front_radius_mean']**2)):.3f}")
    sd = d.std(axis=0, ddof=1)
    print(f"   per-realization change sd RMS: p_inj {np.sqrt(np.mean(sd[obs=='p_inj']**2)):.3f} front {np.sqrt(np.mean(sd[obs=='front_radius_mean']**2)):.3f}")
    # realization deviation itself (for scale): sd over k of f1
    s1 = f1.std(axis=0, ddof=1) / sig
    print(f"   realization spread at the anchor RMS: p_inj {np.sqrt(np.mean(s1[obs=='p_inj']**2)):.3f} front {np.sqrt(np.mean(s1[obs=='front_radius_mean']**2)):.3f}")
