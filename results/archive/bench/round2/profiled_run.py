import sys, json, time
from solver import Parameters, RunOptions, simulate
h = float(sys.argv[1]); t_end = float(sys.argv[2]); out = sys.argv[3]
kw = dict(a.split("=") for a in sys.argv[4:])
kw = {k: (int(v) if v.isdigit() else float(v)) for k, v in kw.items()}
res = simulate(Parameters(), RunOptions(h=h, t_end=t_end, snapshot_times=[], **kw))
ts = res.timeseries
tot = res.profile["total"]
json.dump({"kw": kw, "wall": res.wall_time, "steps": len(ts), "rejected": len(res.rejected_steps), "fact": res.factorizations,
           "seconds": tot["seconds"], "calls": tot["calls"], "counters": tot["counters"],
           "t": ts["t"].tolist(), "p_inj": ts["p_inj"].tolist()}, open(out, "w"))
print(out, "wall", round(res.wall_time, 1), tot["counters"], "fact", res.factorizations)
