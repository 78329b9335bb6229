"""Does a mesh refined where the cracks grow take the crack-row noise out of the long twins?  (issue #23 part 3)

The long twins fail because, after crack initiation, a new mesh realization moves the observables by more than the
damage viscosity beta does (``../long_bias/``).  This probe runs the long_floor campaign's base at w_i = 50 mm/s
(porosity floor 0.1, observation times 0.02-2 s x 40) on four mesh families, each at beta = 60 and 35 kPa.s:

    U3  h = 3 uniform, dt_max 0.01 s         (the correction's fine realizations; seeds 1-6 and the data's 11)
    T3  h = 3, h_inner = 1, graded over 15 mm, dt_max 0.01 s  (same seeds)
    U4  h = 4 uniform, dt_max 0.02 s         (the workflow's coarse model; seeds 1-3 and the default mesh)
    T4  h = 4, h_inner = 1.5, graded over 15 mm, dt_max 0.02 s (same seeds)

and, added after the first four showed that the cavity refinement leaves the scatter (``README.md``), the outer
wall graded (h_outer = 0.5 mm: W3, W4, as U3, U4), a finer uniform mesh (U2: h = 2, dt_max 0.01 s, seeds of U3)
and, once those showed the same scatter, the paper's mesh-independent porosity field (three pockets, Sec. 3.4)
instead of its per-element random one (P3, P4, as U3, U4): the random field is drawn per element, so a new mesh
realization is also a new draw of the heterogeneity, at the element's length scale.

It reports, in units of the twin's measurement noise (2 kPa, 0.2 mm, 0.5 mm), RMS over the times t >= 1 s (after
initiation): the realization scatter (the sd over seeds), beta's signal (the seed-mean difference 60 - 35), their
ratio, the data seed 11's distance from the other six (in their sd), and how much the discretization correction
(fine mean minus coarse default mesh) changes between beta = 35 and 60.  Units mm, s, kPa.

    python results/archive/discrepancy/tip_refined/probe.py CACHE OUT.json [--jobs 2]   # the runs, then the tables
    python results/archive/discrepancy/tip_refined/probe.py --tables OUT.json            # the tables from OUT.json
"""
import json
import sys
from pathlib import Path

import numpy as np

from solver import RunOptions
from sweep.discrepancy.forward import SolverForward
from sweep.discrepancy.spec import spec_from_dict
from sweep.discrepancy.twins import load_twin_campaign

CAMP = load_twin_campaign(Path(__file__).resolve().parents[3] / "campaigns" / "discrepancy" / "discrepancy_twins_long_floor.toml")
SPEC = spec_from_dict(CAMP["spec"])
A, B, N = CAMP["data"]["times"]
TIMES = np.linspace(A, B, N)
OBS = CAMP["data"]["observables"]
NOISE = CAMP["data"]["noise"]
BETAS = (60.0, 35.0)
FAMILIES = {  # name: (run options, mesh seeds; None = the default mesh[, parameter overrides])
    "U3": (dict(h=3.0, dt_max=0.01, t_end=2.0), (1, 2, 3, 4, 5, 6, 11)),
    "T3": (dict(h=3.0, h_inner=1.0, inner_grading_length=15.0, dt_max=0.01, t_end=2.0), (1, 2, 3, 4, 5, 6, 11)),
    "U4": (dict(h=4.0, dt_max=0.02, t_end=2.0), (None, 1, 2, 3)),
    "T4": (dict(h=4.0, h_inner=1.5, inner_grading_length=15.0, dt_max=0.02, t_end=2.0), (None, 1, 2, 3)),
    "W3": (dict(h=3.0, h_outer=0.5, dt_max=0.01, t_end=2.0), (1, 2, 3, 4, 5, 6, 11)),
    "W4": (dict(h=4.0, h_outer=0.5, dt_max=0.02, t_end=2.0), (None, 1, 2, 3)),
    "U2": (dict(h=2.0, dt_max=0.01, t_end=2.0), (1, 2, 3, 4, 5, 6, 11)),
    "P3": (dict(h=3.0, dt_max=0.01, t_end=2.0), (1, 2, 3, 4, 5, 6, 11), {"porosity_field": "pockets"}),
    "P4": (dict(h=4.0, dt_max=0.02, t_end=2.0), (None, 1, 2, 3), {"porosity_field": "pockets"}),
}
LATE = TIMES >= 1.0


