"""The ten-minute twin's realization covariance with [noise] realization_blocks = "series" and "observable",
read-only from a copy of the quiet run's cache (issue #53 item 3; a run the cache lacks is reported, not made).
At the correction stage's point (initial baseline) and the profile's anchors a1, a2 of the quiet run: ρ_o per
observable (the pooled correlation between conditions of the six realizations' deviations) and its dof, τ, each
block's scale dof; at a1 and a2 the residual test of the training series (as the workflow's localization) (the model there, corrected by the six
realizations' mean there) under either covariance, and the Gaussian χ² of the training residuals; a diagnostic
beside them (not an option): the correlation between conditions per pair of conditions instead of the pooled ρ_o
(the mean over common times of the pointwise sample correlation matrices, PSD), and the residual test with it.
Run: PYTHONPATH=/work/wt/xcov python results/archive/discrepancy/shared_realization/cache_blocks.py > .../cache_blocks.txt"""
import json
from pathlib import Path

import numpy as np

import sweep.discrepancy.forward as fwm
from solver import RunOptions
from sweep.discrepancy import stats
from sweep.discrepancy.data import load_measured
from sweep.discrepancy.forward import SolverForward, fine_forwards
from sweep.discrepancy.heldout import heldout_data
from sweep.discrepancy.noise import coarse_and_fines
from sweep.discrepancy.problem import Problem
from sweep.discrepancy.realization_blocks import _matched_points
from sweep.discrepancy.realizations import RealizationCovariance
from sweep.discrepancy.spec import spec_from_dict
from sweep.discrepancy.twins import load_twin_campaign


def _no(self, todo, code):
    raise RuntimeError(f"not cached: {list(todo)[:1]}")


fwm.SolverForward._run_batch = _no
CACHE = Path("/work/runs/xcov/cache_copy")          # a copy of /work/runs/twin10b/cache (the quiet run)
camp = load_twin_campaign("campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml")
spec = spec_from_dict(camp["spec"])
data = heldout_data(load_measured("/work/runs/twin10b/out/compliant_boundary_crn_kbar_cement/data"), spec)
fwd = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), CACHE / "workflow", n_jobs=1)
fine = fine_forwards(spec, CACHE / "workflow", 1)
pb = Problem(data, spec, fwd)
P = {"init": {"kbar": 0.0015, "effect:compliant_boundary": 0.0},
     "a1": {"kbar": 0.003821120498103685, "effect:compliant_boundary": 0.017642603850349752},
     "a2": {"kbar": 0.004038501580553543, "effect:compliant_boundary": 0.02022002713907446},
     "truth": {"kbar": 0.0018, "effect:compliant_boundary": 0.02}}
REPORT = "/work/runs/twin10b/out/compliant_boundary_crn_kbar_cement/report.json"
train = json.load(open(REPORT))["train"]                # the training conditions (the residual test's)
print("conditions", list(data.ids), "training", train)


def pair_matrix(fines, o):
    """Per pair of conditions of observable o: mean over common times of the sample correlation of the
    realizations' deviations (conditions in data.ids order)."""
    dev = fines - fines.mean(axis=0)
    rows = {c: np.flatnonzero((pb.cond == c) & (pb.obs == o)) for c in data.ids}
    rows = {c: r[np.argsort(pb.t[r])] for c, r in rows.items()}
    ids = list(data.ids)
    R = np.eye(len(ids))
    for a in range(len(ids)):
        for b in range(a + 1, len(ids)):
            ra, rb = rows[ids[a]], rows[ids[b]]
            i, j = _matched_points(pb.t[ra], pb.t[rb])
            da, db = dev[:, ra[i]], dev[:, rb[j]]
            den = np.sqrt(np.sum(da * da, axis=0) * np.sum(db * db, axis=0))
            R[a, b] = R[b, a] = np.mean(np.sum(da * db, axis=0)[den > 0] / den[den > 0])
    return R


def pairwise_cov(rc, fines):
    """rc's observable blocks with the kernel's ρ_o replaced by the per-pair matrix."""
    blocks = {}
    ids = list(data.ids)
    for g, (rows, C) in rc.blocks.items():
        o = str(pb.obs[rows[0]])
        R = pair_matrix(fines, o)
        ci = np.array([ids.index(c) for c in pb.cond[rows]])
        same = ci[:, None] == ci[None, :]
        rho = rc.rho_cond[o]
        base = np.where(same, C, C / rho)                 # √(v v) exp(−|Δt|/τ) on every pair
        blocks[g] = (rows, base * R[np.ix_(ci, ci)])
    return RealizationCovariance(blocks, rc.tau, rc.rho, rc.k, rc.layout, rc.window, mode="pairwise",
                                 rho_cond=rc.rho_cond, rho_cond_dof=rc.rho_cond_dof)


def residual_test(label, coarse):
    m = pb.mask(train)
    diff = (pb.noise.y - coarse)[m]
    r = pb.noise.standardize(diff, m, spec.fit.nan_residual)
    null = pb.noise.null_calibration(m, seed=spec.fit.seed)
    res = stats.systematic_test(r, pb.series[m], spec.acceptance.z_crit, spec.acceptance.rho_crit, null=null)
    flagged = {pb.series_names[int(k)]: (round(v["chi2_excess_z"], 2), round(v["mean_z"], 2))
               for k, v in res["series"].items() if v["systematic"]}
    zs = {pb.series_names[int(k)]: round(v["chi2_excess_z"], 2) for k, v in res["series"].items()}
    print(f"   {label}chi2 {r @ r:.1f} (n {r.size}) marginal deviance {pb.noise.marginal_deviance(r, m):.1f}; "
          f"systematic {flagged or 'none'}; chi2-excess z {zs}")
for name, vals in P.items():
    try:
        coarse, fines = coarse_and_fines(pb, fine, vals)
    except RuntimeError as exc:
        print(f"{name} {vals}: {exc}")
        continue
    err = np.where(np.isfinite(fines.mean(axis=0) - coarse), fines.mean(axis=0) - coarse, 0.0)
    for mode in ("series", "observable"):
        pb.noise.set_discretization(err, fines, 0.0, mode)
        rc = pb.noise.real_cov
        dofs = {str(g): round(rc.scale_dof(rows), 1) for g, (rows, _) in rc.blocks.items()}
        print(f"{name} {mode}: rho_o {({o: round(v, 3) for o, v in rc.rho_cond.items()})} dof "
              f"{({o: round(v, 1) for o, v in rc.rho_cond_dof.items()})} tau_s {({o: round(v, 4) for o, v in rc.tau.items()})}"
              f" blocks {list(map(str, rc.blocks))} scale dof {dofs}")
        if name == "init":
            continue
        residual_test("", coarse)
        if mode == "observable":
            for o in ("front_radius_mean", "p_inj"):
                R = pair_matrix(fines, o)
                print(f"   {o} per-pair correlation ({list(data.ids)}):\n{np.round(R, 3)}\n   eigenvalues "
                      f"{np.round(np.linalg.eigvalsh(R), 3)}")
            pb.noise.real_cov = pairwise_cov(rc, fines)
            pb.noise._attach()
            residual_test("per-pair correlation: ", coarse)
