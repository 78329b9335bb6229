"""The residual test at the truth, leave-one-out (issue #53 item 4): each of the six check realizations taken
in turn as the data's realization (plus the twin's own noise draw), corrected with the other five's mean and
covariance, as the workflow corrects the data with all six; beside it the data (mesh_seed 11).  At the true
parameters a series flagged systematic is a false alarm of the test for that realization."""
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
from sweep.discrepancy.spec import spec_from_dict
from sweep.discrepancy.data import load_measured
from sweep.discrepancy.heldout import heldout_data
from sweep.discrepancy.forward import SolverForward, fine_forwards
from sweep.discrepancy.problem import Problem
from sweep.discrepancy.noise import coarse_and_fines, NoiseModel
from sweep.discrepancy import stats
CACHE = Path("/work/runs/t53/diag_cache")
camp = load_twin_campaign("/work/wt/t53/campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml")
spec = spec_from_dict(camp["spec"])
data = heldout_data(load_measured("/work/runs/twin10/out/compliant_boundary_crn_kbar_cement/data"), spec)
fwd = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), CACHE / "workflow", n_jobs=1)
fine = fine_forwards(spec, CACHE / "workflow", 1)
pb = Problem(data, spec, fwd)
truth = {"kbar": 0.0018, "effect:compliant_boundary": 0.02}
coarse, fines = coarse_and_fines(pb, fine, truth)
gen = SolverForward(spec.baseline_overrides(), RunOptions.from_dict({k: v for k, v in camp["data"].items() if k not in DATA_KEYS}),
                    CACHE / "data", n_jobs=1)
ids = data.ids
allm = np.ones(pb.y.size, bool)
dat = pb.model_vector(dict(zip(ids, gen.predict_many([(pb.overrides(c, truth), pb.times[c]) for c in ids]))), allm)
noise = pb.noise.y_measured - dat          # the twin's own noise draw
sig = pb.noise.sig_measured
train = pb.mask(["c06", "c12", "c24"])
names = pb.series_names

def test(y_real, others):
    nm = NoiseModel(y_real + noise, sig, pb.layout)
    nm.set_discretization(others.mean(axis=0) - coarse, others, 0.0)
    r = nm.standardize(nm.y[train] - coarse[train], train, 50.0)
    t = stats.systematic_test(r, pb.series[train], 3.0, 0.3, null=nm.null_calibration(train, seed=0))
    flagged = [names[int(k)] for k, v in t["series"].items() if v["systematic"]]
    worst = max(t["series"].items(), key=lambda kv: kv[1]["chi2_excess_z"])
    return {"flagged": flagged, "chi2": float(r @ r), "worst": names[int(worst[0])],
            "worst_z": round(worst[1]["chi2_excess_z"], 2), "worst_rho": round(worst[1]["rho1"], 2)}

out = {"seed11_data": test(dat, fines)}
print("seed 11 (data)", out["seed11_data"], flush=True)
for k in range(len(fines)):
    out[f"seed{k + 1}"] = test(fines[k], np.delete(fines, k, axis=0))
    print(f"seed {k + 1} vs other five", out[f"seed{k + 1}"], flush=True)
# the data against five of the six (the same k as the leave-one-out), each five in turn
for k in range(len(fines)):
    out[f"seed11_vs_five_without{k + 1}"] = test(dat, np.delete(fines, k, axis=0))
print("seed 11 vs each five:", [out[f"seed11_vs_five_without{k + 1}"]["flagged"] for k in range(len(fines))])
json.dump(out, open("/work/runs/t53/diag/diag3.json", "w"), indent=1)
