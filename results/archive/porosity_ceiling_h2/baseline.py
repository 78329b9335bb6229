"""The baseline of campaigns/studies/porosity_ceiling_h2.toml (its point and options without a ceiling) rerun on this code,
as the quantities of sweep.studies.closure, printed as JSON (units mm, s, kPa).

    python results/archive/porosity_ceiling_h2/baseline.py > baseline_current_code.json
"""
import json, sys

import pandas as pd
from solver import Parameters, RunOptions, simulate
from sweep.studies.closure import series_row
p = Parameters(eta_w=1e-6, kbar=0.0015, w_i=50.0, eta_o=0.29, cement=1.5, porosity_floor=0.1)
o = RunOptions(h=2.0, h_outer=0.25, pressure_stabilization=1.0, t_end=4.0, stop_front_radius=45.0, snapshot_times=[2.0], write_xdmf=False)
r = simulate(p, o)
ts = r.timeseries
print(json.dumps({"status": r.status, "wall_s": r.wall_time, **series_row(ts, p.r_inner, float(ts["t"].iloc[-1]))}))
