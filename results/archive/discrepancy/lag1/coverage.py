"""Coverage of the strength's 95 % interval with ``[noise] lag1 = "mean_ratio"`` against today's ``"pooled"``
(issue #53), on the same data sets: the toy of tests/test_discrepancy_shared_realization.py (_draws: four
conditions, "observable" blocks, y_c = θ (1 + c/4) t, 12 times 0.1–1.2 s, v = 1, τ = 0.3 s, ρ = 0.9 between
conditions, σ = 0.3, θ = 1; the data one realization outside the k).  Two measures:

- "profile": each data set's profile interval of the whitened χ² (``likelihood = "gaussian"``; for this linear
  model the GLS Wald interval) at the three thresholds χ²(1), f_welch, f_realizations; MC sd binomial, and the
  paired sd of the difference new − old (the same data sets);
- "wald_exact": the GLS Wald interval's exact coverage given the k realizations, 2Φ(1.96 √(V̂/V)) − 1
  (results/archive/discrepancy/smallk/diagnose.py), averaged over draws of the k realizations.

    PYTHONPATH=<worktree> python results/archive/discrepancy/lag1/coverage.py K N_DRAWS N_EXACT [LIKELIHOOD]

(with LIKELIHOOD, e.g. marginal: that profile alone, N_EXACT unused)

appends JSON lines to results/discrepancy/shared_realization/lag1_coverage.jsonl."""
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import norm

ROOT = Path(__file__).resolve().parents[4]
sys.path.insert(0, str(ROOT / "tests"))
import test_discrepancy_shared_realization as T  # noqa: E402
from sweep.discrepancy.realization_blocks import block_kernel  # noqa: E402
from sweep.discrepancy.realizations import RealizationCovariance  # noqa: E402

OUT = ROOT / "results/discrepancy/shared_realization/lag1_coverage.jsonl"
EST = ("pooled", "mean_ratio")


def profile(k, n_draws, seed=101, likelihood="gaussian"):
    t0 = time.time()
    levels = [3.84, T.f_level("f_welch"), T.f_level("f_realizations")]
    hits, ests = {}, {}
    for e in EST:
        est, lo, hi, _ = T._draws("observable", n_draws, 0.9, k, likelihood, seed=seed, levels=levels, lag1=e)
        hits[e] = (lo <= 1.0) & (1.0 <= hi)
        ests[e] = est
    d = hits["mean_ratio"].astype(float) - hits["pooled"]
    row = {"measure": "profile", "likelihood": likelihood, "n_cond": 4, "blocks": "observable", "k": k,
           "n_draws": n_draws, "seed": seed, "levels": ["chi2", "f_welch", "f_realizations"],
           **{f"coverage_{e}": hits[e].mean(axis=0).tolist() for e in EST},
           **{f"coverage_mc_sd_{e}": np.sqrt(hits[e].mean(axis=0) * (1 - hits[e].mean(axis=0)) / n_draws).tolist()
              for e in EST},
           "difference": d.mean(axis=0).tolist(), "difference_mc_sd": (d.std(axis=0, ddof=1) / np.sqrt(n_draws)).tolist(),
           "mean_estimate": {e: float(ests[e].mean()) for e in EST},
           "mean_estimate_mc_sd": {e: float(ests[e].std(ddof=1) / np.sqrt(n_draws)) for e in EST},
           "seconds": round(time.time() - t0, 1)}
    return row


def wald_exact(k, n_draws, seed=3, tau=0.3, rho=0.9, sig=0.3):
    t0 = time.time()
    lay = T._layout(n_cond=4, n=12, t_end=1.2)
    g = (1.0 + lay.series / 4.0) * lay.t
    rows = np.arange(lay.n)
    Se = (1 + 1 / k) * block_kernel(lay, rows, tau, rho) + sig**2 * np.eye(lay.n)
    rng = np.random.default_rng(seed)
    cov, tau_hat = {e: [] for e in EST}, {e: [] for e in EST}
    for _ in range(n_draws):
        dev = T._shared_deviations(rng, k, 4, lay.t[:12], rho, tau=tau)
        for e in EST:
            rc = RealizationCovariance.estimate(dev, lay, mode="observable", lag1=e)
            C = rc.dense(rows) + sig**2 * np.eye(lay.n)
            Wg = np.linalg.solve(C, g)
            Vhat = 1.0 / (g @ Wg)
            a = Wg * Vhat
            cov[e].append(2 * norm.cdf(1.96 * np.sqrt(Vhat / (a @ Se @ a))) - 1)
            tau_hat[e].append(rc.tau[T.OBS])
    d = np.array(cov["mean_ratio"]) - np.array(cov["pooled"])
    return {"measure": "wald_exact", "n_cond": 4, "blocks": "observable", "k": k, "n_draws": n_draws, "seed": seed,
            **{f"coverage_{e}": float(np.mean(cov[e])) for e in EST},
            **{f"coverage_mc_sd_{e}": float(np.std(cov[e], ddof=1) / np.sqrt(n_draws)) for e in EST},
            "difference": float(d.mean()), "difference_mc_sd": float(d.std(ddof=1) / np.sqrt(n_draws)),
            **{f"median_tau_{e}": float(np.median(tau_hat[e])) for e in EST},
            **{f"mean_tau_{e}": float(np.mean(tau_hat[e])) for e in EST}, "seconds": round(time.time() - t0, 1)}


if __name__ == "__main__":
    k, n_prof, n_exact = (int(x) for x in sys.argv[1:4])
    if len(sys.argv) > 4:                   # a likelihood: its profile alone (e.g. marginal, the starting SPEC's)
        rows = [profile(k, n_prof, likelihood=sys.argv[4])]
    else:
        rows = [wald_exact(k, n_exact), profile(k, n_prof)]
    for row in rows:
        with open(OUT, "a") as fh:
            fh.write(json.dumps(row) + "\n")
        print(json.dumps(row), flush=True)
