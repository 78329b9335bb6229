"""An estimate of what ``[profile] correction_follows = "all"`` would change on the ten-minute twin (issue #53),
from its quiet run's cache (read from a copy) and 28 new solver runs; not a run of the workflow.

The quiet run (results/discrepancy/README.md, "Ten minutes") named outer compliance 0.01893 mm/kPa with
k̄ = 0.00396 mm² (truth 0.02 and 0.0018).  Its cache holds the correction (six h = 3 mm realizations minus the
h = 4 mm model) at three points: the initial baseline A0 (k̄ 0.0015, compliance off) and the profile's two strength
anchors A1, A2 (compliance 0.01764 and 0.02022, k̄ refitted there: 0.00382, 0.00404).  A1 and A2 differ little in
k̄, and A0 lies nearly on their line, so a third anchor A3 is run at A1's compliance with k̄ displaced by
−0.15 decades (0.0027: toward the baseline's k̄, not the truth), three of the six realizations carrying A1's
mean to it (``correction_slope_realizations`` = 3: 4 coarse + 12 fine runs).  The plane through A1, A2, A3 in
(log10 k̄, compliance) is the "all" model; the line through A1, A2 the run's own ("strength").  A0 is kept out
as a check of the plane's reach.  Under each model the marginal deviance of the training rows (the run's noise
model: the realization covariance of A0's realizations, ``likelihood = "marginal"``) is evaluated at the named
fit, at the truth and at k̄ 0.0018, 0.0023, 0.003 with the named compliance (3 coarse runs each): the named
compliance's conditional optimum of k̄ under each model is the minimum of a quadratic in log10 k̄ through
those points and the fit's.

    nice -n 10 python results/discrepancy/correction_follows/ten_minute_estimate.py CACHE_COPY OUT.json
"""
import json
import logging
import math
import sys
import tomllib
from pathlib import Path

import numpy as np

from solver import RunOptions
from sweep.discrepancy.data import load_measured
from sweep.discrepancy.forward import SolverForward, fine_forwards
from sweep.discrepancy.heldout import heldout_data
from sweep.discrepancy.noise import add_discretization_error, coarse_and_fines, correction_from
from sweep.discrepancy.problem import Problem
from sweep.discrepancy.profile import StrengthCorrection
from sweep.discrepancy.spec import spec_from_dict
from sweep.discrepancy.twins import load_twin_campaign

DATA = "/work/runs/twin10b/out/compliant_boundary_crn_kbar_cement/data"
CAMPAIGN = "campaigns/discrepancy/discrepancy_coverage_crn_kbar_cement.toml"
NAMED = {"kbar": 0.00395682311306126, "effect:compliant_boundary": 0.018931315494712105}
TRUTH = {"kbar": 0.0018, "effect:compliant_boundary": 0.02}
TRAIN = ["c06", "c12", "c24"]


def cached_anchors(cache: Path) -> list:
    """The (kbar, outer compliance) of the fine (h = 3) points in the cache with all 24 runs, by k̄."""
    pts = {}
    for d in (cache / "workflow").iterdir():
        if not (d / "params.toml").exists():
            continue
        p, o = (tomllib.load(open(d / f, "rb")) for f in ("params.toml", "options.toml"))
        if o["h"] == 3.0:
            k = (p["kbar"], p["outer_compliance"])
            pts[k] = pts.get(k, 0) + 1
    return sorted(k for k, n in pts.items() if n == 24)


def main(cache: Path, out: Path) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", datefmt="%H:%M:%S")
    spec = spec_from_dict(load_twin_campaign(CAMPAIGN)["spec"])
    data = heldout_data(load_measured(DATA), spec)
    fwd = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(spec.options), cache / "workflow", n_jobs=2)
    fine = fine_forwards(spec, cache / "workflow", 2)
    pb = Problem(data, spec, fwd)
    params = tuple(spec.calibrate) + (spec.candidate_param("compliant_boundary"),)
    add_discretization_error(pb, fine, {p.name: p.initial for p in spec.calibrate})     # A0: cached
    a0, a1, a2 = cached_anchors(cache)
    vals = [{"kbar": k, "effect:compliant_boundary": c} for k, c in (a1, a2)]
    runs0 = (fwd.n_runs, sum(f.n_runs for f in fine))
    corr, fines1 = [], None
    for v in vals:
        coarse, fs = coarse_and_fines(pb, fine, v)
        corr.append(correction_from(coarse, fs))
        fines1 = fs if fines1 is None else fines1
    v3 = {"kbar": a1[0] * 10 ** -0.15, "effect:compliant_boundary": a1[1]}
    coarse, fs = coarse_and_fines(pb, fine[:3], v3)
    corr.append(correction_from(coarse, fs, ref=fines1))
    vals.append(v3)
    c0 = correction_from(*coarse_and_fines(pb, fine, {"kbar": a0[0], "effect:compliant_boundary": a0[1]}))
    X = np.array([[p.to_x(v[p.name]) for p in params] for v in vals])
    models = {"all": StrengthCorrection(X, corr, params=params, strength=1),
              "strength": StrengthCorrection(X[:2, 1], corr[:2], params=(params[1],))}
    res = {"anchors": vals, "A0": {"kbar": a0[0], "outer_compliance": a0[1]},
           "plane_miss_at_A0_rms": float(np.sqrt(np.mean((models["all"]({"kbar": a0[0], "effect:compliant_boundary": a0[1]}) - c0) ** 2))),
           "A0_change_rms": float(np.sqrt(np.mean((c0 - corr[0]) ** 2))),
           "slope_per_decade_kbar_rms": float(np.sqrt(np.mean(models["all"].B[0] ** 2)))}
    mask = pb.mask(TRAIN)
    points = {"named": NAMED, "truth": TRUTH}
    for k in (0.0018, 0.0023, 0.003):
        points[f"kbar_{k}"] = {"kbar": k, "effect:compliant_boundary": NAMED["effect:compliant_boundary"]}
    xs = [np.array([p.to_x(v[p.name]) for p in params]) for v in points.values()]
    pb.residual_batch(params, xs, TRAIN)                     # one batch of the new coarse runs
    for name, model in models.items():
        dev = {}
        for (label, v), x in zip(points.items(), xs):
            with pb.noise.following(model):
                r = pb.residual_batch(params, [x], TRAIN)[0]
            dev[label] = {"chi2": float(r @ r), "marginal_deviance": pb.noise.marginal_deviance(r, mask)}
        scan = [(math.log10(v["kbar"]), dev[l]["marginal_deviance"]) for l, v in points.items() if l != "truth"]
        q = np.polyfit([s[0] for s in scan], [s[1] for s in scan], 2)
        res[name] = {"deviance": dev, "quadratic_in_log10_kbar": q.tolist(),
                     "conditional_optimum_kbar": float(10 ** (-q[1] / (2 * q[0]))) if q[0] > 0 else None}
        logging.info("%s: %s", name, json.dumps(res[name]))
    res["new_runs"] = {"coarse": fwd.n_runs - runs0[0], "fine": sum(f.n_runs for f in fine) - runs0[1]}
    out.write_text(json.dumps(res, indent=1, default=float))
    print(json.dumps(res, indent=1, default=float))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
