"""Why the 95 % interval under-covers at few realizations k (issue #53 item 3): the GLS (Wald) interval's
exact conditional coverage given the k realizations, 2Φ(1.96 √(V̂/V)) − 1 with V̂ = 1/(gᵀŴg) the variance the
workflow states and V = aᵀΣ_e a the true variance of θ̂ = aᵀy (a = Ŵg/gᵀŴg; the data's error e is independent
of the k realizations' deviations about their mean, so given them θ̂ is exactly N(θ, V)).  Averaged over draws
of the k realizations (no data draws needed: Rao–Blackwellized).  Components of the estimated covariance Ĉ =
√(v̂v̂ᵀ) K(τ̂, ρ̂) are replaced one at a time by the truth to see which estimate's error costs coverage.
The toy is tests/test_discrepancy_shared_realization.py's (v = 1, τ = 0.3 s, ρ = 0.9, σ = 0.3, 12 times).
Also the interval's multiplier alternatives: t(k − 1) on V̂ (``[profile] threshold = "f_realizations"``), t(ν) with
ν the block scale's Satterthwaite dof (RealizationCovariance.scale_dof), and the sandwich variance along a from
the k realizations' sample covariance (z and Welch–Satterthwaite t).
Run: PYTHONPATH=<worktree> python results/archive/discrepancy/smallk/diagnose.py
  > results/discrepancy/shared_realization/smallk_diagnosis.txt"""
import sys
from pathlib import Path

import numpy as np
from scipy.stats import norm, chi2, t

ROOT = Path(__file__).resolve().parents[4]
sys.path.insert(0, str(ROOT / "tests"))
import test_discrepancy_shared_realization as T  # noqa: E402
from sweep.discrepancy.realization_blocks import block_kernel  # noqa: E402
from sweep.discrepancy.realizations import RealizationCovariance  # noqa: E402

TAU, RHO, SIG = 0.3, 0.9, 0.3


def run(n_cond, k, mode, n_draws=4000, seed=3):
    lay = T._layout(n_cond=n_cond, n=12, t_end=1.2)
    g = (1.0 + lay.series / 4.0) * lay.t
    rows = np.arange(lay.n)
    Ktrue = block_kernel(lay, rows, TAU, RHO)
    Se = (1 + 1 / k) * Ktrue + SIG**2 * np.eye(lay.n)
    rng = np.random.default_rng(seed)
    out = {name: [] for name in ("plugin", "true_tau", "true_rho", "true_v", "true_v_tau")}
    ratios = {name: [] for name in out}
    extra = {}
    for _ in range(n_draws):
        dev = T._shared_deviations(rng, k, n_cond, lay.t[:12], RHO, tau=TAU)
        rc = RealizationCovariance.estimate(dev, lay, mode=mode)
        v = rc.variance(lay.n)
        tau = rc.tau[T.OBS]
        rho = rc.rho_cond[T.OBS] if mode == "observable" else 0.0
        vt = np.full(lay.n, 1 + 1 / k)
        variants = {"plugin": (v, tau, rho), "true_tau": (v, TAU, rho), "true_rho": (v, tau, RHO if mode == "observable" else 0.0),
                    "true_v": (vt, tau, rho), "true_v_tau": (vt, TAU, rho)}
        for name, (vv, tt, rr) in variants.items():
            C = np.sqrt(np.outer(vv, vv)) * block_kernel(lay, rows, tt, rr) + SIG**2 * np.eye(lay.n)
            Wg = np.linalg.solve(C, g)
            Vhat = 1.0 / (g @ Wg)
            a = Wg * Vhat
            V = a @ Se @ a
            ratios[name].append(V / Vhat)
            out[name].append(2 * norm.cdf(1.96 * np.sqrt(Vhat / V)) - 1)
        # the sample variance over the k realizations of the projection aᵀd (exactly k−1 dof for fixed a):
        # the sandwich variance V_emp = σ² aᵀa + (1 + 1/k) aᵀSa, Satterthwaite ν = (k−1) (V_emp / its estimated part)²
        C = np.sqrt(np.outer(v, v)) * block_kernel(lay, rows, tau, rho) + SIG**2 * np.eye(lay.n)
        Wg = np.linalg.solve(C, g)
        Vhat = 1.0 / (g @ Wg)
        a = Wg * Vhat
        V = a @ Se @ a
        proj = (dev - dev.mean(axis=0)) @ a
        est = (1 + 1 / k) * (proj @ proj) / (k - 1)
        Vemp = SIG**2 * (a @ a) + est
        nu = (k - 1) * (Vemp / est) ** 2
        for name, q2 in (("t(k-1) on V̂", t.ppf(0.975, k - 1) ** 2 * Vhat), ("t(nu_scale) on V̂", t.ppf(0.975, rc.scale_dof(rows if mode == "observable" else rows[:12])) ** 2 * Vhat),
                         ("sandwich z", 1.96**2 * Vemp), ("sandwich t(nu)", t.ppf(0.975, nu) ** 2 * Vemp)):
            extra.setdefault(name, []).append(2 * norm.cdf(np.sqrt(q2 / V)) - 1)
        extra.setdefault("nu", []).append(nu)
    res = {}
    for name in out:
        r = np.array(ratios[name])
        cv2 = np.var(1 / r) / np.mean(1 / r) ** 2
        res[name] = (np.mean(out[name]), np.std(out[name]) / np.sqrt(n_draws), np.mean(r), np.mean(1 / r),
                     2 / cv2 if cv2 > 1e-12 else np.inf)
    for name, c in extra.items():
        res[name] = (np.mean(c), np.std(c) / np.sqrt(n_draws), np.nan, np.nan, np.nan) if name != "nu" else (np.median(c), 0, np.nan, np.nan, np.nan)
    return res


if __name__ == "__main__":
    for n_cond, mode in ((1, "series"), (4, "observable"), (4, "series")):
        for k in (3, 6, 20):
            res = run(n_cond, k, mode, n_draws=2000 if k < 20 else 500)
            for name, (cov, sd, mr, mir, nu) in res.items():
                head = f"cond={n_cond} {mode:10s} k={k:2d} {name:18s}"
                if name == "nu":
                    print(f"{head} median Satterthwaite ν of the sandwich variance {cov:.1f}", flush=True)
                elif np.isnan(mr):
                    print(f"{head} Wald coverage {cov:.3f} ± {sd:.3f}", flush=True)
                else:
                    print(f"{head} Wald coverage {cov:.3f} ± {sd:.3f}  E[V/V̂] {mr:.3f}  E[V̂/V] {mir:.3f}  "
                          f"2/CV²(V̂/V) {nu:.1f}", flush=True)
