"""How far does one mesh realization move β, and does the workflow's error model say so?  A leave-one-out study
on the realization curves that realizations.py made (no new run).

Each of the six correction realizations at β = 60 (h = 3, seeds 1-6, dt_max = 0.01 s, w_i = 50 mm/s) is taken in
turn as the data, noise-free.  The model is the mean of the other five, linear in β between their means at β = 60
and at 37.3: m(β) = m60 + (60 − β)/22.7 · (m37.3 − m60).  β is estimated by generalized least squares with the
covariance Σ = diag(σ²) + C, σ the twin's measurement noise (2 kPa, 0.2 mm, 0.5 mm) and C the workflow's
realization covariance (sweep.discrepancy.realizations.RealizationCovariance, estimated from the same five at
β = 60), and with Σ = diag(σ²) alone (measurement noise only).  Its standard error is 22.7 / √(dᵀΣ⁻¹d),
d = m37.3 − m60: what a Gaussian likelihood with that covariance reports.  If the error model carries the
realization scatter, the six estimates scatter about 60 by about that standard error (z = (β − 60)/se of order 1).
The twins' data runs (seeds 11 and 12, dt_max = 0.005 s, β = 60, noise-free; seed 12's made by the twins' code,
solver ada0fb1caa3269e8) are estimated against all six.  Estimates outside [37.3, 60] extrapolate
the linear model.  Units: β in kPa·s; observables kPa, mm.

    python results/archive/discrepancy/long_bias/leave_one_out.py      # writes leave_one_out.json beside it

Each condition with curves in curves/ is studied alone, and all of them together (one vector; the realization
covariance per condition × observable, its correlation time pooled over conditions as in the workflow).
"""
import json
from pathlib import Path

import numpy as np

from sweep.discrepancy.layout import CurveLayout
from sweep.discrepancy.realizations import RealizationCovariance

HERE = Path(__file__).resolve().parent
NOISE = {"p_inj": 2.0, "front_radius_mean": 0.2, "crack_length": 0.5}
OBS = list(NOISE)
TIMES = np.linspace(0.02, 2.0, 40)
B_HI, B_LO = 60.0, 37.3
DATA_SEEDS = (11, 12)  # the twins' data meshes (dt_max = 0.005 s)


#: the twins' conditions (w_i, mm/s) and the suffix of their curve files in curves/ (w50's files have none)
CONDITIONS = {"w50": "", "w35": "_w35", "w65": "_w65", "w42": "_w42"}


def _vec(curves: dict) -> np.ndarray:
    return np.concatenate([np.asarray(curves[o], float) for o in OBS])


def _read(name: str) -> dict:
    return json.loads((HERE / "curves" / name).read_text())


def _load(conditions=("w50",)):
    """(hi (6, n), lo (6, n), {data name: (n,)}, seeds) over ``conditions``, each condition's three observables
    in turn (n = 120 per condition)."""
    hi, lo, data = [], [], {f"data_seed{k}": [] for k in DATA_SEEDS}
    for c in conditions:
        suf = CONDITIONS[c]
        h, l = _read(f"beta60{suf}.json"), _read(f"beta37.3{suf}.json")
        seeds = sorted(h)
        hi.append(np.array([_vec(h[s]) for s in seeds]))
        lo.append(np.array([_vec(l[s]) for s in seeds]))
        for k in DATA_SEEDS:
            data[f"data_seed{k}"].append(_vec(_read(f"data_seed{k}_beta60{suf}.json")["data"]))
    return np.hstack(hi), np.hstack(lo), {k: np.concatenate(v) for k, v in data.items()}, seeds


def _layout(n_conditions: int = 1) -> CurveLayout:
    n, k = TIMES.size, len(OBS) * n_conditions
    obs = np.tile(np.repeat(np.array(OBS), n), n_conditions)
    return CurveLayout(series=np.repeat(np.arange(k), n), obs=obs, t=np.tile(TIMES, k))


def gls_beta(y, hi, lo, sigma, cov=None, rows=None):
    """(β, standard error) of the linear model between the means of ``hi`` and ``lo`` (k, n) for data ``y``."""
    rows = np.arange(y.size) if rows is None else rows
    m60, d = hi.mean(axis=0)[rows], (lo.mean(axis=0) - hi.mean(axis=0))[rows]
    S = np.diag(sigma[rows] ** 2) + (0.0 if cov is None else cov[np.ix_(rows, rows)])
    w = np.linalg.solve(S, d)
    alpha, info = w @ (y[rows] - m60) / (w @ d), w @ d
    return B_HI - (B_HI - B_LO) * alpha, (B_HI - B_LO) / np.sqrt(info)


def study(conditions=("w50",)) -> dict:
    hi, lo, data, seeds = _load(conditions)
    layout, n = _layout(len(conditions)), TIMES.size
    sigma = np.tile(np.concatenate([np.full(n, NOISE[o]) for o in OBS]), len(conditions))
    subsets = {"all": np.arange(hi.shape[1]), "crack_length": np.flatnonzero(layout.obs == "crack_length")}
    out = {}
    for name, rows in subsets.items():
        for model in ("noise_only", "realization_covariance"):
            est = []
            for i, s in enumerate(seeds + list(data)):
                others = [j for j in range(len(seeds)) if j != i]
                y = hi[i] if i < len(seeds) else data[s]
                cov = RealizationCovariance.estimate(hi[others], layout).dense(np.arange(layout.n)) \
                    if model == "realization_covariance" else None
                b, se = gls_beta(y, hi[others], lo[others], sigma, cov, rows)
                est.append({"data": s, "beta": float(b), "se": float(se), "z": float((b - B_HI) / se)})
            loo = [e for e in est if e["data"] not in data]
            out[f"{name}/{model}"] = {
                "estimates": est,
                "loo_beta_mean": float(np.mean([e["beta"] for e in loo])),
                "loo_beta_sd": float(np.std([e["beta"] for e in loo], ddof=1)),
                "loo_median_se": float(np.median([e["se"] for e in loo])),
                "loo_rms_z": float(np.sqrt(np.mean([e["z"] ** 2 for e in loo])))}
    return out


if __name__ == "__main__":
    available = [c for c in CONDITIONS if all((HERE / "curves" / f).exists() for f in
                 (f"beta60{CONDITIONS[c]}.json", f"beta37.3{CONDITIONS[c]}.json"))]
    res = {c: study((c,)) for c in available}
    training = tuple(c for c in ("w50", "w35", "w65") if c in available)  # the twins' training conditions
    for combo in dict.fromkeys([training, tuple(available)]):
        if len(combo) > 1:
            res["+".join(combo)] = study(combo)
    (HERE / "leave_one_out.json").write_text(json.dumps(res, indent=1) + "\n")
    for k, v in ((f"{c} {m}", r) for c, rc in res.items() for m, r in rc.items()):
        print(f"{k}: LOO β mean {v['loo_beta_mean']:.1f}, sd {v['loo_beta_sd']:.1f}, median se {v['loo_median_se']:.2f}, "
              f"rms z {v['loo_rms_z']:.1f}; " + ", ".join(f"{e['data']} {e['beta']:.1f}±{e['se']:.1f}" for e in v["estimates"]))
