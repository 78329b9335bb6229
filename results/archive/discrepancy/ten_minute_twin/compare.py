import json, statistics as S
A = "wander_crn_marginal_emulator_refits"
B = "wander_crn_marginal_emulator_refits_no_refresh_2anchors"
def rows(v):
    return {r["draw"]: r for r in (json.loads(l) for l in open(f"/work/runs/t53/cov/{v}.log") if l.startswith("{\"setup\""))}
a, b = rows(A), rows(B)
common = sorted(set(a) & set(b))
def tot(r, k=None):
    return sum(x["coarse"] + x["fine"] for x in r["runs_by_stage"].values()) if k is None else sum(x[k] for x in r["runs_by_stage"].values())
out = {"draws": common}
for name, R in ((A, a), (B, b)):
    rr = [R[d] for d in common]
    out[name] = {"named": sum(r["verdict"] == "named" for r in rr), "covered": sum(bool(r.get("covered")) for r in rr),
                 "runs_median": S.median(tot(r) for r in rr), "runs_range": [min(tot(r) for r in rr), max(tot(r) for r in rr)],
                 "fine_median": S.median(tot(r, "fine") for r in rr),
                 "bias_sd": [round(S.mean((r["strength"] - r["truth"]) / ((r["upper"] - r["lower"]) / 3.92) for r in rr), 2)]}
dl = [abs(a[d]["lower"] - b[d]["lower"]) / (a[d]["upper"] - a[d]["lower"]) for d in common]
du = [abs(a[d]["upper"] - b[d]["upper"]) / (a[d]["upper"] - a[d]["lower"]) for d in common]
ds = [abs(a[d]["strength"] - b[d]["strength"]) / ((a[d]["upper"] - a[d]["lower"]) / 3.92) for d in common]
out["ends_diff_over_width"] = {"median": round(S.median(dl + du), 4), "max": round(max(dl + du), 4)}
out["strength_diff_over_sd"] = {"median": round(S.median(ds), 3), "max": round(max(ds), 3)}
out["rebuilt"] = [d for d in common if tot(b[d], "fine") > 72]
print(json.dumps(out, indent=1))
json.dump(out, open("/work/runs/t53/cov/compare.json", "w"), indent=1)
