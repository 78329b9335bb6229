"""Does the correction's time step explain the long twins' low beta?  The data mesh (h = 3, seed 11) at the
correction's step dt_max = 0.01 s with beta = B, against the data (dt_max = 0.005 s, beta = 60) of
results/archive/discrepancy/long_bias/probe.json: RMS difference over the 40 times in noise units per observable.

    python results/archive/discrepancy/long_bias/time_step.py BETA DT_MAX CACHE      # prints one JSON line
"""
import json
import sys
from pathlib import Path
import numpy as np
sys.path.insert(0, str(Path(__file__).resolve().parent))
import probe
from solver import RunOptions
from sweep.discrepancy.forward import SolverForward
beta = float(sys.argv[1]); dt = float(sys.argv[2])
ref = json.load(open(Path(__file__).resolve().parent / "probe.json"))
fwd = SolverForward(probe.SPEC.baseline_overrides(), RunOptions.from_dict({**probe.DATA, "dt_max": dt}), Path(sys.argv[3]), n_jobs=1)
pred = fwd.predict_one({"beta": beta, "w_i": 50.0}, {o: probe.TIMES for o in probe.OBS})
out = {}
for o in probe.OBS:
    a = np.asarray(pred[o], float); b = np.asarray(ref["curves"]["data beta60"][o], float)
    out[o] = float(np.sqrt(np.nanmean(((a - b) / probe.NOISE[o]) ** 2)))
print(json.dumps({"beta": beta, "dt_max": dt, "rms_noise_units_vs_data_beta60": out, "last": {o: float(np.asarray(pred[o])[-1]) for o in probe.OBS}}))
