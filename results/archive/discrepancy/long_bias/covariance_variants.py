"""Would a different realization covariance make the leave-one-out calibrated?  Two variants of the workflow's
model (sweep.discrepancy.realizations.RealizationCovariance), tried on the curves of ``leave_one_out.py`` (no new
run):

* cross-condition correlation: the same mesh realization is used at every injection rate, so its deviation at
  one rate may predict its deviation at another.  Cross blocks r √(v_i v'_j) exp(−|t_i − t'_j|/τ̄) between the
  series of two conditions, r the pooled correlation of the realizations' deviation curves, τ̄ the geometric
  mean of the two correlation times; "same_obs" only between series of the same observable (a Schur product of a
  sample correlation and one kernel, positive semi-definite), "all" between every pair;
* longer correlation times: τ_o times 3, 10 and 100 (towards a curve-wide offset).

Prints and writes ``covariance_variants.json``: per variant and set of conditions, the leave-one-out β mean,
sd, median standard error and RMS z of the six check realizations, and the data seeds' estimates.  RMS z near 1
is a calibrated error model.  Units: β kPa·s.

    python results/archive/discrepancy/long_bias/covariance_variants.py
"""
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import leave_one_out as L  # noqa: E402
from sweep.discrepancy.realizations import RealizationCovariance  # noqa: E402

TRAINING = ("w50", "w35", "w65")


def _kernel(t_a, t_b, tau):
    dt = np.abs(t_a[:, None] - t_b[None, :])
    return np.exp(-dt / tau) if tau > 0 else (dt == 0).astype(float)


def covariance(fines, layout, cross: str = "none", tau_scale: float = 1.0) -> np.ndarray:
    """The dense realization covariance of the k curves ``fines`` on ``layout``, with the variant's changes."""
    rc = RealizationCovariance.estimate(fines, layout)
    C = np.zeros((layout.n, layout.n))
    v = rc.variance(layout.n)
    sr = layout.series_rows()
    for s, rows in sr.items():
        C[np.ix_(rows, rows)] = np.sqrt(np.outer(v[rows], v[rows])) * _kernel(
            layout.t[rows], layout.t[rows], rc.tau[str(layout.obs[rows[0]])] * tau_scale)
    if cross == "none":
        return C
    dev = fines - fines.mean(axis=0)
    keys = list(sr)
    for i, a in enumerate(keys):
        for b in keys[i + 1:]:
            ra, rb = sr[a], sr[b]
            oa, ob = str(layout.obs[ra[0]]), str(layout.obs[rb[0]])
            if cross == "same_obs" and oa != ob:
                continue
            da, db = dev[:, ra], dev[:, rb]
            r = np.sum(da * db) / np.sqrt(np.sum(da * da) * np.sum(db * db))
            blk = r * np.sqrt(np.outer(v[ra], v[rb])) * _kernel(layout.t[ra], layout.t[rb],
                                                                 np.sqrt(rc.tau[oa] * rc.tau[ob]) * tau_scale)
            C[np.ix_(ra, rb)], C[np.ix_(rb, ra)] = blk, blk.T
    return C


def study(conditions, **variant) -> dict:
    hi, lo, data, seeds = L._load(conditions)
    layout, n = L._layout(len(conditions)), L.TIMES.size
    sigma = np.tile(np.concatenate([np.full(n, L.NOISE[o]) for o in L.OBS]), len(conditions))
    est = []
    for i, s in enumerate(seeds + list(data)):
        others = [j for j in range(len(seeds)) if j != i]
        y = hi[i] if i < len(seeds) else data[s]
        b, se = L.gls_beta(y, hi[others], lo[others], sigma, covariance(hi[others], layout, **variant))
        est.append({"data": s, "beta": float(b), "se": float(se), "z": float((b - L.B_HI) / se)})
    loo = [e for e in est if e["data"] in seeds]
    return {"loo_beta_mean": float(np.mean([e["beta"] for e in loo])),
            "loo_beta_sd": float(np.std([e["beta"] for e in loo], ddof=1)),
            "loo_median_se": float(np.median([e["se"] for e in loo])),
            "loo_rms_z": float(np.sqrt(np.mean([e["z"] ** 2 for e in loo]))),
            "data": {e["data"]: [e["beta"], e["se"]] for e in est if e["data"] not in seeds}}


if __name__ == "__main__":
    variants = {"workflow": {}, "cross_same_obs": {"cross": "same_obs"}, "cross_all": {"cross": "all"},
                **{f"tau_x{k:g}": {"tau_scale": k} for k in (3.0, 10.0, 100.0)}}
    res = {}
    for name, kw in variants.items():
        for cond in (("w50",), ("w35",), ("w65",), TRAINING):
            r = study(cond, **kw)
            res[f"{name}/{'+'.join(cond)}"] = r
            print(f"{name:15s} {'+'.join(cond):12s} LOO β {r['loo_beta_mean']:.1f} ± {r['loo_beta_sd']:.1f}, median se "
                  f"{r['loo_median_se']:.2f}, RMS z {r['loo_rms_z']:.2f}; "
                  + ", ".join(f"{k} {b:.1f}±{s:.1f}" for k, (b, s) in r["data"].items()))
    (HERE / "covariance_variants.json").write_text(json.dumps(res, indent=1) + "\n")
