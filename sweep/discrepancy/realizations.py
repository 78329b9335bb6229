"""Mesh realizations in the discrepancy workflow: the fine check runs on several meshes and porosity fields.

The measured data are one realization of mesh and porosity field that the workflow cannot know.  The fine
check realizations give the discretization correction (their mean) and the uncertainty of which
realization the data are: per point (:func:`realization_mean_spread`) or as a covariance per series
correlated in time (:class:`RealizationCovariance`).  Units those of the observables (kPa, mm), times s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import stats

__all__ = ["realizations", "realization_mean_spread", "RealizationCovariance"]


def realizations(fine_forward) -> list:
    """The fine forward models as a list: None -> [], one model -> [model], a list/tuple -> its models."""
    if fine_forward is None:
        return []
    return list(fine_forward) if isinstance(fine_forward, (list, tuple)) else [fine_forward]


@dataclass
class RealizationCovariance:
    """Covariance of the data's mesh-realization deviation, one block per series (condition × observable).

    The data are one realization of mesh and porosity field; its deviation from the k check realizations'
    mean is a random curve.  Measured with the solver (twins, h = 3 mm): the front radius of a realization
    wanders from the others by ~1 mm, with jumps where fingers connect, over stretches of several
    observation times; per-point variances read such a stretch as a systematic misfit, and k = 3 curves
    are far too few to estimate its covariance freely (their rank-2 sample covariance gives no variance
    at all to a deviation outside their span: tried, the solver negative control got worse, χ² excess
    z 11 -> 27).  So a model with few parameters, estimated from the k curves:

        C_s[i, j] = √(v_i v_j) exp(−|t_i − t_j| / τ_o),

    v_i = (1 + 1/k) s_i² averaged over ``window`` neighbouring points of the series (s_i the sample std of
    the realizations at that point; 1 + 1/k: one more realization about a k-sample mean), τ_o per
    observable from the lag-1 autocorrelation ρ of the realizations' deviation curves pooled over
    conditions, τ = −Δt/ln ρ (Δt the median time step; ρ clipped to [0, 0.99]; ρ = 0: C diagonal).
    Series are taken as independent of one another.  Units: v in kPa², mm²; τ in s.
    """

    blocks: dict        # series -> (rows in time order, C (n_s, n_s))
    tau: dict           # observable -> correlation time, s
    rho: dict           # observable -> pooled lag-1 autocorrelation of the deviations

    @classmethod
    def estimate(cls, fines: np.ndarray, problem, window: int = 5) -> "RealizationCovariance":
        """From the realizations' predictions ``fines`` (k, n) on the rows of ``problem`` (a workflow
        ``Problem``: its ``series``, ``obs`` and ``t`` (s) per row)."""
        fines = np.atleast_2d(np.asarray(fines, float))
        ok = np.isfinite(fines)
        cnt = ok.sum(axis=0)
        mean, spread = realization_mean_spread(fines)
        with np.errstate(invalid="ignore", divide="ignore"):
            var = np.where(cnt >= 2, (1.0 + 1.0 / cnt) * spread**2, 0.0)
        dev = np.where(ok & (cnt >= 2), fines - np.where(np.isfinite(mean), mean, 0.0), 0.0)
        series_rows = {}
        for s in np.unique(problem.series):
            rows = np.flatnonzero(problem.series == s)
            series_rows[int(s)] = rows[np.argsort(problem.t[rows], kind="stable")]
        tau, rho = {}, {}
        for o in np.unique(problem.obs):
            rs = [r for r in series_rows.values() if problem.obs[r[0]] == o]
            rho[str(o)] = stats.pooled_lag1([dev[:, r] for r in rs])
            steps = np.concatenate([np.diff(problem.t[r]) for r in rs])
            dt = float(np.median(steps)) if steps.size else 0.0
            tau[str(o)] = -dt / math.log(rho[str(o)]) if rho[str(o)] > 0 and dt > 0 else 0.0
        blocks = {}
        for s, rows in series_rows.items():
            v = stats.moving_average(var[rows], window)
            ta = tau[str(problem.obs[rows[0]])]
            lag = np.abs(problem.t[rows][:, None] - problem.t[rows][None, :])
            corr = np.exp(-lag / ta) if ta > 0 else np.eye(rows.size)
            blocks[s] = (rows, np.sqrt(np.outer(v, v)) * corr)
        return cls(blocks, tau, rho)

    def variance(self, n: int) -> np.ndarray:
        """Per-point realization variance (the blocks' diagonals) on n rows, kPa² / mm²."""
        out = np.zeros(n)
        for rows, C in self.blocks.values():
            out[rows] = np.diag(C)
        return out

    def dense(self, sel: np.ndarray) -> np.ndarray:
        """The covariance on the rows ``sel`` (sorted global indices) as a dense matrix."""
        out = np.zeros((sel.size, sel.size))
        for rows, C in self.blocks.values():
            keep = np.isin(rows, sel)
            if keep.any():
                ix = np.searchsorted(sel, rows[keep])
                out[np.ix_(ix, ix)] = C[np.ix_(keep, keep)]
        return out

    def whiteners(self, mask: np.ndarray, sig_diag: np.ndarray) -> list:
        """[(positions in the masked vector, W)] per series with rows in ``mask``: W = R^(−1/2),
        R = I + D^(−1/2) C D^(−1/2) (D = σ_diag²) on those rows (a subset's marginal covariance is the
        sub-block)."""
        rows_m = np.flatnonzero(mask)
        out = []
        for rows, C in self.blocks.values():
            keep = mask[rows]
            if not keep.any():
                continue
            r = rows[keep]
            d = sig_diag[r]
            R = np.eye(r.size) + C[np.ix_(keep, keep)] / np.outer(d, d)
            out.append((np.searchsorted(rows_m, r), stats.symmetric_whitener(R)))
        return out


def realization_mean_spread(fines: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-point mean and sample standard deviation (ddof = 1) over realizations, rows of ``fines`` (k, n).

    Only finite values count (a realization that failed at a point is left out there); the mean is NaN
    where none is finite, the spread 0 where fewer than 2 are.  Units those of ``fines`` (kPa, mm)."""
    fines = np.atleast_2d(np.asarray(fines, float))
    ok = np.isfinite(fines)
    cnt = ok.sum(axis=0)
    vals = np.where(ok, fines, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(cnt > 0, vals.sum(axis=0) / cnt, np.nan)
        ss = np.where(ok, (fines - mean) ** 2, 0.0).sum(axis=0)
        spread = np.where(cnt >= 2, np.sqrt(ss / (cnt - 1)), 0.0)
    return mean, spread
