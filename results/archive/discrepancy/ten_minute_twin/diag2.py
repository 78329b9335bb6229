"""Is the data's realization (mesh_seed 11, h = 3, dt_max 0.005) an outlier of the six the workflow corrects
with (seeds 1-6, h = 3, dt_max 0.01)?  At the truth (kbar 0.0018, c 0.02): the data's noise-free curves, the
same seed at the realizations' dt_max 0.01, and each of the six left out against the other five, in units of
the leave-one-out spread (issue #53 item 4)."""
import json
import numpy as np
import sweep.campaign.store as st
st.current_code_hash = lambda: "ef28364bdd8eb658"
import sweep.discrepancy.forward as fw
_fin = fw.finished
fw.finished = lambda rd, code_hash=None: _fin(rd, "ef28364bdd8eb658") or _fin(rd, "436edfd5d504aaef")
from pathlib import Path
from solver import RunOptions
from sweep.discrepancy.twins import load_twin_campaign, DATA_KEYS
from sweep.discrepancy.spec import spec_from_dict, fine_options
from sweep.discrepancy.data import load_measured
from sweep.discrepancy.heldout import heldout_data
from sweep.discrepancy.forward import SolverForward, fine_forwards
from sweep.discrepancy.problem import Problem
from sweep.discrepancy.noise import coarse_and_fines
CACHE = Path("/work/runs/t53/diag_cache")
camp = load_twin_campaign("/work/wt/t53/campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml")
spec = spec_from_dict(camp["spec"])
data = heldout_data(load_measured("/work/runs/twin10/out/compliant_boundary_crn_kbar_cement/data"), spec)
fwd = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), CACHE / "workflow", n_jobs=2)
fine = fine_forwards(spec, CACHE / "workflow", 2)
pb = Problem(data, spec, fwd)
truth = {"kbar": 0.0018, "effect:compliant_boundary": 0.02}
coarse, fines = coarse_and_fines(pb, fine, truth)
gen = SolverForward(spec.baseline_overrides(), RunOptions.from_dict({k: v for k, v in camp["data"].items() if k not in DATA_KEYS}),
                    CACHE / "data", n_jobs=2)
s11 = SolverForward(spec.baseline_overrides(), RunOptions.from_dict({**fine_options(spec)[0], "mesh_seed": 11}),
                    CACHE / "workflow", n_jobs=2)
ids = data.ids
allm = np.ones(pb.y.size, bool)
jobs = [(pb.overrides(cid, truth), pb.times[cid]) for cid in ids]
dat = pb.model_vector(dict(zip(ids, gen.predict_many(jobs))), allm)
d11 = pb.model_vector(dict(zip(ids, s11.predict_many(jobs))), allm)
sig = pb.noise.sig_measured
out = {}
def z_of(x, others):
    m, s = others.mean(axis=0), others.std(axis=0, ddof=1) * np.sqrt(1 + 1 / len(others))
    return (x - m) / np.where(s > 0, s, np.nan)
for key in sorted(set(zip(pb.cond, pb.obs))):
    rows = (pb.cond == key[0]) & (pb.obs == key[1])
    late = rows & (pb.t >= 0.1)
    row = {"data_minus_mean6_over_sigma_noise": float(np.mean((dat - fines.mean(0))[late] / sig[late])),
           "data_z_vs_six": float(np.nanmean(z_of(dat, fines)[late])),
           "seed11_dt01_z_vs_six": float(np.nanmean(z_of(d11, fines)[late])),
           "data_minus_seed11_dt01_over_sigma_noise": float(np.mean((dat - d11)[late] / sig[late])),
           "loo_z_of_each": [float(np.nanmean(z_of(fines[k], np.delete(fines, k, 0))[late])) for k in range(len(fines))]}
    out["/".join(key)] = row
    print("/".join(key), json.dumps({k: (round(v, 2) if isinstance(v, float) else [round(u, 2) for u in v]) for k, v in row.items()}), flush=True)
json.dump(out, open("/work/runs/t53/diag/diag2.json", "w"), indent=1)
