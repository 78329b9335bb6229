"""Is the long twins' low beta the data's mesh realization?  The data (h = 3, seed 11, dt_max = 0.005 s, beta = 60,
w_i = 50 mm/s, the long_floor campaign's base) against the mean of the correction's six fine realizations (h = 3,
seeds 1-6, dt_max = 0.01 s) at beta = 60 and at the twin's refit 37.3: RMS difference over the 40 times in noise
units per observable, and the seed-to-seed spread.

    python results/archive/discrepancy/long_bias/realizations.py CACHE data OUT_data.json     # the data run
    python results/archive/discrepancy/long_bias/realizations.py CACHE 60 OUT_60.json         # six realizations at beta = 60
    python results/archive/discrepancy/long_bias/realizations.py CACHE 37.3 OUT_37.3.json     # and at 37.3

realizations.json holds the comparison (made from the three outputs).
"""
import json
import sys
from pathlib import Path
import numpy as np
from solver import RunOptions
from sweep.discrepancy.forward import SolverForward
from sweep.discrepancy.spec import spec_from_dict
from sweep.discrepancy.twins import load_twin_campaign
camp = load_twin_campaign(Path(__file__).resolve().parents[3] / "campaigns" / "discrepancy" / "discrepancy_twins_long_floor.toml")
spec = spec_from_dict(camp["spec"])
a, b, n = camp["data"]["times"]; times = np.linspace(a, b, n)
obs = camp["data"]["observables"]; noise = camp["data"]["noise"]
cache = Path(sys.argv[1]); which = sys.argv[2]
def pred(opts, beta):
    f = SolverForward(spec.baseline_overrides(), RunOptions.from_dict(opts), cache, n_jobs=1)
    p = f.predict_one({"beta": beta, "w_i": 50.0}, {o: times for o in obs})
    return {o: np.asarray(p[o], float).tolist() for o in obs}
out = {}
if which == "data":
    out["data"] = pred(dict(h=3.0, mesh_seed=11, dt_max=0.005, t_end=2.0), 60.0)
else:
    beta = float(which)
    for s in range(1, 7):
        out[f"seed{s}"] = pred(dict(h=3.0, mesh_seed=s, dt_max=0.01, t_end=2.0), beta)
        print(s, flush=True)
Path(sys.argv[3]).write_text(json.dumps(out))
