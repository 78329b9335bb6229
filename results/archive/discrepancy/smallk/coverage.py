"""Coverage and bias of the strength's 95 % profile interval at few mesh realizations k (issue #53 item 3),
today's χ²(1) threshold against ``[profile] threshold = "f_welch"`` (F(1, ν), ν the Welch–Satterthwaite dof,
NoiseModel.strength_dof) and ``"f_realizations"`` (F(1, k − 1)) on the same data sets (each data set's interval at
the three thresholds; the runs before the option's two values were split called them "f_realizations" and
"F(1, k - 1)" in the JSON's "levels").  The toy is
tests/test_discrepancy_shared_realization.py's (_draws: y_c = θ (1 + c/4) t, 12 times, v = 1, τ = 0.3 s,
ρ = 0.9 between conditions, σ = 0.3; θ = 1).  One configuration per call:

    PYTHONPATH=<worktree> python results/archive/discrepancy/smallk/coverage.py LIKELIHOOD N_COND BLOCKS K N_DRAWS

appends one JSON line to results/discrepancy/shared_realization/smallk_coverage.jsonl."""
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[4]
sys.path.insert(0, str(ROOT / "tests"))
import test_discrepancy_shared_realization as T  # noqa: E402
from sweep.discrepancy.stats import realization_level  # noqa: E402

OUT = ROOT / "results/discrepancy/shared_realization/smallk_coverage.jsonl"


def main(likelihood, n_cond, blocks, k, n_draws, seed=101):
    t0 = time.time()
    base = 1.96**2 if likelihood == "gls" else 3.84
    levels = [base, T.f_level("f_welch"), T.f_level("f_realizations")]
    est, lo, hi, used = T._draws(blocks, n_draws, 0.9, k, likelihood, seed=seed, n_cond=n_cond, levels=levels)
    hit = (lo <= 1.0) & (1.0 <= hi)
    cov = hit.mean(axis=0)
    row = {"likelihood": likelihood, "n_cond": n_cond, "blocks": blocks, "k": k, "n_draws": n_draws, "seed": seed,
           "levels": ["chi2", "f_welch", "f_realizations"],
           "median_level": np.median(used, axis=0).tolist(), "coverage": cov.tolist(), "coverage_mc_sd": np.sqrt(cov * (1 - cov) / n_draws).tolist(),
           "mean_estimate": float(est.mean()), "sd_estimate": float(est.std(ddof=1)),
           "mean_estimate_mc_sd": float(est.std(ddof=1) / np.sqrt(n_draws)),
           "median_half_width": np.median(0.5 * (hi - lo), axis=0).tolist(), "seconds": round(time.time() - t0, 1)}
    with open(OUT, "a") as fh:
        fh.write(json.dumps(row) + "\n")
    print(json.dumps(row), flush=True)


if __name__ == "__main__":
    a = sys.argv[1:]
    main(a[0], int(a[1]), a[2], int(a[3]), int(a[4]))
