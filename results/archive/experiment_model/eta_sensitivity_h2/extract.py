"""One-off (archived): p_inj at 1, 1.7 and 2 s of every run of the eta line's store that reached the time, and
d ln p_inj / d ln eta_o between neighbouring eta_o at each C (issue #47's target >= 0.3 at 2 s).  Reads the run
folders (record.json, timeseries.csv), which are not committed; writes p_inj.csv and slopes.csv here.
Usage: python extract.py STORE/experiment_ca_star_eta_line.  Units: kPa, s, eta_o kPa*s, C %."""
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

TIMES = (1.0, 1.7, 2.0)  # s: the experiment's measured pressures' times
rows = []
for d in sorted((Path(sys.argv[1]) / "runs").iterdir()):
    if d.name.startswith(".") or not (d / "timeseries.csv").is_file():
        continue
    rec = json.loads((d / "record.json").read_text())
    ts = pd.read_csv(d / "timeseries.csv")
    row = {"cement": rec["params"]["cement"], "eta_o": rec["params"]["eta_o"], "status": rec["status"],
           "t_reached": float(ts["t"].iloc[-1]), "key": d.name}
    for t in TIMES:
        row[f"p_inj_{t:g}s"] = float(np.interp(t, ts["t"], ts["p_inj"])) if ts["t"].iloc[-1] >= t else np.nan
    rows.append(row)
p = pd.DataFrame(rows).sort_values(["cement", "eta_o"])
p.to_csv("p_inj.csv", index=False, float_format="%.6g")
slopes = []
for c, g in p.groupby("cement"):
    g = g.sort_values("eta_o")
    for (_, a), (_, b) in zip(g.iloc[:-1].iterrows(), g.iloc[1:].iterrows()):
        s = {"cement": c, "eta_o_lo": a["eta_o"], "eta_o_hi": b["eta_o"], "statuses": f"{a['status']}/{b['status']}"}
        for t in TIMES:
            s[f"dlnp_dlneta_{t:g}s"] = np.log(b[f"p_inj_{t:g}s"] / a[f"p_inj_{t:g}s"]) / np.log(b["eta_o"] / a["eta_o"])
        slopes.append(s)
pd.DataFrame(slopes).to_csv("slopes.csv", index=False, float_format="%.4g")
print(p.to_string(index=False)); print(pd.DataFrame(slopes).to_string(index=False))
