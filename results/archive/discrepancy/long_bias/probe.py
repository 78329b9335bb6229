"""Where does the long damage-viscosity twin's low beta come from?  One condition (w_i = 50 mm/s), the twin
campaign's base and observation times; each pair of runs differs in one setting, and the difference of their
observables is printed in units of the twin's measurement noise (RMS over the 40 times).  Units mm, s, kPa.

    python results/archive/discrepancy/long_bias/probe.py CACHE OUT.json      # the runs, then the tables
    python results/archive/discrepancy/long_bias/probe.py --tables OUT.json    # the tables again from OUT.json

CACHE: a folder of forward-run caches (run folders keyed by parameters and options; the twin campaign's own
data cache is reused when given).
"""
import json
import sys
from pathlib import Path

import numpy as np

from solver import RunOptions
from sweep.discrepancy.forward import SolverForward
from sweep.discrepancy.spec import spec_from_dict
from sweep.discrepancy.twins import load_twin_campaign

CAMP = load_twin_campaign(Path(__file__).resolve().parents[3] / "campaigns" / "discrepancy" / "discrepancy_twins_long.toml")
SPEC = spec_from_dict(CAMP["spec"])
A, B, N = CAMP["data"]["times"]
TIMES = np.linspace(A, B, N)
OBS = CAMP["data"]["observables"]
NOISE = CAMP["data"]["noise"]
DATA = dict(h=3.0, mesh_seed=11, dt_max=0.005, t_end=2.0)
COARSE = dict(h=4.0, t_end=2.0, dt_max=0.02)
FINE = dict(h=3.0, t_end=2.0, dt_max=0.01)

# (name, run options, parameter overrides)
RUNS = [
    ("data beta60", DATA, {"beta": 60.0}),
    ("data dt0.01 beta60", {**DATA, "dt_max": 0.01}, {"beta": 60.0}),
    ("data beta35", DATA, {"beta": 35.0}),
    ("fine seed1 beta60", {**FINE, "mesh_seed": 1}, {"beta": 60.0}),
    ("coarse beta60", COARSE, {"beta": 60.0}),
    ("coarse beta35", COARSE, {"beta": 35.0}),
    ("coarse beta35 E352", COARSE, {"beta": 35.0, "E": 351.9}),
]
PAIRS = [("time step 0.005 -> 0.01 s (data mesh)", "data beta60", "data dt0.01 beta60"),
         ("beta 60 -> 35 (data mesh and step)", "data beta60", "data beta35"),
         ("mesh seed 11 -> 1 (h = 3, beta 60; step 0.005 -> 0.01)", "data beta60", "fine seed1 beta60"),
         ("beta 60 -> 35 (coarse)", "coarse beta60", "coarse beta35"),
         ("beta 60 -> 35, E 331 -> 351.9 (coarse)", "coarse beta60", "coarse beta35 E352")]


def main(cache, out):
    cond = {"w_i": 50.0}
    preds = {}
    for name, opts, over in RUNS:
        fwd = SolverForward(SPEC.baseline_overrides(), RunOptions.from_dict(opts), Path(cache), n_jobs=1)
        preds[name] = fwd.predict_one({**over, **cond}, {o: TIMES for o in OBS})
        print(name, {o: float(np.asarray(preds[name][o])[-1]) for o in OBS}, flush=True)
    curves = {k: {o: np.asarray(v[o], float).tolist() for o in OBS} for k, v in preds.items()}
    res = {"condition": cond, "noise": NOISE, "times": TIMES.tolist(), **tables(curves), "curves": curves}
    Path(out).write_text(json.dumps(res, indent=1))


def _rms(v: np.ndarray, o: str, sel=slice(None)) -> float:
    """RMS of a difference of curves over the observation times ``sel``, in noise units of observable o."""
    return float(np.sqrt(np.nanmean((np.asarray(v)[sel] / NOISE[o]) ** 2)))


def tables(curves: dict) -> dict:
    """The pairs' differences and the change of the correction (data mesh minus coarse) from beta 35 to 60,
    beside beta's signal on each mesh: RMS in noise units over all times, t < 1 s and t >= 1 s."""
    g = {k: {o: np.asarray(v, float) for o, v in c.items()} for k, c in curves.items()}
    pairs = {}
    for label, a, b in PAIRS:
        pairs[label] = {o: _rms(g[b][o] - g[a][o], o) for o in OBS}
        print(f"{label}: " + ", ".join(f"{k} {v:.3g}" for k, v in pairs[label].items()))
    late = TIMES >= 1.0
    corr = {}
    for o in OBS:
        d60, d35, c60, c35 = (g[k][o] for k in ("data beta60", "data beta35", "coarse beta60", "coarse beta35"))
        series = {"correction change": (d60 - c60) - (d35 - c35), "beta signal, data mesh": d60 - d35,
                  "beta signal, coarse": c60 - c35}
        corr[o] = {k: {"all": _rms(v, o), "t<1": _rms(v, o, ~late), "t>=1": _rms(v, o, late)} for k, v in series.items()}
        print(o, {k: {w: round(x, 2) for w, x in v.items()} for k, v in corr[o].items()})
    return {"rms_difference_in_noise_units": pairs, "correction_change_beta_35_60": corr}


if __name__ == "__main__":
    if sys.argv[1] == "--tables":
        doc = json.loads(Path(sys.argv[2]).read_text())
        doc.update(tables(doc["curves"]))
        Path(sys.argv[2]).write_text(json.dumps(doc, indent=1))
    else:
        main(*sys.argv[1:3])
