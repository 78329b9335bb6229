"""Diagnosis of the ten-minute twin's c12 front miss (issue #53 item 4): residuals at the final fit and at
the truth, each under the correction re-estimated there, and the data realization against the six."""
import json, sys, logging
import numpy as np
import sweep.campaign.store as st
st.current_code_hash = lambda: "ef28364bdd8eb658"   # the twin10 cache's solver (numerics unchanged since)
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
from sweep.discrepancy.noise import add_discretization_error, _coarse_and_fines
from sweep.discrepancy.evidence import localize
from sweep.discrepancy import stats
logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", datefmt="%H:%M:%S")

CACHE = Path("/work/runs/t53/diag_cache")
camp = load_twin_campaign("/work/wt/t53/campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml")
spec = spec_from_dict(camp["spec"])
data = heldout_data(load_measured("/work/runs/twin10/out/compliant_boundary_crn_kbar_cement/data"), spec)
fwd = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), CACHE / "workflow", n_jobs=2)
fine = fine_forwards(spec, CACHE / "workflow", 2)
pb = Problem(data, spec, fwd)
train = ["c06", "c12", "c24"]
params = tuple(spec.calibrate) + (spec.candidate_param("compliant_boundary"),)

def state(vals, label, corr_vals=None):
    add_discretization_error(pb, fine, corr_vals or vals)
    x = np.array([p.to_x(vals[p.name]) for p in params])
    r = pb.residual_batch(params, [x], train)[0]
    m = pb.mask(train)
    from sweep.discrepancy.problem import Fit
    f = Fit(params, x, r, np.zeros((r.size, 2)), 0.5 * float(r @ r), 0)
    loc = localize(pb, f, train)
    dev = pb.noise.marginal_deviance(r, m)
    out = {"label": label, "values": vals, "chi2": float(r @ r), "marginal": dev,
           "series": {k: {kk: round(v[kk], 3) for kk in ("rho1", "chi2_excess_z", "mean_z", "systematic")}
                      for k, v in loc["series"].items()}, "systematic": loc["systematic"]}
    print(json.dumps(out, indent=1), flush=True)
    return out

res = {}
res["final"] = state({"kbar": 0.00423330953679034, "effect:compliant_boundary": 0.018416154036689208}, "final fit")
res["refresh"] = state({"kbar": 0.0036687979411356886, "effect:compliant_boundary": 0.018099285108451765}, "refresh fit",
                      {"kbar": 0.003664211840910444, "effect:compliant_boundary": 0.01821430860836485})
res["final_refreshcorr"] = state({"kbar": 0.00423330953679034, "effect:compliant_boundary": 0.018416154036689208}, "final fit, refresh correction",
                      {"kbar": 0.003664211840910444, "effect:compliant_boundary": 0.01821430860836485})
res["truth"] = state({"kbar": 0.0018, "effect:compliant_boundary": 0.02}, "truth")
json.dump(res, open("/work/runs/t53/diag/diag1.json", "w"), indent=1)