def run(cache: Path, jobs: int) -> dict:
    """{family: {seed: {beta: {observable: curve}}}}, each (family, seed) pair's two betas run side by side."""
    curves: dict = {}
    for fam, (opts, seeds, *over) in FAMILIES.items():
        for seed in seeds:
            o = RunOptions.from_dict({**opts, **({} if seed is None else {"mesh_seed": seed})})
            fwd = SolverForward({**SPEC.baseline_overrides(), **(over[0] if over else {})}, o, cache, n_jobs=jobs)
            preds = fwd.predict_many([({"beta": b, "w_i": 50.0}, {k: TIMES for k in OBS}) for b in BETAS])
            curves.setdefault(fam, {})[str(seed)] = {
                str(b): {k: np.asarray(p[k], float).tolist() for k in OBS} for b, p in zip(BETAS, preds)}
            print(fam, seed, {str(b): round(float(np.asarray(p["crack_length"])[-1]), 2)
                              for b, p in zip(BETAS, preds)}, flush=True)
    return curves


def _rms(v, o) -> float:
    """RMS over t >= 1 s in noise units of observable o."""
    return float(np.sqrt(np.nanmean((np.asarray(v)[LATE] / NOISE[o]) ** 2)))


def tables(curves: dict) -> dict:
    """Scatter, signal, their ratio, seed 11's leave-out distance and the correction's beta-dependence per family."""
    arr = {f: {s: {b: {o: np.asarray(c, float) for o, c in bc.items()} for b, bc in sc.items()}
               for s, sc in fc.items()} for f, fc in curves.items()}
    out = {}
    for fam, by_seed in arr.items():
        train = [s for s in by_seed if s != "11"]
        row = {}
        for o in OBS:
            stack = {b: np.array([by_seed[s][b][o] for s in train]) for b in ("60.0", "35.0")}
            sd = np.sqrt(0.5 * sum(np.nanvar(stack[b], axis=0, ddof=1) for b in stack))
            signal = np.nanmean(stack["60.0"], 0) - np.nanmean(stack["35.0"], 0)
            r = {"scatter": _rms(sd, o), "signal": _rms(signal, o)}
            r["signal_over_scatter"] = r["signal"] / r["scatter"]
            if "11" in by_seed:
                d = by_seed["11"]["60.0"][o] - np.nanmean(stack["60.0"], 0)
                r["seed11_distance_in_sd"] = float(np.sqrt(np.nanmean((d[LATE] / sd[LATE]) ** 2)))
            r["final_mean_beta60"] = float(np.nanmean(stack["60.0"][:, -1]))
            r["final_sd_beta60"] = float(np.nanstd(stack["60.0"][:, -1], ddof=1))
            row[o] = r
        out[fam] = row
    for fine, coarse in (("U3", "U4"), ("T3", "T4"), ("W3", "W4"), ("P3", "P4")):
        ch = {}
        for o in OBS:
            def corr(b):
                return np.nanmean([arr[fine][s][b][o] for s in arr[fine] if s != "11"], 0) - arr[coarse]["None"][b][o]
            ch[o] = _rms(corr("60.0") - corr("35.0"), o)
        out[f"correction_change_{fine}-{coarse}"] = ch
    for k, v in out.items():
        print(k, json.dumps(v, default=lambda x: round(x, 3)))
    return out


if __name__ == "__main__":
    if sys.argv[1] == "--tables":
        doc = json.loads(Path(sys.argv[2]).read_text())
        doc["tables"] = tables(doc["curves"])
        Path(sys.argv[2]).write_text(json.dumps(doc, indent=1))
    else:
        jobs = int(sys.argv[sys.argv.index("--jobs") + 1]) if "--jobs" in sys.argv else 1
        c = run(Path(sys.argv[1]), jobs)
        doc = {"noise": NOISE, "times": TIMES.tolist(), "families": {k: v[0] for k, v in FAMILIES.items()},
               "curves": c, "tables": tables(c)}
        Path(sys.argv[2]).write_text(json.dumps(doc, indent=1))
