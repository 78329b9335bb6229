"""fill_batch on and off, on the known answers of tests/test_boundary_sampler.py.

``runs``: runs, rounds, short rounds and boundary error for batch 2 and 4 (the wall time of a campaign with one run
per core is about rounds x the run time).  ``coverage``: how often the separatrix's 95 % profile intervals of A and
B hold the truth on the fuzzy answer (batch 4, degree 2, tolerance 0.1, as the default-suite test).

    python results/archive/boundary_sampler/fill_batch.py runs --seeds 20 --out results/archive/boundary_sampler/fill_batch.json
    python results/archive/boundary_sampler/fill_batch.py coverage --seeds 200 --out results/archive/boundary_sampler/fill_batch_coverage.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
import test_boundary_sampler as T  # noqa: E402  (the oracles, the driver and the error measure of the tests)
from sweep.regimes.separatrix import separatrix_profile_interval  # noqa: E402

CASES = {"separatrix_sharp": (T.CA_AXES, T.separatrix_sharp, T._sep_truth, {"cement": 0.1, "eta_o": 0.1}),
         "separatrix_fuzzy": (T.CA_AXES, T.separatrix_fuzzy, T._sep_truth, {"cement": 0.1, "eta_o": 0.1}),
         "three_regimes": (T.MAP_AXES, T.three_regimes, T._map_truth, 0.1)}


def measure(case: str, batch: int, fill: bool, seeds) -> dict:
    axes, oracle, truth, tol = CASES[case]
    runs, rounds, short, errors, stops = [], [], [], [], []
    for seed in seeds:
        spec = T._spec(axes, budget=150, tolerance=tol, seed=seed, batch=batch, fill_batch=fill)
        st, _ = T.drive(spec, oracle, seed)
        sizes = [len(r) for r in st.rounds[1:]]  # after the initial design
        runs.append(st.runs_used)
        rounds.append(len(st.rounds))
        short.append(sum(1 for k in sizes[:-1] if k < batch))  # the last round may be short on the budget
        errors.append(T.boundary_error(st.model, truth))
        stops.append(st.reason.split(":")[0])
    return {"case": case, "batch": batch, "fill_batch": fill, "seeds": len(list(seeds)),
            "runs_median": float(np.median(runs)), "runs_max": int(max(runs)),
            "rounds_median": float(np.median(rounds)), "rounds_max": int(max(rounds)),
            "short_rounds_median": float(np.median(short)), "short_rounds_total": int(sum(short)),
            "error_median": float(np.median(errors)), "error_max": float(max(errors)),
            "converged": sum(s == "converged" for s in stops)}


def coverage(fill: bool, seeds) -> dict:
    cover_a = cover_b = 0
    runs, rounds = [], []
    for seed in seeds:
        spec = T._spec(T.CA_AXES, budget=300, tolerance=0.1, seed=seed, batch=4, degree=2, fill_batch=fill)
        st, table = T.drive(spec, T.separatrix_fuzzy, seed)
        runs.append(st.runs_used)
        rounds.append(len(st.rounds))
        ca = table["eta_o"].to_numpy() * T._CA_PER_ETA_O[0]
        sep = separatrix_profile_interval(table["cement"], ca, table["regime"] == "fracturing", level=0.95)
        cover_a += sep.A_interval[0] <= T.A_TRUE <= sep.A_interval[1]
        cover_b += sep.B_interval[0] <= T.B_TRUE <= sep.B_interval[1]
    return {"fill_batch": fill, "seeds": len(list(seeds)), "cover_A": int(cover_a), "cover_B": int(cover_b),
            "runs_median": float(np.median(runs)), "rounds_median": float(np.median(rounds))}


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("what", choices=("runs", "coverage"))
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args()
    # what the tests' module fixture sets: Ca* per unit eta_o at the base parameters
    spec = T._spec(T.CA_AXES, budget=60, tolerance=0.1)
    T._BASE_PARAMS.update(T.BoundarySampler().initial(spec)[0].params)
    T._CA_PER_ETA_O[0] = T._numbers(T._BASE_PARAMS)["Ca_star"] / T._BASE_PARAMS["eta_o"]
    if a.what == "coverage":
        jobs = [(coverage, (fill, range(a.seeds))) for fill in (False, True)]
    else:
        jobs = [(measure, (case, batch, fill, range(a.seeds))) for case in CASES for batch in (2, 4)
                for fill in (False, True)]
    out = []
    for fn, args in jobs:
        out.append(fn(*args))
        print(json.dumps(out[-1]), flush=True)
    a.out.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
