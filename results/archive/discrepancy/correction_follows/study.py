"""k̄'s bias with the profile's linear correction following the strength alone or every fitted parameter
(``[profile] correction_follows``), over several noise and mesh-realization draws of the toy twin of
tests/test_discrepancy_crn.py::test_a_correction_that_follows_the_calibrated_parameter_removes_its_bias.

The twin: MeshToy (sweep/discrepancy/toy.py) set-up kbar_cement_beta (k̄ calibrated, cement 0.6/1.2/2.4 for
training, 1.8 held out, damage viscosity the only candidate), hidden β = 50 kPa·s and k̄ = 0.0045 mm² (the
spec's initial k̄ 0.0015), discretization coefficients x``--bias`` (40), realization deviations x``--spread``;
data from mesh realization 1000·draw (h = 2 mm) with the coverage study's noise, the workflow on h = 4 mm with
three other realizations as its fine check; the library's settings but disc_error_fraction = 0 and the
Gaussian profile likelihood with correction = "linear".  Per draw and mode: the named k̄ and β, β's interval.

    python results/archive/discrepancy/correction_follows/study.py --draws 8 --out results/discrepancy/correction_follows/summary.json
"""
import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sweep.discrepancy.coverage import NOISE, SETUPS, TIMES, _spec
from sweep.discrepancy.data import load_measured
from sweep.discrepancy.toy import MeshToy
from sweep.discrepancy.twin import make_twin
from sweep.discrepancy.workflow import calibrate, finalize, prepare, search

SU = next(s for s in SETUPS if s.name == "kbar_cement_beta")
TRUTH = {"beta": 50.0, "volumetric_coupling": 0.0, "kbar": 0.0045}


def one(draw: int, follows: str, bias: float, spread: float) -> dict:
    base = 1000 * (draw + 1)
    with tempfile.TemporaryDirectory() as tmp:
        data = load_measured(make_twin(Path(tmp) / "d", MeshToy(2.0, base, spread, bias), SU.conditions(), TIMES,
                                       TRUTH, noise=NOISE, seed=base, observables=tuple(NOISE), regime=False))
    fines = [MeshToy(2.0, base + 1 + i, spread, bias) for i in range(3)]
    tables = {"noise": {"disc_error_fraction": 0.0},
              "profile": {"likelihood": "gaussian", "correction": "linear", "correction_follows": follows}}
    t0 = time.process_time()
    run = prepare(data, _spec(SU, tables), MeshToy(4.0, 0, spread, bias), fines)
    calibrate(run)
    search(run)
    row = {"draw": draw, "follows": follows, "named": bool(run.accepted)}
    if run.accepted:
        finalize(run)
        v, a = run.current.values(), run.accepted[0]
        row.update({"verdict": run.verdict, "kbar": float(v["kbar"]), "beta": float(a["strength"]),
                    "beta_interval": [float(b) for b in a["strength_interval"]],
                    "beta_covered": bool(a["strength_interval"][0] <= TRUTH["beta"] <= a["strength_interval"][1]),
                    "log10_kbar_error": math.log10(v["kbar"] / TRUTH["kbar"])})
    row["coarse_runs"] = int(sum(s["coarse"] for s in run.ledger.stages.values()))
    row["fine_runs"] = int(sum(s["fine"] for s in run.ledger.stages.values()))
    row["cpu_s"] = time.process_time() - t0
    return row


def summary(rows: list) -> dict:
    out = {}
    for follows in ("strength", "all"):
        r = [q for q in rows if q["follows"] == follows and "kbar" in q]
        e = np.array([q["log10_kbar_error"] for q in r])
        b = np.array([q["beta"] - TRUTH["beta"] for q in r])
        out[follows] = {"named": len(r), "draws": sum(q["follows"] == follows for q in rows),
                        "log10_kbar_bias": float(e.mean()), "log10_kbar_sd": float(e.std(ddof=1)),
                        "log10_kbar_bias_se": float(e.std(ddof=1) / math.sqrt(len(e))),
                        "beta_bias": float(b.mean()), "beta_sd": float(b.std(ddof=1)),
                        "beta_covered": sum(q["beta_covered"] for q in r),
                        "verdicts": {v: sum(q["verdict"] == v for q in r) for v in {q["verdict"] for q in r}},
                        "median_coarse_runs": float(np.median([q["coarse_runs"] for q in r])),
                        "median_fine_runs": float(np.median([q["fine_runs"] for q in r]))}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, default=8)
    ap.add_argument("--bias", type=float, default=40.0)
    ap.add_argument("--spread", type=float, default=1.0)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    rows = []
    for d in range(a.draws):
        for follows in ("strength", "all"):
            rows.append(one(d, follows, a.bias, a.spread))
            print(json.dumps(rows[-1]), flush=True)
    res = {"setup": SU.name, "truth": TRUTH, "bias": a.bias, "spread": a.spread, "rows": rows, "summary": summary(rows)}
    tmp = Path(a.out).with_suffix(".tmp")
    tmp.write_text(json.dumps(res, indent=1))
    tmp.replace(a.out)
    print(json.dumps(res["summary"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
