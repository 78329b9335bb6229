import json, sys, numpy as np
from importlib import import_module
from solver import Parameters, RunOptions
from sweep.cli import _load_config
sm = import_module("solver.simulate"); st = import_module("solver.stagger")
pdict, odict = _load_config("config.toml"); odict["frames"] = 20
params, options = Parameters.from_dict(pdict), RunOptions.from_dict(odict)
sim = sm._setup(params, options, None, None)
z = np.load(sys.argv[1]); ck = json.loads(str(z["state"]))
sim.U, sim.d, sim.t = z["U"], z["d"], ck["t"]
sim.previous = (z["previous_U"], z["previous_d"], ck["previous_dt"]) if "previous_U" in z.files else None
pts = sim.disc.points
print("t", sim.t, "fields", sim.disc.n_fields, "S col", st.S)
for dt in [float(a) for a in sys.argv[2:]]:
    try:
        sim.step(dt); print("dt", dt, "ok")
    except st.StepFailure as e:
        n = e.node; r = np.hypot(*pts[n]); th = np.degrees(np.arctan2(pts[n][1], pts[n][0]))
        print("dt", dt, "FAIL", e, "node", n, "r %.2f theta %.1f" % (r, th), "S %.3f d %.3f" % (sim.U[n, st.S], sim.d[n]))
        near = np.hypot(*(pts - pts[n]).T) < 3.0
        print("  within 3 mm: S [%.3f, %.3f], d [%.3f, %.3f], p [%.1f, %.1f]" % (sim.U[near, st.S].min(), sim.U[near, st.S].max(), sim.d[near].min(), sim.d[near].max(), sim.U[near, st.P].min(), sim.U[near, st.P].max()))
r = np.hypot(*pts.T)
print("state: S>0.5 max r %.2f; d>0.9 count %d; d>0.5 r range [%.1f, %.1f]" % (r[sim.U[:, st.S] > 0.5].max(), (sim.d > 0.9).sum(), r[sim.d > 0.5].min(), r[sim.d > 0.5].max()))
# the elements around the failing node of the last step tried (node 1106 at dt 4.8e-4 from the 2.2923 s state)
from solver.model import element_fields  # noqa: E402
ef = element_fields(sim.disc, sim.params, sim.U, sim.d, fluxes=True)
tri = sim.disc.triangles
for node in (1106,):
    around = np.any(tri == node, axis=1)
    print("node", node, "r %.2f" % np.hypot(*pts[node]), {k: "[%.3g, %.3g]" % (ef[k][around].min(), ef[k][around].max())
                                                      for k in ("phi", "k", "w1_mag") if k in ef})
print("domain median: ", {k: "%.3g" % np.median(ef[k]) for k in ("phi", "k", "w1_mag") if k in ef})
